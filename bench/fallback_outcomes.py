"""How the missions of a campaign folder ended, by kind: a zone, a fallback site (which), hold, return (issue 53).

Run: ``.venv/bin/python -m bench.fallback_outcomes CAMPAIGN_FOLDER [--out FILE.md]`` on a folder flown with
``--keep-runs`` (every mission's flight log is read: :mod:`sitl.campaign.landing_kinds`). Prints a Markdown table per
condition and strategy: the count of each kind, the fallback sites landed at (by the name the spec gives them), how
many sites were given up before the one landed at, and the safety columns of the campaign's results for each kind:
a body within 1 m of the touchdown, the nearest body's distance at touchdown, a touchdown on an object of the park.
"""

from __future__ import annotations

import argparse
import math
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import yaml

from sitl.campaign.landing_kinds import LandingKind, LandingOutcome, landing_outcome_of_run
from sitl.campaign.runner import read_results


def site_names(folder: Path) -> dict[tuple[float, float], str]:
    """The fallback sites of the campaign's spec (its common mission overrides and its strategies'), by their north
    and east (m)."""
    spec = yaml.safe_load((folder / "spec.yaml").read_text())  # the spec as the campaign flew it
    missions = [spec.get("mission", {})] + [s.get("mission", {}) for s in spec.get("strategies", [])]
    sites = [site for m in missions for site in m.get("guidance", {}).get("fallback", {}).get("sites", [])]
    return {(float(s["north_m"]), float(s["east_m"])): str(s["name"]) for s in sites}


def tabulate(folder: Path) -> str:
    """The Markdown tables (see the module docstring)."""
    names = site_names(folder)
    cells: dict[tuple[str, str], list[tuple[dict[str, Any], LandingOutcome]]] = defaultdict(list)
    for result in read_results(folder / "results.jsonl"):
        flight = folder / "missions" / result["mission_id"] / "flight"
        if "error" in result or not (flight / "flight.jsonl").is_file():
            continue
        cells[(result["condition"], result["strategy"])].append((result, landing_outcome_of_run(flight)))
    lines = []
    for (condition, strategy), missions in sorted(cells.items()):
        kinds = Counter(outcome.kind for _, outcome in missions)
        lines += [f"### {condition} / {strategy}: {len(missions)} missions", ""]
        lines += [
            "| ended | missions | body within 1 m at touchdown | nearest body at touchdown, min (m) | on an object |"
        ]
        lines += ["| --- | --- | --- | --- | --- |"]
        for kind in LandingKind:
            these = [r for r, o in missions if o.kind is kind]
            if not these:
                continue
            landed = [r for r in these if r.get("touchdown_nearest_m") is not None]
            within = sum(1 for r in landed if (r.get("people_within_1m") or 0) > 0)
            nearest = min((float(r["touchdown_nearest_m"]) for r in landed), default=math.nan)
            objects = sum(1 for r in these if r.get("touched_obstacle"))
            near = "n/a" if math.isnan(nearest) else f"{nearest:.2f}"
            lines.append(f"| {kind.value} | {kinds[kind]} | {within} | {near} | {objects} |")
        at_sites = Counter(names.get(o.site_ne_m, str(o.site_ne_m)) for _, o in missions if o.site_ne_m is not None)
        given_up = Counter(o.sites_flown_to - 1 for _, o in missions if o.kind is LandingKind.FALLBACK_SITE)
        lines += [
            "",
            "Fallback landings by site: " + (", ".join(f"{n} {c}" for n, c in sorted(at_sites.items())) or "none"),
        ]
        lines += [
            "Sites given up before the one landed at: "
            + (", ".join(f"{k}: {c}" for k, c in sorted(given_up.items())) or "none"),
            "",
        ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a campaign folder flown with --keep-runs")
    parser.add_argument("--out", type=Path, help="also write the tables here")
    args = parser.parse_args()
    text = tabulate(args.folder)
    print(text)
    if args.out is not None:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
