"""The flight log's schema: the writer's kinds, one checked reader, versions, and a broken record named by line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from companion.app.flight_log import REQUIRED_FIELDS, SCHEMA_VERSION, FlightLog, FlightLogError, RecordKind
from companion.app.recorder import FlightRecorder

pytestmark = pytest.mark.unit


def write_flight(folder: Path, header: dict[str, object]) -> None:
    recorder = FlightRecorder(folder)
    recorder.write(RecordKind.HEADER, None, config={"mode": "fly"}, **header)
    recorder.write(RecordKind.START, None, mode="fly")
    recorder.write(RecordKind.PHASE, 1.0, phase="search", previous="idle", reason="start")
    recorder.write(RecordKind.PHASE, 9.5, phase="land", previous="descent", reason="over the zone")
    recorder.write(RecordKind.COMMAND, 9.5, command="land")
    recorder.write(RecordKind.END, 12.0, outcome={"phase": "done"})
    recorder.close()


def test_a_log_reads_back_by_kind(tmp_path: Path) -> None:
    write_flight(tmp_path, {"schema_version": SCHEMA_VERSION})
    log = FlightLog.read(tmp_path)
    assert log.version == SCHEMA_VERSION
    assert log.config == {"mode": "fly"}
    assert log.phases() == [(1.0, "search"), (9.5, "land")]
    assert log.count(RecordKind.COMMAND) == 1
    assert log.outcome == {"phase": "done"}
    assert log.first(RecordKind.FRAME) is None


def test_a_log_from_before_the_schema_reads_as_version_1(tmp_path: Path) -> None:
    write_flight(tmp_path, {})
    assert FlightLog.read(tmp_path / "flight.jsonl").version == 1


def test_a_newer_schema_is_refused_by_name(tmp_path: Path) -> None:
    write_flight(tmp_path, {"schema_version": SCHEMA_VERSION + 1})
    with pytest.raises(FlightLogError, match=f"schema version {SCHEMA_VERSION + 1}"):
        FlightLog.read(tmp_path)


def test_a_record_missing_a_required_field_is_named_with_its_line(tmp_path: Path) -> None:
    write_flight(tmp_path, {"schema_version": SCHEMA_VERSION})
    with (tmp_path / "flight.jsonl").open("a") as f:
        f.write(json.dumps({"t_s": 13.0, "kind": "phase", "previous": "land"}) + "\n")
    with pytest.raises(FlightLogError, match=r"record 7 \(phase\) lacks phase"):
        FlightLog.read(tmp_path)


def test_every_kind_the_recorder_writes_itself_is_in_the_schema() -> None:
    # FlightRecorder.frame() writes "frame" records on its own (the recorder knows no schema).
    assert RecordKind("frame") is RecordKind.FRAME
    assert set(REQUIRED_FIELDS) <= set(RecordKind)
