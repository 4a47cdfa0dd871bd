"""The campaign report: per condition x strategy, every metric with its 95 % interval, the paper's Table I beside
ours, paired comparisons of strategies on the same scenes, as Markdown, CSV and JSON, plus plots.

Rates carry Wilson intervals, means percentile-bootstrap intervals (seeded); success between two strategies of one
condition is compared with the exact McNemar test on the paired missions, distances with a paired bootstrap of the
per-mission differences. Our success rate against the paper's (independent samples, the paper's 100 runs per row) is
a difference with Newcombe's interval and Fisher's exact test, Holm-adjusted over the rows. Missions that failed for
infrastructure reasons (``error``) are counted and left out.
"""

from __future__ import annotations

import collections
import csv
import itertools
import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from companion.flightlog.recorder import read_log
from sitl.campaign.metric_fields import Summary, fields_of
from sitl.campaign.metrics import HOLD_CAUSES, MissionMetrics, park_layout, stale, with_obstacles
from sitl.campaign.provenance import Segment, SegmentLog, segments
from sitl.campaign.record import FlownMission, MissionFailure, flown_missions, parse_results
from sitl.campaign.spec import CampaignSpec
from sitl.campaign.stats import (
    Estimate,
    bootstrap_mean,
    holm,
    mcnemar_exact,
    paired_mean_difference,
    rate_difference,
    wilson,
)
from sitl.world.park import ParkObject

# The paper's Table I (AirSim + Unreal, 100 runs per row): success %, warning 1 m %, warning 1.5 m %, SLZ area m^2,
# average nearest person m, IoU. None where the paper gives '*'. Keyed by (condition, strategy) as named in
# mission_configs/campaigns/paper_table1.yaml.
PAPER_TABLE1: dict[tuple[str, str], tuple[float, float, float, float | None, float, float | None]] = {
    ("static", "random"): (59.0, 2.7, 10.0, None, 1.1579, None),
    ("static", "oldest"): (97.0, 0.0, 0.4, 6.153, 2.2197, 0.484),
    ("static", "biggest"): (99.0, 0.0, 0.3, 9.621, 2.4508, 0.593),
    ("moving_10", "oldest"): (87.0, 0.06, 0.16, 4.5996, 1.9706, 0.394),
    ("moving_10", "biggest"): (80.0, 0.01, 0.1, 9.079, 1.7087, 0.607),
    ("moving_20", "oldest"): (84.0, 0.06, 0.14, 4.374, 1.5848, 0.421),
    ("moving_20", "biggest"): (76.0, 0.09, 0.2, 8.042, 1.5136, 0.549),
    ("weather", "oldest"): (86.0, 0.08, 0.16, 4.495, 1.8451, 0.527),
    ("weather", "biggest"): (80.0, 0.06, 0.1, 6.9582, 2.074, 0.540),
}
# "For each scenario condition, 100 iterations of autonomous landing missions have been performed" (the paper's
# experimental section): its success percentages are counts of 100.
PAPER_RUNS_PER_ROW = 100

MEANS = fields_of(MissionMetrics, Summary.MEAN)
"""The metrics a cell reports as means with a bootstrap interval, in the report's order (their field metadata)."""
RATES = fields_of(MissionMetrics, Summary.RATE)
"""The metrics a cell reports as rates with Wilson's interval (their field metadata)."""


def _values(rows: list[FlownMission], key: str) -> list[float]:
    """A mean's values: the missions where it applies (NaN where it does not)."""
    values = (float(getattr(r, key)) for r in rows)
    return [v for v in values if math.isfinite(v)]


def cell_summary(rows: list[FlownMission], errors: int, seed: int) -> dict[str, Any]:
    """Every metric of one cell with its interval, and its holds counted by cause."""
    out: dict[str, Any] = {"missions": len(rows), "errors": errors}
    for key in RATES:
        out[key] = asdict(wilson(sum(1 for r in rows if getattr(r, key)), len(rows)))
    for k, key in enumerate(MEANS):
        out[key] = asdict(bootstrap_mean(_values(rows, key), seed + k))
    out["holds"] = dict(sorted(collections.Counter(hold_kind(r) for r in rows if not r.landed).items()))
    out["endings"] = dict(sorted(collections.Counter(r.ending or BEFORE_ENDINGS for r in rows).items()))
    out["landed_unsafe"] = sum(1 for r in rows if r.landed and not r.success)
    out["overflown_above_gate"] = sum(1 for r in rows if r.overflown_above_gate)
    return out


