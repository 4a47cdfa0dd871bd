"""Flight recorder: records survive a crash of the writer, a torn last line is skipped, values stay JSON."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.flightlog.recorder import FlightRecorder, RecorderError, open_append, read_log
from companion.guidance.landing import LandingPhase
from companion.vehicle.link import Setpoint

pytestmark = pytest.mark.unit


def test_records_are_json_lines_with_plain_values(tmp_path: Path) -> None:
    rec = FlightRecorder(tmp_path / "run", frame_every=2)
    rec.write("header", None, config={"a": 1}, model_sha256="ab")
    rec.write("phase", 1.5, phase=LandingPhase.SEARCH, setpoint=Setpoint(1.0, 2.0, -20.0, 90.0), nan=math.nan)
    rec.write("zones", 1.6, radii=np.array([1.5, 2.0], np.float32), count=np.int64(2))
    for seq in range(3):
        rec.frame(seq, 1.0 + seq, np.zeros((8, 8, 3), np.uint8))
    rec.close()
    rec.close()  # idempotent
    records = read_log(tmp_path / "run" / "flight.jsonl")
    kinds = [r["kind"] for r in records]
    assert kinds == ["header", "phase", "zones", "frame", "frame"]  # frames 0 and 2
    assert records[1]["phase"] == "search"
    assert records[1]["setpoint"] == {"north_m": 1.0, "east_m": 2.0, "down_m": -20.0, "yaw_deg": 90.0}
    assert records[1]["nan"] is None
    assert records[2]["radii"] == [1.5, 2.0]
    assert (tmp_path / "run" / records[3]["path"]).is_file()
    with pytest.raises(RecorderError, match="closed"):
        rec.write("phase", 2.0)


def test_the_log_survives_a_killed_writer(tmp_path: Path) -> None:
    script = (
        "import os, sys\n"
        "from pathlib import Path\n"
        "from companion.flightlog.recorder import FlightRecorder\n"
        f"rec = FlightRecorder(Path({str(tmp_path)!r}))\n"
        "for k in range(50):\n"
        "    rec.write('phase', float(k), phase='search')\n"
        'rec._file.write(\'{"t_s": 51, "kind": "pha\')\n'  # a torn record, then a hard crash
        "rec._file.flush()\n"
        "os._exit(9)\n"
    )
    result = subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).resolve().parent.parent, timeout=60)
    assert result.returncode == 9
    records = read_log(tmp_path / "flight.jsonl")
    assert len(records) == 50
    assert records[-1]["t_s"] == 49.0
    assert json.loads((tmp_path / "flight.jsonl").read_text().splitlines()[0])["kind"] == "phase"


def test_appending_after_a_torn_last_line_starts_a_line_of_its_own(tmp_path: Path) -> None:
    log = tmp_path / "results.jsonl"
    log.write_text('{"mission_id": "a"}\n{"mission_id": "b", "succ')  # killed mid-write
    with open_append(log) as f:
        f.write('{"mission_id": "b"}\n')
    assert [r["mission_id"] for r in read_log(log)] == ["a", "b"]  # the torn record cut off, nothing glued to it
    with open_append(log) as f:  # a whole log is left as it is
        f.write('{"mission_id": "c"}\n')
    assert [r["mission_id"] for r in read_log(log)] == ["a", "b", "c"]


def test_an_unwritable_directory_is_named(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(RecorderError, match="cannot open flight log"):
        FlightRecorder(blocker / "run")


def test_rotation_deletes_the_oldest_flights_beyond_the_count_and_the_size(tmp_path: Path) -> None:
    import os

    from companion.flightlog.recorder import prune_flights

    for i in range(5):
        flight = tmp_path / f"2026112{i}T000000Z"
        flight.mkdir()
        (flight / "flight.jsonl").write_text("{}\n")
        (flight / "frames.bin").write_bytes(b"\0" * 300_000)
        os.utime(flight / "flight.jsonl", (1_000_000 + i, 1_000_000 + i))  # flight i is the i-th oldest
    (tmp_path / "notes.txt").write_text("not a flight")
    (tmp_path / "empty").mkdir()
    assert prune_flights(tmp_path) == []  # no limit: nothing deleted
    assert prune_flights(tmp_path, keep_flights=4) == [tmp_path / "20261120T000000Z"]
    # 4 flights of 0.29 MiB: at most 0.7 MiB keeps the newest 2.
    deleted = prune_flights(tmp_path, max_total_mb=0.7)
    assert deleted == [tmp_path / "20261121T000000Z", tmp_path / "20261122T000000Z"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["20261123T000000Z", "20261124T000000Z", "empty", "notes.txt"]


@pytest.mark.parametrize(
    ("content", "error"),
    [
        (b'{"kind": "phase"}\n\xff\xfe not text\n', "not UTF-8"),
        (b'{"kind": "phase"}\n[1, 2]\n{"kind": "phase"}\n', ":2: a list, not a JSON object"),
        (b'{"kind": "phase"}\n' + b"[" * 100_000 + b"\n{}\n", ":2: not a JSON record"),
        (b"garbage\n{}\n", ":1: not a JSON record"),
    ],
)
def test_a_hostile_log_read_back_is_refused_by_line_not_with_a_traceback(
    tmp_path: Path, content: bytes, error: str
) -> None:
    log = tmp_path / "flight.jsonl"
    log.write_bytes(content)
    with pytest.raises(RecorderError, match=error):
        read_log(log)
