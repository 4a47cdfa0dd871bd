"""The flight log's schema: the writer's kinds, one checked reader, versions, and a broken record named by line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from companion.flightlog.flight_log import REQUIRED_FIELDS, SCHEMA_VERSION, FlightLog, FlightLogError, RecordKind
from companion.flightlog.recorder import FlightRecorder

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


def test_decisions_read_typed_and_kinds_in_log_order_from_the_recorders_own_records(tmp_path: Path) -> None:
    from companion.guidance.landing import CommandKind, Decision, LandingPhase
    from companion.guidance.vehicle_state import VehicleState
    from companion.guidance.vocabulary import DecisionEvent, DecisionSource
    from companion.perception.selection import Target
    from companion.vehicle.link import Setpoint

    recorder = FlightRecorder(tmp_path)
    recorder.write(RecordKind.HEADER, None, config={"mode": "fly"}, schema_version=SCHEMA_VERSION)
    state = VehicleState(3.0, 1.0, 2.0, -20.0, 90.0)
    target = Target(4.0, 5.0, 2.5, 7)
    setpoint = Setpoint(4.0, 5.0, -20.0, 90.0)
    decision = Decision(
        3.0, LandingPhase.APPROACH, CommandKind.SETPOINT, setpoint, target, "approach target 7", DecisionEvent.APPROACH
    )
    recorder.write(RecordKind.DECISION, 3.0, decision=decision, source="frame", state=state, inputs={"seq": 30})
    recorder.write(RecordKind.COMMAND, 3.0, command=CommandKind.SETPOINT, setpoint=setpoint)
    recorder.write("a_newer_kind", 3.5, value=1)  # a newer writer's record
    land = Decision(4.0, LandingPhase.LAND, CommandKind.LAND, None, target, "land on zone 7", DecisionEvent.LAND)
    recorder.write(RecordKind.DECISION, 4.0, decision=land, source="frame", state=state, inputs={"seq": 40})
    recorder.close()
    log = FlightLog.read(tmp_path)
    first, landing = log.decisions()
    assert (first.t_s, first.kind, first.phase) == (3.0, CommandKind.SETPOINT, LandingPhase.APPROACH)
    assert first.source is DecisionSource.FRAME
    assert first.target == Target(4.0, 5.0, 2.5, 7)
    assert first.setpoint == Setpoint(4.0, 5.0, -20.0, 90.0)
    assert first.state is not None
    assert first.state.north_m == 1.0
    assert (landing.kind, landing.setpoint, landing.reason) == (CommandKind.LAND, None, "land on zone 7")
    assert (first.event, landing.event) == (DecisionEvent.APPROACH, DecisionEvent.LAND)
    kinds = [kind for kind, _ in log.tagged()]
    assert kinds == [RecordKind.HEADER, RecordKind.DECISION, RecordKind.COMMAND, RecordKind.DECISION]  # not the new one
    assert [kind for kind, _ in log.tagged(RecordKind.COMMAND, RecordKind.DECISION)] == kinds[1:]
    assert len(log.records) == 5


def test_a_decision_naming_an_unknown_source_is_named_with_its_time(tmp_path: Path) -> None:
    write_flight(tmp_path, {"schema_version": SCHEMA_VERSION})
    decision = {"kind": "hold", "phase": "failsafe", "reason": "why"}
    with (tmp_path / "flight.jsonl").open("a") as f:
        f.write(
            json.dumps({"t_s": 13.0, "kind": "decision", "decision": decision, "source": "x", "state": None}) + "\n"
        )
    log = FlightLog.read(tmp_path)
    with pytest.raises(FlightLogError, match=r"decision at t = 13.0 s: 'x' is not a valid DecisionSource"):
        log.decisions()


def test_the_header_is_written_and_read_typed_and_an_older_one_reads_with_defaults(tmp_path: Path) -> None:
    from companion.flightlog.flight_log import FlightHeader

    written = FlightHeader(
        {"mode": "dry_run"}, SCHEMA_VERSION, "models/density/slz_yolox.onnx", "ab" * 32, True, "9.9.9"
    )
    recorder = FlightRecorder(tmp_path / "new")
    recorder.write(RecordKind.HEADER, None, **written.fields())
    recorder.close()
    assert FlightLog.read(tmp_path / "new").header == written
    assert written.mode == "dry_run"
    write_flight(tmp_path / "old", {})  # a header of config alone, as the first writers wrote it
    old = FlightLog.read(tmp_path / "old")
    assert old.header == FlightHeader({"mode": "fly"})
    assert (old.header.model, old.header.version, old.header.model_validated_real_imagery) == (None, None, False)
    (tmp_path / "none").mkdir()
    (tmp_path / "none" / "flight.jsonl").write_text(json.dumps({"t_s": None, "kind": "start", "mode": "fly"}) + "\n")
    headless = FlightLog.read(tmp_path / "none")
    assert headless.header is None
    with pytest.raises(FlightLogError, match="no header record"):
        headless.require_header()
