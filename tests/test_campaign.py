"""The campaign runner end to end: real SITL and companion processes per mission, in parallel workers.

The smoke spec (2 conditions x 2 strategies x 1 run, short missions) is flown with one warm worker (one SITL and one
companion process for all four missions), with two workers killed mid-way (the whole process group, SIGKILL) and
resumed, with new processes for every mission (``--cold``), and on a two-node Ray cluster with a node killed. All must
give the same per-mission results and the same report tables; the report must be produced and every metric within
its valid range.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from sitl.campaign.runner import read_results
from sitl.harness.process import log_tail
from sitl.testing.helpers import wait_until

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent
SPEC = REPO_ROOT / "mission_configs" / "campaigns" / "smoke.yaml"
# The only fields allowed to differ between two runs: when and in which segment a mission was flown, how long it took,
# and on which node.
WALL_FIELDS = {"wall_s", "segment", "finished_utc", "node"}  # ...and where


BASELINE = REPO_ROOT / "mission_configs" / "campaigns" / "baselines" / "smoke.json"


def campaign(out: Path, workers: int, *extra: str, **popen: Any) -> subprocess.Popen[str]:
    command = [sys.executable, "-m", "companion.cli", "campaign", "--spec", str(SPEC), "--out", str(out)]
    command += ["--workers", str(workers), *extra]  # each worker leases a free SITL instance
    return subprocess.Popen(command, cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)


def comparable(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in r.items() if k not in WALL_FIELDS} for r in results]


@pytest.fixture(scope="module")
def one_worker(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("campaign") / "one"
    run = campaign(out, 1, "--check-against", str(BASELINE))
    stdout, stderr = run.communicate(timeout=900)
    assert run.returncode == 0, stdout[-3000:] + stderr[-3000:]
    assert "wrote" in stdout
    return out


def test_the_regression_gate_passes_against_the_shipped_baseline(one_worker: Path) -> None:
    gate = json.loads((one_worker / "gate.json").read_text())
    assert not gate["failed"]
    assert gate["unpaired"] == 0
    assert {(c["strategy"], c["metric"]) for c in gate["checks"]} == {
        (s, m) for s in ("biggest", "oldest") for m in ("success", "warning_1m", "warning_1_5m")
    }
    assert all(c["pairs"] == 2 for c in gate["checks"])
    assert "# Regression gate: passed" in (one_worker / "gate.md").read_text()


def test_the_report_is_written_and_every_metric_is_in_its_range(one_worker: Path) -> None:
    results = read_results(one_worker / "results.jsonl")
    assert sorted(r["mission_id"] for r in results) == [
        "moving_20/biggest/0000",
        "moving_20/oldest/0000",
        "static/biggest/0000",
        "static/oldest/0000",
    ]
    for r in results:
        assert "error" not in r, r
        assert isinstance(r["success"], bool)
        assert r["success"] <= r["landed"]
        assert r["people_within_1m"] <= r["people_within_1_5m"]
        for key in ("zone_area_m2", "nearest_person_mean_m", "nearest_person_min_m", "time_to_land_s"):
            assert r[key] is None or r[key] >= 0.0, (key, r[key])
        assert r["zone_iou"] is None or 0.0 <= r["zone_iou"] <= 1.0
        if r["nearest_person_min_m"] is not None:
            assert r["nearest_person_min_m"] <= r["nearest_person_mean_m"] + 1e-9
        assert r["path_length_m"] >= 0.0
        assert r["touched_obstacle"] <= r["landed"]
        assert (r["obstacle_distance_m"] is None) == (not r["landed"])
        assert r["obstacle_distance_m"] is None or r["obstacle_distance_m"] >= 0.0
        assert r["sites_flown_to"] == 0  # no fallback sites in this campaign
        endings = ("zone", "failsafe_land") if r["landed"] else ("hold", "return", "failsafe_land", "other")
        assert r["ending"] in endings
    # Paired scenes: both strategies of a condition flew the same seed.
    seeds = {(r["condition"], r["strategy"]): r["seed"] for r in results}
    assert seeds["static", "oldest"] == seeds["static", "biggest"] != seeds["moving_20", "oldest"]
    summary = json.loads((one_worker / "summary.json").read_text())
    for cell in summary["cells"].values():
        s = cell["success"]
        assert 0.0 <= s["low"] <= s["value"] <= s["high"] <= 1.0
    # The paired time to land is over the scenes both strategies landed in.
    by_id = {r["mission_id"]: r for r in results}
    for pair in summary["paired"]:
        times = [
            (by_id[f"{pair['condition']}/{pair['a']}/0000"]["time_to_land_s"]),
            (by_id[f"{pair['condition']}/{pair['b']}/0000"]["time_to_land_s"]),
        ]
        landing = pair["time_to_land_difference_s"]
        assert landing["n"] == (1 if None not in times else 0)
        if landing["n"]:
            assert landing["value"] == pytest.approx(times[0] - times[1])
    report = (one_worker / "report.md").read_text()
    assert "The paper's Table I beside ours" in report
    assert "Paired comparisons" in report
    assert "on an obstacle" in report
    for plot in ("success.png", "nearest_person.png", "touchdowns_static.png", "touchdowns_moving_20.png"):
        assert (one_worker / plot).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (one_worker / "results.csv").read_text().count("\n") == 5


def test_missions_in_new_processes_give_the_warm_workers_results(one_worker: Path, tmp_path: Path) -> None:
    """The fixture's campaign flew its four missions on one warm worker (one SITL and one companion process for all);
    with ``--cold`` every mission starts both anew. Every metric must agree."""
    out = tmp_path / "cold"
    run = campaign(out, 2, "--cold")
    _, stderr = run.communicate(timeout=900)
    assert run.returncode == 0, stderr[-3000:]
    cold = {r["mission_id"]: r for r in comparable(read_results(out / "results.jsonl"))}
    warm = {r["mission_id"]: r for r in comparable(read_results(one_worker / "results.jsonl"))}
    assert len(cold) == 4
    assert cold == warm


def test_a_campaign_killed_and_resumed_on_two_workers_gives_the_same_results(one_worker: Path, tmp_path: Path) -> None:
    # One worker at first: it flies the smoke campaign's two scenes one after the other, so the kill after the first
    # scene's results finds the second in flight (two workers would fly both scenes at once, and end them together).
    out = tmp_path / "two"
    run = campaign(out, workers=1, start_new_session=True)
    results_path = out / "results.jsonl"
    deadline = time.monotonic() + 600
    try:
        while not (results_path.is_file() and results_path.read_text().count("\n") >= 1):
            assert run.poll() is None, run.communicate()[1][-3000:]
            assert time.monotonic() < deadline, "no mission finished in 600 s"
            with contextlib.suppress(subprocess.TimeoutExpired):
                run.wait(timeout=0.5)  # paces the poll; returns early only if the campaign ends by itself
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)  # the runner, its workers, their SITLs and companions
        run.communicate()
    interrupted = read_results(results_path)
    assert len(interrupted) == 2  # one scene's two strategies, written together when the scene ends
    resumed = campaign(out, workers=2)
    _, stderr = resumed.communicate(timeout=900)
    assert resumed.returncode == 0, stderr[-3000:]
    final = read_results(results_path)
    assert len(final) == 4
    assert results_path.read_text().count("\n") == 4  # nothing flown twice: the finished kept, the rest flown
    assert comparable(final[: len(interrupted)]) == comparable(interrupted)
    by_id = {r["mission_id"]: r for r in comparable(final)}
    expected = {r["mission_id"]: r for r in comparable(read_results(one_worker / "results.jsonl"))}
    assert by_id == expected
    summary_one = json.loads((one_worker / "summary.json").read_text())
    summary_two = json.loads((out / "summary.json").read_text())
    assert summary_two["cells"] == summary_one["cells"]
    assert summary_two["paired"] == summary_one["paired"]
    assert not math.isnan(summary_two["cells"]["static/oldest"]["success"]["value"])
    # Two segments: the killed one (no end record: its last mission ends it) and the one that finished.
    segments = [json.loads(line) for line in (out / "segments.jsonl").read_text().splitlines()]
    assert [(s["kind"], s["segment"]) for s in segments] == [("start", 1), ("start", 2), ("end", 2)]
    assert (segments[0]["workers"], segments[1]["workers"]) == (1, 2)
    assert segments[2] | {"utc": None} == {
        "kind": "end",
        "segment": 2,
        "utc": None,
        "flown": 4 - len(interrupted),
        "interrupted": False,
    }
    flown = summary_two["flown"]
    missions_by_segment = [(s["number"], s["missions"]) for s in flown["segments"]]
    assert missions_by_segment == [(1, len(interrupted)), (2, 4 - len(interrupted))]
    assert flown["wall_s"] > 0
    assert flown["missions_per_hour"] > 0
    assert "## How it was flown" in (out / "report.md").read_text()


def test_on_a_ray_cluster_with_a_node_killed_the_results_are_the_local_ones(one_worker: Path, tmp_path: Path) -> None:
    pytest.importorskip("ray", reason="Ray comes with the `ray` extra (in `dev`)")
    from ray.cluster_utils import Cluster

    # A cluster of two worker nodes of one CPU each on this machine (the head schedules nothing).
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0, "include_dashboard": False})
    out = tmp_path / "ray"
    try:
        nodes = [cluster.add_node(num_cpus=1) for _ in range(2)]
        cluster.wait_for_nodes()
        run = campaign(out, 2, "--backend", "ray", "--address", cluster.address)
        results_path = out / "results.jsonl"
        deadline = time.monotonic() + 600
        while not (results_path.is_file() and results_path.read_text().count("\n") >= 1):
            assert run.poll() is None, run.communicate()[1][-3000:]
            assert time.monotonic() < deadline, "no mission finished in 600 s"
            with contextlib.suppress(subprocess.TimeoutExpired):
                run.wait(timeout=0.5)  # paces the poll; returns early only if the campaign ends by itself
        # The node that finished first is flying its next mission: kill it (its raylet and workers, SIGKILL).
        first = read_results(results_path)[0]
        victim = next(n for n in nodes if first["node"].endswith("/" + n.node_id[:8]))
        cluster.remove_node(victim, allow_graceful=False)
        stdout, stderr = run.communicate(timeout=900)
        assert run.returncode == 0, stdout[-3000:] + stderr[-3000:]
    finally:
        cluster.shutdown()  # type: ignore[no-untyped-call]
    final = read_results(results_path)
    assert results_path.read_text().count("\n") == 4  # every mission once: the killed one flown again, elsewhere
    assert not any("error" in r for r in final)
    by_id = {r["mission_id"]: r for r in comparable(final)}
    expected = {r["mission_id"]: r for r in comparable(read_results(one_worker / "results.jsonl"))}
    assert by_id == expected  # every metric, touchdown coordinates included
    survivor = next(n for n in nodes if n is not victim).node_id[:8]
    assert {r["node"].rsplit("/", 1)[1] for r in final} == {victim.node_id[:8], survivor}
    assert sum(r["node"].endswith(survivor) for r in final) >= 3  # it flew its own and the victim's last


def processes() -> list[tuple[int, int, str]]:
    """(pid, process group, state) of every process, from /proc."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError):
            fields = stat.read_text().rsplit(")", 1)[1].split()
            out.append((int(stat.parent.name), int(fields[2]), fields[0]))
    return out


