"""CPU seconds one campaign mission costs, cold (new processes) and warm (a worker's kept processes), one at a time.

Run: ``.venv/bin/python -m bench.mission_cpu [--missions ID ...]``. Flies each mission of
``mission_configs/campaigns/paper_table1_roi_sample.yaml`` named (default: four, one per kind of cell) alone on this
machine, first with new processes, then on one warm worker (after one warm-up mission that pays the imports), and
measures per mission the wall time and the CPU time (user + system, every thread) of every process involved: the
worker itself, its SITL and its companion. Cold, the SITL and companion are children the worker reaps
(``RUSAGE_CHILDREN``); warm, their CPU is read from ``/proc/<pid>/stat`` before and after. Prints and saves
``bench/results/mission_cpu.json``, each mission's metrics compared cold against warm (they must agree).
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.campaign_sample import NOT_METRICS, SPEC, differences
from bench.machine import machine_context, save_report
from sitl.campaign.spec import load_campaign_spec
from sitl.campaign.worker import fly_one
from sitl.harness.instances import leased_instance
from sitl.harness.warm import WarmWorker

REPO_ROOT = Path(__file__).resolve().parent.parent


MISSIONS = ("static/oldest/0001", "moving_10/biggest/0001", "moving_20/oldest/0001", "weather/biggest/0001")
WARM_UP = "static/random/0000"
TICKS_PER_S = os.sysconf("SC_CLK_TCK")


def process_cpu_s(pid: int) -> float:
    """User + system CPU seconds of a live process, all its threads (``/proc/<pid>/stat``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS_PER_S


def own_and_children_cpu_s() -> tuple[float, float]:
    """This process's CPU seconds, and its reaped children's."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--missions", nargs="+", default=list(MISSIONS))
    args = parser.parse_args()
    spec = load_campaign_spec(SPEC).model_dump(mode="json")
    out = Path(tempfile.mkdtemp(prefix="mission-cpu-"))
    rows: dict[str, dict[str, Any]] = {}
    results: dict[str, dict[str, dict[str, Any]]] = {"cold": {}, "warm": {}}
    with leased_instance() as lease:
        for mission_id in args.missions:
            own0, children0 = own_and_children_cpu_s()
            started = time.monotonic()
            results["cold"][mission_id] = fly_one(spec, mission_id, str(out / "cold"), False, lease.instance)
            own1, children1 = own_and_children_cpu_s()
            rows[mission_id] = {
                "cold_wall_s": round(time.monotonic() - started, 2),
                "cold_cpu_s": round(own1 - own0 + children1 - children0, 2),
            }
        worker = WarmWorker(lease.instance, out / "warm-logs")
        try:
            fly_one(spec, WARM_UP, str(out / "warm"), False, lease.instance, worker)
            for mission_id in args.missions:
                pids = (worker.sitl_process.pid, worker.companion_process.pid)
                before = [process_cpu_s(pid) for pid in pids]
                own0, _ = own_and_children_cpu_s()
                started = time.monotonic()
                flown = fly_one(spec, mission_id, str(out / "warm"), False, lease.instance, worker)
                results["warm"][mission_id] = flown
                own1, _ = own_and_children_cpu_s()
                if (worker.sitl_process.pid, worker.companion_process.pid) != pids:
                    raise RuntimeError(f"{mission_id}: a warm process was replaced: {flown}")
                after = [process_cpu_s(pid) for pid in pids]
                sitl_s, companion_s = (a - b for a, b in zip(after, before, strict=True))
                rows[mission_id] |= {
                    "warm_wall_s": round(time.monotonic() - started, 2),
                    "warm_cpu_s": round(own1 - own0 + sitl_s + companion_s, 2),
                    "warm_sitl_cpu_s": round(sitl_s, 2),
                    "warm_companion_cpu_s": round(companion_s, 2),
                }
        finally:
            worker.close()
    for mission_id, row in rows.items():
        cold, warm = results["cold"][mission_id], results["warm"][mission_id]
        row["time_to_land_s"] = cold.get("time_to_land_s")
        row["same_metrics"] = not differences(warm, cold) and "error" not in cold
        row["differing"] = differences(warm, cold)
    mean = {k: round(sum(r[k] for r in rows.values()) / len(rows), 2) for k in ("cold_cpu_s", "warm_cpu_s")}
    report = {
        "machine": machine_context(),
        "spec": str(SPEC.relative_to(REPO_ROOT)),
        "not_compared": sorted(NOT_METRICS),
        "missions": rows,
        "mean_cpu_s": mean,
        "cpu_saved": round(1.0 - mean["warm_cpu_s"] / mean["cold_cpu_s"], 3),
    }
    print(report)
    save_report(report, REPO_ROOT / "bench" / "results" / "mission_cpu.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
