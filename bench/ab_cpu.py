"""Before and after at the same time: ``bench/mission_cpu.py`` in two checkouts at once, on the same machine moment.

Run: ``.venv/bin/python bench/ab_cpu.py BEFORE_DIR AFTER_DIR [--rounds 2]``. On a shared virtual machine whose speed
drifts by 10 % over minutes, two runs taken one after the other compare the machine's moments as much as the code (on
this project's 2-core machine, the same commit measured 14.5 and 12.7 s of warm CPU per mission ten minutes apart).
Here both checkouts (``git worktree add``) fly ``bench/mission_cpu.py`` together: each flies one mission at a time,
so the two keep both cores busy and meet the same slowdowns. Prints, per round and mission, the warm CPU seconds of
each side and their ratio, and saves ``bench/results/ab_cpu.json`` with the machine's context and both commits.
Each checkout's own ``bench/results/mission_cpu.json`` is put back as it was.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO_ROOT))

from bench.machine import machine_context, save_report  # noqa: E402

RECORD = Path("bench") / "results" / "mission_cpu.json"
ROUND_TIMEOUT_S = 3600.0


def commit_of(checkout: Path) -> str:
    """The checkout's HEAD commit."""
    done = subprocess.run(["git", "rev-parse", "HEAD"], cwd=checkout, capture_output=True, text=True, check=True)
    return done.stdout.strip()


def fly_together(checkouts: list[Path]) -> list[dict[str, Any]]:
    """``bench/mission_cpu.py`` in every checkout at once (its own code on ``PYTHONPATH``); their reports."""
    kept = [(c / RECORD).read_bytes() if (c / RECORD).is_file() else None for c in checkouts]
    procs = []
    try:
        for checkout in checkouts:
            env = {**os.environ, "PYTHONPATH": str(checkout)}
            command = [sys.executable, "bench/mission_cpu.py"]
            procs.append(
                subprocess.Popen(command, cwd=checkout, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
            )
        reports = []
        for checkout, proc in zip(checkouts, procs, strict=True):
            output, _ = proc.communicate(timeout=ROUND_TIMEOUT_S)
            if proc.returncode != 0:
                tail = output.decode(errors="replace")[-3000:]
                raise RuntimeError(f"{checkout}: bench/mission_cpu.py exited {proc.returncode}:\n{tail}")
            reports.append(json.loads((checkout / RECORD).read_text()))
        return reports
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        for checkout, original in zip(checkouts, kept, strict=True):
            if original is not None:
                (checkout / RECORD).write_bytes(original)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("before", type=Path, help="checkout of the before (a git worktree)")
    parser.add_argument("after", type=Path, help="checkout of the after")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench" / "results" / "ab_cpu.json")
    args = parser.parse_args()
    checkouts = [args.before.resolve(), args.after.resolve()]
    rounds = []
    for number in range(1, args.rounds + 1):
        before, after = fly_together(checkouts)
        missions = {}
        for mission, b in before["missions"].items():
            a = after["missions"][mission]
            missions[mission] = {
                "before_warm_cpu_s": b["warm_cpu_s"],
                "after_warm_cpu_s": a["warm_cpu_s"],
                "ratio": round(a["warm_cpu_s"] / b["warm_cpu_s"], 3),
                "before_sitl_companion_cpu_s": [b["warm_sitl_cpu_s"], b["warm_companion_cpu_s"]],
                "after_sitl_companion_cpu_s": [a["warm_sitl_cpu_s"], a["warm_companion_cpu_s"]],
                "same_metrics_cold_warm": [b["same_metrics"], a["same_metrics"]],
            }
            print(
                f"round {number} {mission}: before {b['warm_cpu_s']:.2f} s, after {a['warm_cpu_s']:.2f} s", flush=True
            )
        mean_before = before["mean_cpu_s"]["warm_cpu_s"]
        mean_after = after["mean_cpu_s"]["warm_cpu_s"]
        rounds.append(
            {
                "missions": missions,
                "mean_warm_cpu_s": [mean_before, mean_after],
                "mean_cold_cpu_s": [before["mean_cpu_s"]["cold_cpu_s"], after["mean_cpu_s"]["cold_cpu_s"]],
                "ratio": round(mean_after / mean_before, 3),
            }
        )
        print(f"round {number}: warm mean before {mean_before:.2f} s, after {mean_after:.2f} s", flush=True)
    all_before = [m["before_warm_cpu_s"] for r in rounds for m in r["missions"].values()]
    all_after = [m["after_warm_cpu_s"] for r in rounds for m in r["missions"].values()]
    report = {
        "machine": machine_context(),
        "before": {"checkout": str(checkouts[0]), "commit": commit_of(checkouts[0])},
        "after": {"checkout": str(checkouts[1]), "commit": commit_of(checkouts[1])},
        "rounds": rounds,
        "warm_cpu_s_per_mission": [
            round(sum(all_before) / len(all_before), 2),
            round(sum(all_after) / len(all_after), 2),
        ],
        "ratio": round(sum(all_after) / sum(all_before), 3),
    }
    print(report)
    save_report(report, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