BEFORE_ENDINGS = "before version 7"
"""A result's ending when it was computed before metrics version 7 recorded endings."""
ENDING_WORDS = {
    "zone": "a zone the map chose",
    "fallback_site": "a fallback site",
    "hold": "hold",
    "return": "return",
    "failsafe_land": "landing in place (failsafe)",
    "other": "other",
}
"""The report's words for each ending (:class:`sitl.campaign.landing_kinds.LandingKind`)."""


def hold_kind(result: FlownMission) -> str:
    """A hold's cause (metrics version 5: :func:`sitl.campaign.metrics.hold_cause`); for an earlier result, its
    final reason, marked as such."""
    if result.hold_cause is not None:
        return result.hold_cause
    return f"(before version 5) {result.reason.split(':')[0].split(';')[0]}"


def against_previous(
    spec: CampaignSpec, results: list[FlownMission], previous: list[FlownMission]
) -> list[dict[str, Any]]:
    """Each cell's success against an earlier flight of the same spec, mission by mission (the same scenes and start
    poses): exact two-sided McNemar test, Holm-adjusted over the cells."""
    now = {r.mission_id: r for r in results}
    before = {r.mission_id: r for r in previous}
    rows: list[dict[str, Any]] = []
    tests = []
    for condition, strategy in spec.cell_names():
        ids = sorted(m for m in set(now) & set(before) if now[m].condition == condition and now[m].strategy == strategy)
        test = mcnemar_exact([before[m].success for m in ids], [now[m].success for m in ids])
        tests.append(test)
        rows.append(
            {
                "cell": f"{condition}/{strategy}",
                "pairs": test.n_pairs,
                "before": sum(before[m].success for m in ids),
                "now": sum(now[m].success for m in ids),
                "only_before": test.only_a,
                "only_now": test.only_b,
                "p": test.p_value,
            }
        )
    for row, p_holm in zip(rows, holm([t.p_value for t in tests]), strict=True):
        row["p_holm"] = p_holm
    return rows


SAME_POINT_M = 1.0
"""Two missions chose the same zone (landed on the same point) when its centres (their touchdowns) lie this close."""


def same_point(a: FlownMission, b: FlownMission, kind: str) -> bool | None:
    """Whether two missions of one scene chose the same first zone (``kind`` ``first_zone``) or touched down at the
    same point (``touchdown``), within :data:`SAME_POINT_M`; None where either has no such point (no zone chosen,
    no touchdown, a result before metrics version 8)."""
    pa = (getattr(a, f"{kind}_north_m"), getattr(a, f"{kind}_east_m"))
    pb = (getattr(b, f"{kind}_north_m"), getattr(b, f"{kind}_east_m"))
    if not all(v is not None and math.isfinite(v) for v in (*pa, *pb)):
        return None
    return math.hypot(pa[0] - pb[0], pa[1] - pb[1]) <= SAME_POINT_M


def _flown(spec: CampaignSpec, results: list[dict[str, Any]]) -> list[FlownMission]:
    """The flown missions of stored result lines, completed (:func:`completed`) and read as typed records."""
    return flown_missions(parse_results(completed(spec, results)))