def command_line(pid: int) -> str:
    """``pid``'s command line, for a failure message ("" once it is gone)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
    except OSError:
        return ""


def test_ctrl_c_stops_every_process_and_writes_no_result_for_the_missions_in_flight(tmp_path: Path) -> None:
    out = tmp_path / "interrupted"
    # Started as a shell starts a background job: SIGINT ignored. The campaign must still stop on it.
    run = campaign(
        out,
        2,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),
    )
    try:
        # Both workers have a mission in flight: each has started its companion.
        wait_for = out / "missions"
        deadline = time.monotonic() + 300
        while len(list(wait_for.glob("*/*/*/companion.log"))) < 2:
            assert run.poll() is None, run.communicate()[1][-3000:]
            assert time.monotonic() < deadline, "the missions did not start in 300 s"
            with contextlib.suppress(subprocess.TimeoutExpired):
                run.wait(timeout=0.2)  # paces the poll
        run.send_signal(signal.SIGINT)  # the runner only, as `kill -INT` does
        _, stderr = run.communicate(timeout=60)
        assert run.returncode == 130, stderr[-3000:]
        assert "interrupted" in stderr

        # Nothing of the campaign is left: no worker, SITL or companion in its process group.
        def left() -> list[str]:  # every live process (zombies aside) in the campaign's process group
            return [command_line(pid) for pid, pgid, state in processes() if pgid == run.pid and state != "Z"]

        with contextlib.suppress(AssertionError):
            wait_until(lambda: not left(), 30, "every process of the campaign to exit", poll_s=0.2)
        logs = "".join(f"\n--- {log}:\n{log_tail(log, 15)}" for log in sorted(wait_for.glob("*/*/*/companion.log")))
        assert not left(), f"still running 30 s after the campaign ended: {left()}{logs}"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(run.pid, signal.SIGKILL)
    # The missions in flight left no line: they are flown when the campaign resumes.
    lines = (out / "results.jsonl").read_text().splitlines() if (out / "results.jsonl").is_file() else []
    assert not [line for line in lines if '"error"' in line]
    segments = [json.loads(line) for line in (out / "segments.jsonl").read_text().splitlines()]
    assert [(s["kind"], s["segment"]) for s in segments] == [("start", 1), ("end", 1)]
    assert segments[1]["interrupted"] is True


@pytest.mark.slow  # 60 s: one mission flown twice; in `make test-slow`
def test_one_mission_is_re_flown_from_its_seed_with_its_video(one_worker: Path, tmp_path: Path) -> None:
    command = [sys.executable, "-m", "companion.cli", "campaign", "replay", str(one_worker), "static/oldest/0000"]
    command += ["--out", str(tmp_path / "replay")]
    # Twice into the same folder: the second replay starts its own flight log, not a second flight in the first's.
    for _ in range(2):
        done = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=600, check=False)
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
        assert "metrics identical to the campaign's result" in done.stdout
        assert "(replay identical)" in done.stdout
        assert (tmp_path / "replay" / "camera.mp4").stat().st_size > 100_000
    log = (tmp_path / "replay" / "flight" / "flight.jsonl").read_text().splitlines()
    assert [json.loads(line)["kind"] for line in log].count("header") == 1
