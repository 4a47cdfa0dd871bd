"""What the warning for the people below bought, paired mission by mission (issue 53).

Run: ``.venv/bin/python -m bench.warning_outcomes CAMPAIGN_FOLDER [--without silent] [--with warning] [--out FILE.md]``
on a folder flown with ``--keep-runs`` whose conditions have ``scenario.reaction`` on and whose two strategies differ
only in ``guidance.warning`` (``mission_configs/campaigns/warning_walkers.yaml``). For each condition, over the runs
both strategies flew: success (exact McNemar), and the paired mean differences (with - without, 95 % bootstrap) of
the time to land (both landed), the nearest body during the final descent (its minimum and its mean), the nearest
body at the touchdown, the seconds the descent waited at the walker gate and the aborted descents; and, from the
SITL's truth, how long the warning sounded and how many people reacted to it.
"""

from __future__ import annotations

import argparse
import itertools
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

from companion.flightlog.flight_log import DecisionRecord, FlightLog, RecordKind
from companion.guidance.vocabulary import DecisionEvent
from sitl.campaign.runner import read_results
from sitl.campaign.stats import Estimate, mcnemar_exact, paired_mean_difference
from sitl.vehicle.truth import read_truth


def gate_wait_s(flight: Path) -> float:
    """Seconds of vehicle time the flight's descents waited at the walker gate (from each waiting decision to the
    next decision)."""
    decisions = [DecisionRecord.from_record(r) for r in FlightLog.read(flight).of(RecordKind.DECISION)]
    return sum(
        later.t_s - now.t_s for now, later in itertools.pairwise(decisions) if now.event is DecisionEvent.WAIT_AT_GATE
    )


def warning_of(truth: Path) -> tuple[float, int]:
    """From a mission's ground truth: seconds the warning device sounded, and people's reactions to it."""
    _, records = read_truth(truth)
    sounded = sum(later.t_s - now.t_s for now, later in itertools.pairwise(records) if now.warning)
    return sounded, max((r.reactions for r in records), default=0)


def mission_measures(folder: Path, result: dict[str, Any]) -> dict[str, Any]:
    """One flown mission's measures: its result's, and those read from its flight log and ground truth."""
    run = folder / "missions" / result["mission_id"]
    sounded_s, reactions = warning_of(run / "truth.jsonl")

    def number(key: str) -> float:
        value = result.get(key)
        return math.nan if value is None else float(value)

    return {
        "success": bool(result["success"]),
        "landed": bool(result["landed"]),
        "time_to_land_s": number("time_to_land_s"),
        "nearest_person_min_m": number("nearest_person_min_m"),
        "nearest_person_mean_m": number("nearest_person_mean_m"),
        "touchdown_nearest_m": number("touchdown_nearest_m"),
        "gate_wait_s": gate_wait_s(run / "flight"),
        "aborts": number("aborts"),
        "warning_s": sounded_s,
        "reactions": float(reactions),
        "body_within_1m": (result.get("people_within_1m") or 0) > 0,
    }


PAIRED = (
    ("time_to_land_s", "time to land (s), both landed", 1),
    ("nearest_person_min_m", "nearest body in the final descent, min (m)", 2),
    ("nearest_person_mean_m", "nearest body in the final descent, mean (m)", 2),
    ("touchdown_nearest_m", "nearest body at touchdown (m)", 2),
    ("gate_wait_s", "waited at the walker gate (s)", 1),
    ("aborts", "aborted descents", 2),
    ("warning_s", "warning sounded (s)", 1),
    ("reactions", "people who reacted", 1),
)


def tabulate(folder: Path, without: str, with_: str) -> str:
    """The Markdown tables (see the module docstring)."""
    by_cell: dict[tuple[str, str], dict[int, dict[str, Any]]] = defaultdict(dict)
    for result in read_results(folder / "results.jsonl"):
        if "error" in result or result["strategy"] not in (without, with_):
            continue
        by_cell[(result["condition"], result["strategy"])][int(result["run"])] = mission_measures(folder, result)
    lines = []
    for condition in sorted({c for c, _ in by_cell}):
        a, b = by_cell[(condition, without)], by_cell[(condition, with_)]
        runs = sorted(set(a) & set(b))
        test = mcnemar_exact([b[r]["success"] for r in runs], [a[r]["success"] for r in runs])
        lines += [f"### {condition}: {len(runs)} scenes flown {without} and {with_}", ""]
        lines += [
            f"Success: {with_} {sum(b[r]['success'] for r in runs)}, {without} {sum(a[r]['success'] for r in runs)} "
            f"of {len(runs)}; only {with_} {test.only_a}, only {without} {test.only_b}, "
            f"McNemar p = {test.p_value:.3g}. "
            f"Landed: {sum(b[r]['landed'] for r in runs)} / {sum(a[r]['landed'] for r in runs)}. "
            f"A body within 1 m of the touchdown: {sum(b[r]['body_within_1m'] for r in runs)} / "
            f"{sum(a[r]['body_within_1m'] for r in runs)}.",
            "",
            f"| measure | {with_}, mean | {without}, mean | {with_} - {without}, paired (95 %) | pairs |",
            "| --- | --- | --- | --- | --- |",
        ]
        for key, label, digits in PAIRED:
            x, y = [b[r][key] for r in runs], [a[r][key] for r in runs]
            diff = paired_mean_difference(x, y, seed=11)
            lines.append(f"| {label} | {_mean(x, digits)} | {_mean(y, digits)} | {_format(diff, digits)} | {diff.n} |")
        lines.append("")
    return "\n".join(lines)


def _mean(values: list[float], digits: int) -> str:
    finite = [v for v in values if math.isfinite(v)]
    return f"{sum(finite) / len(finite):.{digits}f}" if finite else "n/a"


def _format(estimate: Estimate, digits: int) -> str:
    if estimate.n == 0 or not math.isfinite(estimate.value):
        return "n/a"
    return f"{estimate.value:+.{digits}f} [{estimate.low:+.{digits}f}, {estimate.high:+.{digits}f}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a campaign folder flown with --keep-runs")
    parser.add_argument("--without", default="silent", help="the strategy without the warning")
    parser.add_argument("--with", dest="with_", default="warning", help="the strategy with it")
    parser.add_argument("--out", type=Path, help="also write the tables here")
    args = parser.parse_args()
    text = tabulate(args.folder, args.without, args.with_)
    print(text)
    if args.out is not None:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