def completed(spec: CampaignSpec, results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The results, those of an earlier metrics version completed where that needs no flight: what lies under the
    touchdown, from the mission's seed (:func:`sitl.campaign.metrics.with_obstacles`)."""
    plans = {plan.mission_id: plan for plan in spec.missions()}
    radii: dict[str, float] = {}
    layouts: dict[tuple[int, float, tuple[tuple[float, float, float], ...]], list[ParkObject]] = {}
    out = []
    for r in results:
        plan = plans.get(r["mission_id"])
        if "error" in r or "obstacle_distance_m" in r or plan is None:
            out.append(r)
            continue
        objects: list[ParkObject] = []
        if r.get("touchdown_north_m") is not None:
            scenario = plan.scenario()
            key = (plan.seed, scenario.roi_side_m, tuple(scenario.clear_ne_m))
            if key not in layouts:
                layouts[key] = park_layout(*key)
            objects = layouts[key]
        if plan.strategy.name not in radii:
            radii[plan.strategy.name] = plan.vehicle_radius_m(spec)
        out.append(with_obstacles(r, objects, radii[plan.strategy.name]))
    return out


def build_report(
    spec: CampaignSpec,
    results: list[dict[str, Any]],
    out_dir: Path,
    previous: tuple[str, list[dict[str, Any]]] | None = None,
) -> dict[str, Any]:
    """Write ``report.md``, ``results.csv``, ``summary.json`` and the plots into ``out_dir``; returns the summary.

    ``previous``, a name and the results of an earlier flight of the same spec, adds a paired comparison with it.
    """
    results = completed(spec, results)
    records = parse_results(results)
    good = flown_missions(records)
    failed = [r for r in records if isinstance(r, MissionFailure)]
    policies = spec.policies()
    cells: dict[str, Any] = {}
    for k, (condition, strategy) in enumerate(spec.cell_names()):
        rows = [r for r in good if r.condition == condition and r.strategy == strategy]
        errors = sum(1 for r in failed if r.condition == condition and r.strategy == strategy)
        cells[f"{condition}/{strategy}"] = cell_summary(rows, errors, seed=1000 * k)
    paired = []
    for condition in dict.fromkeys(c for c, _ in spec.cell_names()):
        strategies = [s for c, s in spec.cell_names() if c == condition]
        for a, b in itertools.combinations(strategies, 2):
            by_run_a = {r.run: r for r in good if r.condition == condition and r.strategy == a}
            by_run_b = {r.run: r for r in good if r.condition == condition and r.strategy == b}
            runs = sorted(set(by_run_a) & set(by_run_b))
            test = mcnemar_exact([by_run_a[i].success for i in runs], [by_run_b[i].success for i in runs])
            diff = paired_mean_difference(
                [by_run_a[i].nearest_person_mean_m for i in runs],
                [by_run_b[i].nearest_person_mean_m for i in runs],
                seed=7,
            )
            landing = paired_mean_difference(  # over the pairs where both touched down
                [by_run_a[i].time_to_land_s for i in runs], [by_run_b[i].time_to_land_s for i in runs], seed=8
            )
            same_zone = [same_point(by_run_a[i], by_run_b[i], "first_zone") for i in runs]
            same_touchdown = [same_point(by_run_a[i], by_run_b[i], "touchdown") for i in runs]
            paired.append(
                {
                    "condition": condition,
                    "a": a,
                    "b": b,
                    "pairs": test.n_pairs,
                    "same_first_zone": sum(x is True for x in same_zone),
                    "first_zone_pairs": sum(x is not None for x in same_zone),
                    "same_touchdown": sum(x is True for x in same_touchdown),
                    "touchdown_pairs": sum(x is not None for x in same_touchdown),
                    "success_only_a": test.only_a,
                    "success_only_b": test.only_b,
                    "mcnemar_p": test.p_value,
                    "nearest_person_mean_difference_m": asdict(diff),
                    "time_to_land_difference_s": asdict(landing),
                }
            )
    against_paper = paper_comparison(cells)
    every_line = read_log(out_dir / "results.jsonl") if (out_dir / "results.jsonl").is_file() else None
    flown = segments(results, SegmentLog(out_dir / "segments.jsonl"), spec.workers, every_line)
    wall_s = sum(seg.wall_s for seg in flown)
    summary = {
        "campaign": spec.name,
        "missions": len(results),
        "errors": len(results) - len(good),
        "stale": sum(stale(r, policies.get(r["mission_id"])) for r in results if "error" not in r),
        "cells": cells,
        "paired": paired,
        "paper": against_paper,
        "previous": None
        if previous is None
        else {
            "name": previous[0],
            "cells": against_previous(spec, good, _flown(spec, previous[1])),
        },
        "flown": {
            "wall_s": wall_s,
            "missions_per_hour": 3600.0 * len(good) / wall_s if wall_s > 0 else None,
            "commits": sorted({c for seg in flown for c in seg.commits}),
            "segments": [asdict(seg) for seg in flown],
        },
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    _write_csv(results, out_dir / "results.csv")
    plots = _plots(spec, good, cells, out_dir)
    (out_dir / "report.md").write_text(_markdown(spec, summary, plots))
    return summary


def paper_comparison(cells: dict[str, Any]) -> list[dict[str, Any]]:
    """Our success rate against the paper's Table I, row by row, as independent samples.

    Parameters
    ----------
    cells : dict
        ``cell_summary`` by ``"condition/strategy"``; rows the paper does not have, or without missions, are skipped.

    Returns
    -------
    list of dict
        Per row: both counts, ``difference`` (ours - paper, a rate in [-1, 1], with Newcombe's 95 % interval),
        Fisher's exact ``p`` and ``p_holm`` (Holm-adjusted over the rows returned).
    """
    rows: list[dict[str, Any]] = []
    for name, cell in cells.items():
        condition, strategy = name.split("/")
        paper = PAPER_TABLE1.get((condition, strategy))
        n = int(cell["success"]["n"])
        if paper is None or n == 0:
            continue
        ours = round(cell["success"]["value"] * n)
        theirs = round(paper[0] * PAPER_RUNS_PER_ROW / 100.0)
        test = rate_difference(ours, n, theirs, PAPER_RUNS_PER_ROW)
        rows.append(
            {
                "cell": name,
                "ours_successes": ours,
                "ours_missions": n,
                "paper_successes": theirs,
                "paper_missions": PAPER_RUNS_PER_ROW,
                "difference": asdict(test.difference),
                "p": test.p_value,
            }
        )
    for row, adjusted in zip(rows, holm([r["p"] for r in rows]), strict=True):
        row["p_holm"] = adjusted
    return rows


def _write_csv(results: list[dict[str, Any]], path: Path) -> None:
    keys = [k for k in results[0] if k != "people_cells"] if results else []
    for r in results:
        keys += [k for k in r if k not in keys and k != "people_cells"]
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        for r in results:
            writer.writerow(r)


def _est(d: dict[str, Any]) -> Estimate:
    return Estimate(d["value"], d["low"], d["high"], d["n"])


def _flown_line(spec: CampaignSpec, summary: dict[str, Any]) -> str:
    """How far the campaign is: missions flown, those not flown yet (never started, or cut off by an infrastructure
    error: both are flown when the campaign resumes)."""
    planned = len(spec.missions())
    flown = summary["missions"] - summary["errors"]
    line = f"{flown} missions flown of {planned} planned ({spec.runs} per cell, master seed {spec.master_seed}). "
    if flown < planned:
        line += f"{planned - flown} not flown yet"
        if summary["errors"]:
            line += f" ({summary['errors']} of them cut off by an infrastructure error, not a landing)"
        line += ": the same command resumes the campaign. "
    return line


def _markdown(spec: CampaignSpec, summary: dict[str, Any], plots: list[str]) -> str:
    lines = [
        f"# Campaign `{spec.name}`",
        "",
        _flown_line(spec, summary)
        + (
            f"{summary['stale']} results are of an earlier definition (holds whose nearest person and path length "
            "ran to the end of the ground truth, or random points drawn around the vehicle instead of the search "
            "area's centre) and are flown again when the campaign resumes. "
            if summary["stale"]
            else ""
        )
        + "Intervals are 95 %: Wilson for rates, bootstrap for means. Definitions: docs/campaigns.md.",
        "",
        "## Ours",
        "",
        "| condition / strategy | n | success | warning 1 m | warning 1.5 m | zone area m² | nearest person m (mean) "
        "| nearest person m (min) | IoU | time to land s | aborts | on an obstacle |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name, cell in summary["cells"].items():
        lines.append(
            f"| {name} | {cell['missions']} | {_est(cell['success']).format(1, True)} "
            f"| {_est(cell['warning_1m']).format(1, True)} | {_est(cell['warning_1_5m']).format(1, True)} "
            f"| {_est(cell['zone_area_m2']).format(2)} | {_est(cell['nearest_person_mean_m']).format(2)} "
            f"| {_est(cell['nearest_person_min_m']).format(2)} | {_est(cell['zone_iou']).format(3)} "
            f"| {_est(cell['time_to_land_s']).format(1)} | {_est(cell['aborts']).format(2)} "
            f"| {_est(cell['touched_obstacle']).format(1, True)} |"
        )
    lines += [
        "",
        "*On an obstacle*: the vehicle's footprint overlapped a tree crown, car, bench, bin, bush or pole at touchdown "
        "(seen from above). The SITL has no collision, so such a landing can still count as a success, which is "
        "about people only.",
    ]
    lines += [
        "",
        "## The paper's Table I beside ours (success %, warnings %, area m², nearest person m, IoU)",
        "",
        "| condition / strategy | paper success | ours | paper warn 1 m | ours | paper warn 1.5 m | ours "
        "| paper area | ours | paper nearest | ours | paper IoU | ours |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name, cell in summary["cells"].items():
        condition, strategy = name.split("/")
        paper = PAPER_TABLE1.get((condition, strategy))
        if paper is None:
            continue

        def p(v: float | None) -> str:
            return "*" if v is None else f"{v:g}"

        lines.append(
            f"| {name} | {p(paper[0])} | {100 * cell['success']['value']:.1f} | {p(paper[1])} "
            f"| {100 * cell['warning_1m']['value']:.1f} | {p(paper[2])} | {100 * cell['warning_1_5m']['value']:.1f} "
            f"| {p(paper[3])} | {_fmt(cell['zone_area_m2']['value'])} | {p(paper[4])} "
            f"| {_fmt(cell['nearest_person_mean_m']['value'])} | {p(paper[5])} | {_fmt(cell['zone_iou']['value'], 3)} |"
        )
    lines += _holds_markdown(summary["cells"])
    lines += _endings_markdown(summary["cells"])
    lines += _paper_test_markdown(summary["paper"])
    lines += _previous_markdown(summary["previous"])
    lines += [
        "",
        "## Paired comparisons (same scenes and start poses)",
        "",
        "| condition | a vs b | pairs | only a succeeded | only b succeeded | McNemar p | nearest person a - b (m) "
        "| time to land a - b (s), both landed | same first zone | same touchdown |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for pair in summary["paired"]:
        diff = _est(pair["nearest_person_mean_difference_m"]).format(2)
        landing = pair.get("time_to_land_difference_s")  # absent in summaries written before it
        landing_text = "" if landing is None else _est(landing).format(1)
        same = [
            f"{pair[key]} of {pair[total]}" if total in pair else ""  # absent in summaries written before them
            for key, total in (("same_first_zone", "first_zone_pairs"), ("same_touchdown", "touchdown_pairs"))
        ]
        lines.append(
            f"| {pair['condition']} | {pair['a']} vs {pair['b']} | {pair['pairs']} | {pair['success_only_a']} "
            f"| {pair['success_only_b']} | {pair['mcnemar_p']:.3g} | {diff} | {landing_text} | {same[0]} | {same[1]} |"
        )
    lines.append("")
    lines.append(
        f"*Same first zone*: the centres of the first zones the two missions committed to lie within "
        f"{SAME_POINT_M:g} m (pairs where both chose one); *same touchdown*: the touchdowns lie within "
        f"{SAME_POINT_M:g} m (pairs where both touched down)."
    )
    lines += _flown_markdown(summary["flown"])
    lines += ["", "## Plots", ""] + [f"![{Path(p).stem}]({p})" for p in plots] + [""]
    return "\n".join(lines)


def _holds_markdown(cells: dict[str, Any]) -> list[str]:
    lines = [
        "",
        "## Missions without a touchdown, by cause",
        "",
        "| condition / strategy | missions | held | causes | landed with a person in the footprint "
        "| landed, a person under the vehicle above the gate |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for name, cell in cells.items():
        holds = cell.get("holds", {})
        causes = ", ".join(f"{kind}: {n}" for kind, n in holds.items()) or "none"
        lines.append(
            f"| {name} | {cell['missions']} | {sum(holds.values())} | {causes} | {cell.get('landed_unsafe', 0)} "
            f"| {cell.get('overflown_above_gate', 0)} |"
        )
    lines += [
        "",
        "Causes (metrics version 5 and later, from each flight log): "
        + "; ".join(f"*{kind}*: {text}" for kind, text in HOLD_CAUSES.items())
        + ". Results of earlier versions show their final reason.",
        "",
        "*Landed with a person in the footprint*: a body came within the vehicle's footprint under it during the "
        "landing descent (from the walker gate's release) or at touchdown: not a success. *A person under the vehicle "
        "above the gate*: a landing where a body passed under the vehicle earlier in its final descent, while it "
        "hovered at the walker gate (3 m above the heads) or higher, before the gate let it go (metrics version 6; "
        "earlier versions counted these as not a success).",
    ]
    return lines


def _endings_markdown(cells: dict[str, Any]) -> list[str]:
    """How the missions of each cell ended (metrics version 7): nothing when no result records it."""
    endings = [cell.get("endings", {}) for cell in cells.values()]
    if not any(set(e) - {BEFORE_ENDINGS} for e in endings):
        return []
    kinds = [k for k in (*ENDING_WORDS, BEFORE_ENDINGS) if any(k in e for e in endings)]
    lines = ["", "## How the missions ended", ""]
    lines.append("| condition / strategy | missions | " + " | ".join(ENDING_WORDS.get(k, k) for k in kinds) + " |")
    lines.append("| --- | --- |" + " --- |" * len(kinds))
    for (name, cell), counts in zip(cells.items(), endings, strict=True):
        lines.append(f"| {name} | {cell['missions']} | " + " | ".join(str(counts.get(k, 0)) for k in kinds) + " |")
    lines += [
        "",
        "A landing on *a fallback site* followed a `fallback_site` decision (the search's budget ended, or the ground "
        "station asked for the site); *hold*, *return* and *landing in place* are last resorts (metrics version 7, "
        "from each flight log's decision events).",
    ]
    return lines


def _previous_markdown(previous: dict[str, Any] | None) -> list[str]:
    if previous is None:
        return []
    lines = [
        "",
        f"## Against {previous['name']} (same scenes and start poses, mission by mission)",
        "",
        "| condition / strategy | pairs | success before | now | only before | only now | McNemar p | Holm p |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in previous["cells"]:
        lines.append(
            f"| {r['cell']} | {r['pairs']} | {r['before']} | {r['now']} | {r['only_before']} | {r['only_now']} "
            f"| {r['p']:.3g} | {r['p_holm']:.3g} |"
        )
    lines += [
        "",
        "Exact two-sided McNemar test on the discordant pairs of each cell, Holm-adjusted over the cells.",
    ]
    return lines


def _paper_test_markdown(rows: list[dict[str, Any]]) -> list[str]:
    if not rows:
        return []
    lines = [
        "",
        "## Success against the paper's, row by row (independent samples)",
        "",
        "| condition / strategy | ours | paper | ours - paper (points) | Fisher p | Holm p | at 5 % (Holm) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        d = _est(r["difference"])
        verdict = "no difference shown" if r["p_holm"] >= 0.05 else ("higher" if d.value > 0 else "lower")
        lines.append(
            f"| {r['cell']} | {r['ours_successes']}/{r['ours_missions']} | {r['paper_successes']}/"
            f"{r['paper_missions']} | {d.format(1, True).replace(' %', '')} | {r['p']:.3g} | {r['p_holm']:.3g} "
            f"| {verdict} |"
        )
    lines += [
        "",
        f"The paper ran {PAPER_RUNS_PER_ROW} missions per row, so its rates are counts too. *ours - paper*: Newcombe's "
        "95 % interval of the difference of two independent rates; Fisher's exact test, two-sided, Holm-adjusted over "
        "the rows. The paper's scenes are not ours (another simulator, park and vehicle), so this compares two "
        "experiments, not two strategies on the same scenes.",
    ]
    return lines


def _flown_markdown(flown: dict[str, Any]) -> list[str]:
    """How the campaign was flown: its segments, their commits and workers, the wall time and the rate."""
    rows = [Segment(**seg) for seg in flown["segments"]]
    rate = flown["missions_per_hour"]
    lines = [
        "",
        "## How it was flown",
        "",
        f"{sum(seg.missions for seg in rows)} missions in {flown['wall_s'] / 3600:.2f} h of wall time (the sum of "
        f"the segments below), {'n/a' if rate is None else f'{rate:.0f}'} missions per hour. Commits: "
        + (", ".join(f"`{c[:12]}`" for c in flown["commits"]) or "unknown")
        + ".",
        "",
        "| segment | started (UTC) | ended (UTC) | commit | workers | missions | flown again later | wall h "
        "| missions/h | flights/h | machine |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for seg in rows:
        name = "before segments were recorded" if seg.number is None else str(seg.number)
        wall = f"{seg.wall_s / 3600:.2f}" + (" (estimated: missions' wall_s / workers)" if seg.estimated else "")
        commits = ", ".join(f"`{c[:12]}`" for c in seg.commits) or "unknown"
        lines.append(
            f"| {name} | {seg.started_utc or 'n/a'} | {seg.ended_utc or 'n/a'} | {commits} | {seg.workers} "
            f"| {seg.missions} | {seg.superseded} | {wall} | {_fmt(seg.missions_per_hour, 0)} "
            f"| {_fmt(seg.flights_per_hour, 0)} | {seg.cpu or 'n/a'} |"
        )
    notes = [f"- Segment {seg.number}: {seg.note}" for seg in rows if seg.note]
    lines += [
        "",
        "*missions/h* counts the segment's results still in the table; *flights/h* also counts those a later flight "
        "replaced (a stale result flown again), so it says how fast the segment flew.",
    ]
    return lines + (["", *notes] if notes else [])


def _fmt(value: float | None, digits: int = 2) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def people_density(rows: list[FlownMission]) -> np.ndarray:
    """People per mission on the report's 1 m grid, shape (40, 40) (row: north from -20 m, col: east from -20 m): the
    mean of the ``people_cells`` maps of the results that carry one (a result restored from ``results.csv``, which
    does not hold them, is left out rather than counted as an empty park); zeros when none does."""
    mapped = [r.people_cells for r in rows if r.people_cells is not None]
    density = np.zeros((40, 40))
    for cells in mapped:
        for row, col, count in cells:
            density[row, col] += count
    return density / max(len(mapped), 1)


def _plots(spec: CampaignSpec, good: list[FlownMission], cells: dict[str, Any], out_dir: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(cells)
    files = []
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(names)), 4))
    values = [100 * cells[n]["success"]["value"] if cells[n]["missions"] else 0.0 for n in names]
    lows = [
        100 * (cells[n]["success"]["value"] - cells[n]["success"]["low"]) if cells[n]["missions"] else 0 for n in names
    ]
    highs = [
        100 * (cells[n]["success"]["high"] - cells[n]["success"]["value"]) if cells[n]["missions"] else 0 for n in names
    ]
    ax.bar(range(len(names)), values, yerr=[lows, highs], capsize=4, color="#4a90c2")
    for i, name in enumerate(names):
        paper = PAPER_TABLE1.get(tuple(name.split("/")))  # type: ignore[arg-type]
        if paper is not None:
            ax.plot(i, paper[0], "k_", markersize=18, mew=2)
    ax.set_xticks(range(len(names)), names, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("success % (95 % Wilson; black: paper)")
    ax.set_ylim(0, 105)
    fig.tight_layout()
    fig.savefig(out_dir / "success.png", dpi=110)
    plt.close(fig)
    files.append("success.png")

    fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(names)), 4))
    data = [
        [
            r.nearest_person_mean_m
            for r in good
            if f"{r.condition}/{r.strategy}" == n and math.isfinite(r.nearest_person_mean_m)
        ]
        or [math.nan]
        for n in names
    ]
    ax.boxplot(data, showmeans=True)
    ax.set_xticks(range(1, len(names) + 1), names, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("nearest person during the final descent, mean (m)")
    fig.tight_layout()
    fig.savefig(out_dir / "nearest_person.png", dpi=110)
    plt.close(fig)
    files.append("nearest_person.png")

    for condition in dict.fromkeys(c for c, _ in spec.cell_names()):
        rows = [r for r in good if r.condition == condition]
        fig, ax = plt.subplots(figsize=(5.5, 5))
        ax.imshow(people_density(rows), origin="lower", extent=(-20, 20, -20, 20), cmap="Greys")
        for k, strategy in enumerate(dict.fromkeys(s for c, s in spec.cell_names() if c == condition)):
            touched = [r for r in rows if r.strategy == strategy and math.isfinite(r.touchdown_north_m)]
            points = [(r.touchdown_east_m, r.touchdown_north_m) for r in touched]
            marks = ["o" if r.success else "x" for r in touched]
            for (x, y), mark in zip(points, marks, strict=True):
                ax.plot(x, y, mark, color=f"C{k}", markersize=4)
            ax.plot([], [], "o", color=f"C{k}", label=strategy)
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
        ax.set_title(f"{condition}: touchdowns (x: not a success) over people per mission")
        ax.legend(fontsize=7)
        fig.tight_layout()
        name = f"touchdowns_{condition}.png"
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        files.append(name)
    return files
