"""Throughput on the ROI paper table's own missions, and whether the committed table still reproduces.

Run: ``.venv/bin/python -m bench.campaign_sample [--workers 2] [--backend local|ray] [--cold] [--out DIR]
[--compare DIR]``. Flies ``mission_configs/campaigns/paper_table1_roi_sample.yaml`` (runs 0 to 6 of each of the nine
cells: 63 missions with the table's seeds and start poses) into a new folder, warm workers unless ``--cold``, then
prints and saves ``bench/results/campaign_sample_<warm|cold>.json``: missions per hour of wall time, missions per
core-hour (a cluster user sizes a run with it), the mean wall time of a mission, the CPU time all processes took per
mission, and, mission by mission, whether every metric (touchdown coordinates included) equals the newest committed
result of the same mission (:data:`REFERENCES`). A mission that differs is listed with the fields that differ: the
references were flown at earlier commits, so a difference is a change of behaviour since, intended or not.
``--compare DIR`` also compares every mission with another campaign folder of the same sample (flown cold, or at
another commit: the before of a before/after).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.machine import machine_context, save_report
from sitl.campaign.metric_fields import field_infos
from sitl.campaign.metrics import with_gate_overflight
from sitl.campaign.record import FlownMission, compared_fields, parse_result
from sitl.campaign.runner import Backend, read_results, run_campaign
from sitl.campaign.spec import load_campaign_spec

REPO_ROOT = Path(__file__).resolve().parent.parent


SPEC = REPO_ROOT / "mission_configs" / "campaigns" / "paper_table1_roi_sample.yaml"
# Committed results of the same missions, newest first: the ROI table itself, flown at 8b4f6ba, 91405d5 and f47a508
# (docs/results/paper_table1_roi.md; the walker campaign of 1dfd031 that flew the moving_20 cells with the same
# seeds predates the commitment of issue 33, so its missions no longer reproduce and it is not a reference).
REFERENCES = (REPO_ROOT / "docs" / "results" / "paper_table1_roi" / "results.jsonl",)
NOT_METRICS = set(field_infos(FlownMission)) - set(compared_fields())
"""The facts of a mission's run, which two flights of it need not share (their field metadata)."""


def differences(flown: dict[str, Any], committed: dict[str, Any], policy: str | None = None) -> list[str]:
    """The fields of ``flown`` whose value differs from the committed result's (absent fields included). A result of
    an earlier metrics version is first completed with the fields a later version added where no flight is needed
    (:func:`sitl.campaign.metrics.with_gate_overflight`, for the mission's selection ``policy``); a stale one keeps
    its difference. The fields compared are the outcomes of a flight (their metadata,
    :func:`sitl.campaign.record.compared_fields`), not the facts of its run (wall time, node, commit)."""
    flown, committed = with_gate_overflight(flown, policy), with_gate_overflight(committed, policy)
    for line in (flown, committed):
        parse_result(line)  # ResultError names a field that is not a result's
    return sorted(k for k in compared_fields() if flown.get(k) != committed.get(k))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--backend", choices=[b.value for b in Backend], default=Backend.LOCAL.value)
    parser.add_argument("--address", help="ray: the cluster's address")
    parser.add_argument("--out", type=Path, help="campaign folder (default: a new temporary one)")
    parser.add_argument("--cold", action="store_true", help="new processes for every mission (the before)")
    parser.add_argument("--compare", type=Path, help="another campaign folder of this sample: compare every mission")
    args = parser.parse_args()
    spec = load_campaign_spec(SPEC)
    policies = spec.policies()
    out = args.out or Path(tempfile.mkdtemp(prefix="campaign-sample-"))
    started, cpu_before = time.monotonic(), os.times()
    results = run_campaign(
        spec, out, workers=args.workers, backend=Backend(args.backend), address=args.address, warm=not args.cold
    )
    wall_s = time.monotonic() - started
    cpu_after = os.times()  # this process and every child it waited for (workers reap their SITLs and companions)
    cpu_s = sum(after - before for after, before in zip(cpu_after[:4], cpu_before[:4], strict=True))
    compared: dict[str, str] = {}
    differing: dict[str, list[str]] = {}
    for reference in REFERENCES:
        committed = {r["mission_id"]: r for r in read_results(reference)}
        for r in results:
            mission_id = r["mission_id"]
            if mission_id in compared or mission_id not in committed:
                continue
            compared[mission_id] = str(reference.parent.relative_to(REPO_ROOT))
            if diff := differences(r, committed[mission_id], policies.get(mission_id)):
                differing[mission_id] = diff
    against: dict[str, list[str]] = {}
    if args.compare is not None:
        other = {r["mission_id"]: r for r in read_results(args.compare / "results.jsonl")}
        against = {
            r["mission_id"]: differences(r, other.get(r["mission_id"], {}), policies.get(r["mission_id"]))
            for r in results
        }
    cores = args.workers if args.backend == Backend.LOCAL.value else os.cpu_count() or 1
    report = {
        "machine": machine_context(),
        "spec": str(SPEC.relative_to(REPO_ROOT)),
        "backend": args.backend,
        "warm": not args.cold,
        "workers": args.workers,
        "missions": len(results),
        "errors": sum("error" in r for r in results),
        "wall_s": round(wall_s, 1),
        "missions_per_hour": round(3600.0 * len(results) / wall_s, 1),
        "missions_per_core_hour": round(3600.0 * len(results) / wall_s / cores, 1),
        "mean_mission_wall_s": round(sum(float(r.get("wall_s", 0.0)) for r in results) / max(len(results), 1), 2),
        "cpu_s_per_mission": round(cpu_s / max(len(results), 1), 2) if args.backend == Backend.LOCAL.value else None,
        "compared_with": compared,
        "identical": len(compared) - len(differing),
        "differing": differing,
        "out": str(out),
    }
    if args.compare is not None:
        report["compared_folder"] = str(args.compare)
        report["identical_to_compared"] = sum(not d for d in against.values())
        report["differing_from_compared"] = {k: d for k, d in against.items() if d}
    print(report)
    save_report(report, REPO_ROOT / "bench" / "results" / f"campaign_sample_{'cold' if args.cold else 'warm'}.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
