"""Campaign provenance: segments, their wall time and rate, the source commit."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

from sitl.campaign.provenance import SegmentLog, segments, source_commit

pytestmark = pytest.mark.unit


def result(mission_id: str, **fields: Any) -> dict[str, Any]:
    return {"mission_id": mission_id, "success": True, **fields}


def start_line(utc: str = "2026-11-21T10:00:00Z", commit: str = "c1", workers: int = 2, **fields: Any) -> str:
    """Segment 1's start record, one line of ``segments.jsonl`` written by hand (a fixed clock and machine)."""
    record = {"kind": "start", "segment": 1, "utc": utc, "commit": commit, "workers": workers}
    return json.dumps({**record, "machine": {"cpu_model": "x", "logical_cpus": 2}, **fields}) + "\n"


def test_a_segment_lasts_from_its_start_to_its_end_and_counts_its_missions(tmp_path: Path) -> None:
    log = SegmentLog(tmp_path / "segments.jsonl")
    number = log.start("abc123", workers=2, missions_done=0)
    assert number == 1
    start = log.records()[0]
    assert start["kind"] == "start"
    assert start["workers"] == 2
    assert start["machine"]["logical_cpus"] >= 1
    log.end(number, flown=2, interrupted=False)
    # Rewrite the clock for the test: one hour between start and end.
    records = log.records()
    records[0]["utc"], records[1]["utc"] = "2026-11-21T10:00:00Z", "2026-11-21T11:00:00Z"
    log.path.write_text("".join(json.dumps(r) + "\n" for r in records))
    results = [
        result("a", segment=1, finished_utc="2026-11-21T10:30:00Z"),
        result("b", segment=1, finished_utc="2026-11-21T10:59:00Z"),
        {"mission_id": "c", "segment": 1, "error": "did not start"},  # not a mission flown
    ]
    [seg] = segments(results, log, default_workers=2)
    assert seg.number == 1
    assert seg.missions == 2
    assert seg.wall_s == pytest.approx(3600.0)
    assert seg.missions_per_hour == pytest.approx(2.0)
    assert seg.commits == ["abc123"]
    assert not seg.estimated


def test_a_killed_segment_ends_at_its_last_mission_and_a_new_one_is_numbered_next(tmp_path: Path) -> None:
    log = SegmentLog(tmp_path / "segments.jsonl")
    log.path.write_text(start_line(workers=3) + '{"kind": "end", "segm')  # a torn line, as a kill -9 leaves it
    assert log.start("c2", workers=2, missions_done=1) == 2
    results = [result("a", segment=1, finished_utc="2026-11-21T10:20:00Z"), result("b", segment=2)]
    first, second = segments(results, log, default_workers=2)
    assert (first.number, first.ended_utc, first.wall_s, first.workers) == (1, "2026-11-21T10:20:00Z", 1200.0, 3)
    assert (second.number, second.missions, second.commits) == (2, 1, ["c2"])


def test_results_from_before_segments_are_estimated_unless_a_reconstructed_segment_claims_them(tmp_path: Path) -> None:
    log = SegmentLog(tmp_path / "segments.jsonl")
    old = [result("a", wall_s=100.0), result("b", wall_s=300.0), result("c", wall_s=90.0)]
    [estimated] = segments(old, log, default_workers=2)
    assert estimated.number is None
    assert estimated.estimated
    assert estimated.missions == 3
    assert estimated.wall_s == pytest.approx(245.0)  # (100 + 300 + 90) / 2 workers
    reconstructed = start_line(
        "2026-11-21T15:53:34Z", "3a0b9c1", workers=3, mission_ids=["c"], note="from the campaign log"
    )
    end = {"kind": "end", "segment": 1, "utc": "2026-11-21T16:53:34Z", "flown": 1, "interrupted": True}
    log.path.write_text(reconstructed + json.dumps(end) + "\n")
    before, claimed = segments(old, log, default_workers=2)
    assert before.missions == 2
    assert before.wall_s == pytest.approx(200.0)
    assert claimed.missions == 1
    assert claimed.wall_s == pytest.approx(3600.0)
    assert claimed.note


def test_a_flight_replaced_by_a_later_one_keeps_its_wall_time_and_is_counted(tmp_path: Path) -> None:
    # "b" was flown before segments were recorded, then flown again in segment 1 (its result was stale).
    log = SegmentLog(tmp_path / "segments.jsonl")
    log.path.write_text(start_line())
    old_b = result("b", wall_s=300.0)
    every_line = [result("a", wall_s=100.0), old_b, result("b", segment=1, finished_utc="2026-11-21T10:10:00Z")]
    current = [every_line[0], every_line[2]]
    before, first = segments(current, log, default_workers=2, every_line=every_line)
    assert (before.missions, before.superseded) == (1, 1)
    assert before.wall_s == pytest.approx(200.0)  # (100 + 300) / 2 workers: the replaced flight took time too
    assert before.missions_per_hour == pytest.approx(18.0)  # 1 result in the table in 200 s
    assert before.flights_per_hour == pytest.approx(36.0)  # 2 flights in 200 s
    assert (first.missions, first.superseded) == (1, 0)
    assert first.wall_s == pytest.approx(600.0)


def test_a_killed_segment_whose_flights_were_all_replaced_still_lasts_until_its_last_flight(tmp_path: Path) -> None:
    log = SegmentLog(tmp_path / "segments.jsonl")
    log.path.write_text(start_line())  # killed: no end record
    log.start("c2", workers=2, missions_done=1)
    every_line = [
        result("a", segment=1, finished_utc="2026-11-21T10:15:00Z"),
        result("a", segment=2, finished_utc="2026-11-21T12:10:00Z"),  # flown again: the first result was stale
    ]
    first, _second = segments([every_line[1]], log, default_workers=2, every_line=every_line)
    assert (first.missions, first.superseded) == (0, 1)
    assert first.ended_utc == "2026-11-21T10:15:00Z"
    assert first.wall_s == pytest.approx(900.0)


@pytest.mark.skipif(shutil.which("git") is None, reason="needs git")
def test_the_source_commit_says_when_the_tree_differs_from_it(tmp_path: Path) -> None:
    assert source_commit(tmp_path) is None  # not a repository
    env = ["-c", "user.name=t", "-c", "user.email=t@t.invalid"]
    subprocess.run(["git", "init", "-q"], cwd=tmp_path, check=True)
    (tmp_path / "f.txt").write_text("one\n")
    subprocess.run(["git", "add", "f.txt"], cwd=tmp_path, check=True)
    subprocess.run(["git", *env, "commit", "-q", "-m", "one"], cwd=tmp_path, check=True)
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=tmp_path, capture_output=True, text=True).stdout.strip()
    assert source_commit(tmp_path) == head
    (tmp_path / "f.txt").write_text("two\n")
    assert source_commit(tmp_path) == head + "-dirty"
