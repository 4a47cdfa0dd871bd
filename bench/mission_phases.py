"""Where a warm mission's CPU goes, by phase of the flight: the SITL's and the companion's CPU seconds in each.

Run: ``.venv/bin/python -m bench.mission_phases [--missions ID ...] [--out PATH]``. One warm worker (after one
warm-up mission that pays the imports) flies the missions named (default: a scene the SITL has not built, then a
second strategy of the same scene, then a walker mission) of ``mission_configs/campaigns/paper_table1_roi_sample.yaml``
one after the other. While each flies, a thread reads both processes' CPU time (``/proc/<pid>/stat``, every thread)
and the simulated time of the newest ground-truth record every 50 ms; each interval's CPU goes to the flight phase
(from the flight log's phase records) the simulated time was in:

- ``setup``: before the first ground-truth record (the SITL builds the scene and vehicle, the companion connects and
  subscribes to the lockstep);
- ``start``: take-off and transit to the start pose (no frames drawn);
- ``search``, ``approach``, ``descent``: the landing logic at work, a frame every tick;
- ``land`` and ``done``: the autopilot lands and the SITL ends itself.

The ground truth is written in blocks, so a few ticks of ``start`` are counted in ``setup``; CPU between two samples
goes to the later sample's phase. Saves ``bench/results/mission_phases.json`` with the machine's context.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

from bench.campaign_sample import SPEC
from bench.machine import machine_context, save_report
from bench.mission_cpu import WARM_UP, process_cpu_s
from companion.flightlog.flight_log import FlightLog
from sitl.campaign.spec import load_campaign_spec
from sitl.campaign.worker import fly_one
from sitl.harness.instances import leased_instance
from sitl.harness.warm import WarmWorker

REPO_ROOT = Path(__file__).resolve().parent.parent


MISSIONS = ("static/oldest/0001", "static/biggest/0001", "moving_20/oldest/0001")
PHASES = ("setup", "start", "search", "approach", "descent", "land", "done")
SAMPLE_S = 0.05


def newest_truth_t_s(path: Path) -> float | None:
    """Simulated time of the newest complete ground-truth record, or None before the first."""
    try:
        with path.open("rb") as f:
            f.seek(0, 2)
            f.seek(max(0, f.tell() - 8192))
            lines = f.read().splitlines()
    except OSError:
        return None
    for line in reversed(lines):
        try:
            t_s = json.loads(line).get("t_s")
        except (json.JSONDecodeError, UnicodeDecodeError, AttributeError):
            continue
        if isinstance(t_s, float | int):
            return float(t_s)
    return None


def fly_sampled(
    spec: dict[str, Any], mission_id: str, out: Path, instance: int, worker: WarmWorker
) -> dict[str, dict[str, float]]:
    """Fly one mission on the warm worker; CPU seconds of each process in each phase."""
    pids = (worker.sitl_process.pid, worker.companion_process.pid)
    truth = out / "missions" / mission_id / "truth.jsonl"
    samples: list[tuple[float | None, float, float]] = []
    stop = threading.Event()

    def sample() -> None:
        while not stop.is_set():
            samples.append((newest_truth_t_s(truth), process_cpu_s(pids[0]), process_cpu_s(pids[1])))
            stop.wait(SAMPLE_S)

    previous = (process_cpu_s(pids[0]), process_cpu_s(pids[1]))
    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    try:
        fly_one(spec, mission_id, str(out), True, instance, worker)
    finally:
        stop.set()
        sampler.join()
    samples.append((None, process_cpu_s(pids[0]), process_cpu_s(pids[1])))
    starts = FlightLog.read(out / "missions" / mission_id / "flight").phases()
    cpu: dict[str, list[float]] = collections.defaultdict(lambda: [0.0, 0.0])
    last_phase = "setup"
    for t_s, sitl_s, companion_s in samples:
        if t_s is not None:
            last_phase = "start"
            for start_s, phase in starts:
                if t_s >= start_s:
                    last_phase = phase
        cpu[last_phase][0] += sitl_s - previous[0]
        cpu[last_phase][1] += companion_s - previous[1]
        previous = (sitl_s, companion_s)
    return {
        phase: {"sitl_cpu_s": round(cpu[phase][0], 2), "companion_cpu_s": round(cpu[phase][1], 2)}
        for phase in [*PHASES, *sorted(set(cpu) - set(PHASES))]
        if phase in cpu
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--missions", nargs="+", default=list(MISSIONS))
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench" / "results" / "mission_phases.json")
    args = parser.parse_args()
    spec = load_campaign_spec(SPEC).model_dump(mode="json")
    out = Path(tempfile.mkdtemp(prefix="mission-phases-"))
    missions: dict[str, dict[str, Any]] = {}
    with leased_instance() as lease:
        worker = WarmWorker(lease.instance, out / "warm-logs")
        try:
            fly_one(spec, WARM_UP, str(out), False, lease.instance, worker)
            for mission_id in args.missions:
                phases = fly_sampled(spec, mission_id, out, lease.instance, worker)
                totals = {k: round(sum(p[k] for p in phases.values()), 2) for k in ("sitl_cpu_s", "companion_cpu_s")}
                missions[mission_id] = {"phases": phases, "total": totals}
                sys.stdout.write(f"{mission_id}: {totals}\n")
                for phase, row in phases.items():
                    sys.stdout.write(
                        f"  {phase:<9} SITL {row['sitl_cpu_s']:5.2f} s  companion {row['companion_cpu_s']:5.2f} s\n"
                    )
        finally:
            worker.close()
    report = {"machine": machine_context(), "spec": str(SPEC.relative_to(REPO_ROOT)), "missions": missions}
    save_report(report, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
