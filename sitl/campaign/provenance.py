"""Where and how a campaign was flown: the source commit, the machine, and its flying segments.

A campaign is often flown in several pieces (it resumes where it stopped), perhaps at several commits and with
different worker counts. Each invocation that flies missions is a *segment*, written to ``segments.jsonl`` in the
campaign folder: a ``start`` record (UTC time, commit, workers, machine) when it begins and an ``end`` record when
it stops, killed or not (a segment cut off by ``kill -9`` has no end; its last mission's finish time stands in).
Every result line names its segment, its commit and its finish time. The campaign's wall time is the sum of its
segments' durations. A segment flown before segments were recorded may be added afterwards as a ``start`` record
with a ``note`` saying how it was reconstructed and the ``mission_ids`` it flew; results that belong to no segment
have their wall time estimated from their own ``wall_s`` divided by the spec's workers, and are said to be.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import platform
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from companion.flightlog.recorder import open_append, read_log
from sitl.harness.process import REPO_ROOT


def utc_now() -> str:
    """The current UTC time, ISO 8601 with seconds (``2026-11-21T15:53:34Z``)."""
    return dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def _parse_utc(text: str) -> dt.datetime:
    return dt.datetime.strptime(text, "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=dt.timezone.utc)


def source_commit(repo_root: Path = REPO_ROOT) -> str | None:
    """The git commit of the code that runs, with ``-dirty`` when tracked files differ from it; None without git."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=repo_root, capture_output=True, text=True, timeout=10, check=False
        )
        if head.returncode != 0 or not head.stdout.strip():
            return None
        dirty = subprocess.run(
            ["git", "diff", "--quiet", "HEAD", "--"], cwd=repo_root, capture_output=True, timeout=10, check=False
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return head.stdout.strip() + ("-dirty" if dirty.returncode == 1 else "")


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo, or the platform's processor string."""
    try:
        lines = Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines()
    except OSError:  # not Linux
        lines = []
    for line in lines:
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor() or "unknown"


def machine() -> dict[str, Any]:
    """The machine in a few fields: CPU model, logical CPUs, architecture, Python."""
    return {
        "cpu_model": cpu_model(),
        "logical_cpus": os.cpu_count(),
        "machine": platform.machine(),
        "python": platform.python_version(),
    }


class SegmentLog:
    """``segments.jsonl`` of one campaign folder: append a segment's start and end (each line fsync'd)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def records(self) -> list[dict[str, Any]]:
        """Every record so far (a torn last line is skipped)."""
        return read_log(self.path) if self.path.is_file() else []

    def _append(self, record: dict[str, Any]) -> None:
        with open_append(self.path) as f:
            f.write(json.dumps(record, separators=(",", ":")) + "\n")
            f.flush()
            os.fsync(f.fileno())

    def start(self, commit: str | None, workers: int, missions_done: int) -> int:
        """Record a new segment's start; returns its number (1, 2, ...)."""
        number = 1 + max((int(r["segment"]) for r in self.records()), default=0)
        self._append(
            {
                "kind": "start",
                "segment": number,
                "utc": utc_now(),
                "commit": commit,
                "workers": workers,
                "missions_done": missions_done,
                "machine": machine(),
            }
        )
        return number

    def end(self, number: int, flown: int, interrupted: bool) -> None:
        """Record the end of segment ``number`` after ``flown`` missions."""
        self._append({"kind": "end", "segment": number, "utc": utc_now(), "flown": flown, "interrupted": interrupted})


@dataclass
class Segment:
    """One flying segment as the report shows it."""

    number: int | None  # None: the results flown before segments were recorded
    commits: list[str] = field(default_factory=list)
    workers: int | None = None
    started_utc: str | None = None
    ended_utc: str | None = None
    missions: int = 0
    wall_s: float = 0.0
    estimated: bool = False  # wall time from the missions' own wall_s, not from the segment's clock
    superseded: int = 0  # missions this segment flew whose result a later flight replaced (errors aside)
    cpu: str | None = None
    note: str = ""  # e.g. how a segment recorded after the fact was reconstructed

    @property
    def missions_per_hour(self) -> float:
        """Missions flown (with a result) per hour of this segment's wall time."""
        return 3600.0 * self.missions / self.wall_s if self.wall_s > 0 else float("nan")

    @property
    def flights_per_hour(self) -> float:
        """Missions flown per hour of wall time, those whose result a later flight replaced included: how fast the
        segment flew (``missions_per_hour`` is how fast it added to the table)."""
        return 3600.0 * (self.missions + self.superseded) / self.wall_s if self.wall_s > 0 else float("nan")


def segments(
    results: list[dict[str, Any]],
    log: SegmentLog,
    default_workers: int,
    every_line: list[dict[str, Any]] | None = None,
) -> list[Segment]:
    """The segments that flew ``results`` (the current result of each mission), oldest first.

    ``every_line`` (all of ``results.jsonl``, superseded lines included) counts the flights whose result a later one
    replaced, and puts their wall time into the estimate for the results flown before segments were recorded.
    """
    records = log.records()
    starts = {int(r["segment"]): r for r in records if r.get("kind") == "start"}
    ends = {int(r["segment"]): r for r in records if r.get("kind") == "end"}
    claimed = {m: number for number, r in starts.items() for m in r.get("mission_ids", [])}  # reconstructed ones

    def by_segment(rows: list[dict[str, Any]]) -> dict[int | None, list[dict[str, Any]]]:
        out: dict[int | None, list[dict[str, Any]]] = {}
        for r in rows:
            if "error" not in r:
                out.setdefault(r.get("segment", claimed.get(r["mission_id"])), []).append(r)
        return out

    current = by_segment(results)
    flights = by_segment(every_line if every_line is not None else results)
    out = []
    unrecorded = current.get(None, [])
    if flights.get(None):
        out.append(
            Segment(
                number=None,
                commits=sorted({str(r["commit"]) for r in unrecorded if r.get("commit")}),
                workers=default_workers,
                missions=len(unrecorded),
                wall_s=sum(float(r.get("wall_s", 0.0)) for r in flights[None]) / default_workers,
                estimated=True,
                superseded=len(flights[None]) - len(unrecorded),
            )
        )
    for number in sorted(starts):
        start, rows, flown = starts[number], current.get(number, []), flights.get(number, [])
        # A killed segment (no end record) ended at its last flight, replaced later or not: it took that time.
        last_finished = max((str(r["finished_utc"]) for r in flown if r.get("finished_utc")), default=None)
        end_utc = ends[number]["utc"] if number in ends else last_finished
        wall_s = (_parse_utc(end_utc) - _parse_utc(start["utc"])).total_seconds() if end_utc else 0.0
        out.append(
            Segment(
                number=number,
                commits=[str(start["commit"])] if start.get("commit") else [],
                workers=int(start["workers"]),
                started_utc=start["utc"],
                ended_utc=end_utc,
                missions=len(rows),
                wall_s=wall_s,
                superseded=len(flown) - len(rows),
                cpu=f"{start['machine']['cpu_model']}, {start['machine']['logical_cpus']} logical CPUs",
                note=str(start.get("note", "")),
            )
        )
    return out
