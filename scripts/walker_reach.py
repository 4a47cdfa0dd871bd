"""What a hard bound on walkers would cost: how long a descent would wait for no walker to be within reach.

The walker gate (``companion/guidance/walker_watch.py``) predicts each walker at constant velocity over the blind last
metres of the descent; a walker who turns towards the point after the gate defeats it (docs/results/walker_gate.md).
The safe alternative is a bound: wait until no walker is close enough to reach the footprint by touchdown, whatever
way it turns, i.e. within ``footprint_radius_m + max_speed_mps * blind_s`` of the point. This script measures, on the
SITL's own crowds and without perception (every walker's true position), how long that wait would be at the points
where a campaign's missions touched down, starting at moments spread over the mission.

Usage (from the repository root, with the dev venv's python)::

    python scripts/walker_reach.py docs/results/walker_gate_moving20/results.jsonl --moving-fraction 0.2

It prints, per blind time, the reach, the share of moments a walker is within it, the mean wait, and the share of
waits longer than the gate's limit (20 s, after which the point is refused).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import numpy.typing as npt

from sitl.world.crowd import Crowd
from sitl.world.scenario import ScenarioConfig

STEP_S = 0.5
"""Time step of the crowd's sampled positions."""


def walker_near(
    crowd: Crowd, point_ne_m: npt.NDArray[np.float64], reach_m: float, times_s: npt.NDArray[np.float64]
) -> npt.NDArray[np.bool_]:
    """Per time, whether a walker's body edge is within ``reach_m`` of ``point_ne_m`` (north, east; m), shape (T,)."""
    near = np.zeros(len(times_s), dtype=bool)
    for k, t_s in enumerate(times_s):
        crowd.advance_to(float(t_s))
        walkers = crowd.moving
        if not walkers.any():
            continue
        gap_m = np.hypot(*(crowd.positions_ne_m[walkers] - point_ne_m).T) - crowd.radii_m[walkers]
        near[k] = bool(gap_m.min() < reach_m)
    return near


def waits_s(near: npt.NDArray[np.bool_], starts: range) -> list[float]:
    """For each start index, the time until ``near`` is first false (the end of the record if never), s."""
    out = []
    for i0 in starts:
        j = i0
        while j < len(near) and near[j]:
            j += 1
        out.append((j - i0) * STEP_S)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", type=Path, help="a campaign's results.jsonl (touchdown points and seeds)")
    parser.add_argument("--moving-fraction", type=float, required=True, help="the campaign condition's walkers")
    parser.add_argument("--footprint-radius-m", type=float, default=1.0, help="vehicle radius plus margin")
    parser.add_argument("--max-speed-mps", type=float, default=1.6, help="the fastest walker (SITL: 0.8-1.6 m/s)")
    parser.add_argument("--limit-s", type=float, default=20.0, help="the gate's longest wait")
    parser.add_argument("--blind-s", type=float, nargs="+", default=[5.5, 3.0, 1.5], help="blind descent times")
    args = parser.parse_args()

    rows = [json.loads(line) for line in args.results.read_text().splitlines() if line.strip()]
    landed = [row for row in rows if row.get("landed") and row.get("strategy") != "random"]
    config = ScenarioConfig(moving_fraction=args.moving_fraction)
    times_s = np.arange(0.0, 200.0, STEP_S)
    starts = range(int(40.0 / STEP_S), int(150.0 / STEP_S), int(5.0 / STEP_S))  # a start every 5 s, 40-150 s
    print(f"{len(landed)} touchdown points of {args.results}, {len(starts)} start moments each (true positions)")
    print("| blind time | reach | moments with a walker within reach | mean wait | waits over the limit |")
    print("| --- | --- | --- | --- | --- |")
    for blind_s in args.blind_s:
        reach_m = args.footprint_radius_m + args.max_speed_mps * blind_s
        waits: list[float] = []
        for row in landed:
            crowd = Crowd(config, int(row["seed"]))
            point = np.array([row["touchdown_north_m"], row["touchdown_east_m"]])
            waits += waits_s(walker_near(crowd, point, reach_m, times_s), starts)
        w = np.asarray(waits)
        print(
            f"| {blind_s:.1f} s | {reach_m:.1f} m | {np.mean(w > 0):.0%} | {w.mean():.1f} s | "
            f"{np.mean(w > args.limit_s):.0%} |"
        )


if __name__ == "__main__":
    main()
