"""Before and after at the same time: ``bench/mission_cpu.py`` in two checkouts at once, on the same machine moment.

Run: ``.venv/bin/python -m bench.ab_cpu BEFORE_DIR AFTER_DIR [--rounds 2] [--sample]``. On a shared virtual machine
whose speed drifts by 10 % over minutes, two runs taken one after the other compare the machine's moments as much as
the code (on this project's 2-core machine, the same commit measured 14.5 and 12.7 s of warm CPU per mission ten
minutes apart). Here both checkouts (``git worktree add``) fly ``bench/mission_cpu.py`` together: each flies one
mission at a time, so the two keep both cores busy and meet the same slowdowns. Prints, per round and mission, the
warm CPU seconds of each side and their ratio, and saves ``bench/results/ab_cpu.json`` with the machine's context and
both commits. Each checkout's own ``bench/results/mission_cpu.json`` is put back as it was.

``--spec FILE`` (a path inside the checkouts) flies the missions of another sample spec on both sides instead of
``paper_table1_roi_sample.yaml``, in checkouts of any age (the spec is set in the benchmark's module before it runs):
e.g. ``mission_configs/campaigns/paper_table1_roi_sample_makehuman.yaml``, so that both sides fly the same people when
the before's SITL drew procedural ones by default (issue 63).

``--sample`` flies the whole 63-mission sample instead (``bench/campaign_sample.py --workers 1`` in both checkouts at
once, each one core's worth, into two new folders): missions per hour and CPU seconds per mission of each side, and
whether each mission's metrics are the same on both sides (the sample's own references are still compared by each
side). Saves ``bench/results/ab_sample.json``; each checkout's ``campaign_sample_warm.json`` is put back.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from bench.campaign_sample import SPEC, differences
from bench.machine import machine_context, save_report
from sitl.campaign.runner import read_results
from sitl.campaign.spec import load_campaign_spec

REPO_ROOT = Path(__file__).resolve().parent.parent


RECORD = Path("bench") / "results" / "mission_cpu.json"
WITH_SPEC = (
    "import sys; from pathlib import Path; import importlib; module = importlib.import_module(sys.argv[1]); "
    "module.SPEC = Path(sys.argv[2]).resolve(); sys.argv = [sys.argv[1], *sys.argv[3:]]; "
    "raise SystemExit(module.main())"
)
"""Runs a benchmark module (argv 1) with its sample spec set to argv 2: ``python -c WITH_SPEC MODULE SPEC ARGS...``."""


def bench_command(module: str, spec: Path | None, *args: str) -> list[str]:
    """The command line of ``module`` (``bench.mission_cpu``, ``bench.campaign_sample``) in a checkout, with its
    sample spec replaced by ``spec`` (relative to the checkout) where given."""
    if spec is None:
        return [module.replace(".", "/") + ".py", *args]
    return ["-c", WITH_SPEC, module, str(spec), *args]


SAMPLE_RECORD = Path("bench") / "results" / "campaign_sample_warm.json"
ROUND_TIMEOUT_S = 3600.0


def commit_of(checkout: Path) -> str:
    """The checkout's HEAD commit."""
    done = subprocess.run(["git", "rev-parse", "HEAD"], cwd=checkout, capture_output=True, text=True, check=True)
    return done.stdout.strip()


def fly_together(
    checkouts: list[Path], commands: list[list[str]] | None = None, record: Path = RECORD
) -> list[dict[str, Any]]:
    """In every checkout at once (its own code on ``PYTHONPATH``), its command (by default ``bench/mission_cpu.py``);
    the report each wrote to ``record`` (then put back as it was)."""
    commands = commands or [["bench/mission_cpu.py"] for _ in checkouts]
    kept = [(c / record).read_bytes() if (c / record).is_file() else None for c in checkouts]
    procs = []
    try:
        for checkout, command in zip(checkouts, commands, strict=True):
            env = {**os.environ, "PYTHONPATH": str(checkout)}
            procs.append(
                subprocess.Popen(
                    [sys.executable, *command], cwd=checkout, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
                )
            )
        reports = []
        for checkout, command, proc in zip(checkouts, commands, procs, strict=True):
            output, _ = proc.communicate(timeout=ROUND_TIMEOUT_S)
            if proc.returncode != 0:
                tail = output.decode(errors="replace")[-3000:]
                raise RuntimeError(f"{checkout}: {command[0]} exited {proc.returncode}:\n{tail}")
            reports.append(json.loads((checkout / record).read_text()))
        return reports
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        for checkout, original in zip(checkouts, kept, strict=True):
            if original is not None:
                (checkout / record).write_bytes(original)


def sample_together(checkouts: list[Path], out: Path, spec: Path | None = None) -> int:
    """The 63-mission sample in both checkouts at once, one worker each; both sides' throughput and whether every
    mission flew the same (``--sample``; ``spec``: another sample spec, relative to the checkouts)."""
    folders = [Path(tempfile.mkdtemp(prefix=f"ab-sample-{side}-")) for side in ("before", "after")]
    commands = [bench_command("bench.campaign_sample", spec, "--workers", "1", "--out", str(f)) for f in folders]
    before, after = fly_together(checkouts, commands, SAMPLE_RECORD)
    policies = load_campaign_spec(SPEC if spec is None else checkouts[1] / spec).policies()
    flown = [{r["mission_id"]: r for r in read_results(f / "results.jsonl")} for f in folders]
    differing = {
        mission_id: diff
        for mission_id, b in flown[0].items()
        if (diff := differences(flown[1].get(mission_id, {}), b, policies.get(mission_id)))
    }
    side_keys = ("missions", "errors", "wall_s", "missions_per_hour", "cpu_s_per_mission", "identical", "differing")
    report = {
        "machine": machine_context(),
        "before": {"checkout": str(checkouts[0]), "commit": commit_of(checkouts[0])}
        | {k: before[k] for k in side_keys}
        | {"out": str(folders[0])},
        "after": {"checkout": str(checkouts[1]), "commit": commit_of(checkouts[1])}
        | {k: after[k] for k in side_keys}
        | {"out": str(folders[1])},
        "spec": str(spec or SPEC.relative_to(REPO_ROOT)),
        "missions_per_hour_ratio": round(after["missions_per_hour"] / before["missions_per_hour"], 3),
        "cpu_s_per_mission_ratio": round(after["cpu_s_per_mission"] / before["cpu_s_per_mission"], 3),
        "same_in_both": len(flown[0]) - len(differing),
        "differing_between": differing,
    }
    print(report)
    save_report(report, out)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("before", type=Path, help="checkout of the before (a git worktree)")
    parser.add_argument("after", type=Path, help="checkout of the after")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--sample", action="store_true", help="fly the 63-mission sample in both (one worker each)")
    parser.add_argument("--out", type=Path, help="report (default bench/results/ab_cpu.json, ab_sample.json)")
    parser.add_argument("--spec", type=Path, help="another sample spec, a path inside both checkouts")
    args = parser.parse_args()
    checkouts = [args.before.resolve(), args.after.resolve()]
    results = REPO_ROOT / "bench" / "results"
    if args.sample:
        return sample_together(checkouts, args.out or results / "ab_sample.json", args.spec)
    args.out = args.out or results / "ab_cpu.json"
    rounds = []
    for number in range(1, args.rounds + 1):
        before, after = fly_together(checkouts, [bench_command("bench.mission_cpu", args.spec) for _ in checkouts])
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
        "spec": str(args.spec or SPEC.relative_to(REPO_ROOT)),
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
