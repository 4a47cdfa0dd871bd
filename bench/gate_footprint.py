"""What a per-ray footprint check at the walker gate would have seen, on replayed flights: a candidate, not flown.

At the gate (4.8 m) the descent waits until its map sees the 1 m footprint around the landing point free. The map
puts every pixel of a person on the head plane 1.7 m above the ground, so a standing person's lower body lands nearer
the camera's nadir than the person stands (``bench/map_berth.py``: most of the berth at the gate), and the holds of
the ROI table are descents that waited there for people 2.3-2.7 m away. A per-ray check reads each occupied run on the
ray from the nadir as one body whose lowest point is the run's inner end: a run from ``r_in`` to ``r_out`` keeps only
``[min(r_in h / (h - h_t), r_out), r_out]`` (``h`` the camera's height, ``h_t`` the head plane's), and a run that
touches an unknown cell, or reaches the nadir, is kept whole. ``bench/map_berth.py``'s ``reach`` measures whether the
map's runs reach the feet, which the check needs (at the gate, every body in view by 0.59 m or more).

For every map of a replayed flight taken while the descent was at the gate (the frame's altitude within the gate's
band, a landing point locked by the descent's decision on it), this recomputes the map as the companion did and says
whether the footprint is seen occupied as flown and with the per-ray check, beside the truth (a body's edge inside
the footprint). Reported per flight and in total: maps at the gate, maps seen occupied each way, maps with a body
truly inside and how many of those each way saw (a check that sees such a map free would let a descent go on over a
person), and why the check kept each map it kept.

Run: ``.venv/bin/python -m bench.gate_footprint FOLDER... [--out bench/results/gate_footprint.json]`` on folders as
``bench/hold_replays.py`` or ``slz campaign replay`` write them (``flight/`` with png frames, ``truth.jsonl``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from bench.machine import machine_context, save_report
from bench.map_berth import ray_samples
from companion.flightlog.flight_log import FlightLog, RecordKind
from companion.geometry import Pose
from companion.guidance.descent import GATE_SLACK_M
from companion.guidance.footprint import footprint_view
from companion.perception.density import input_scale, predict_downscaled
from companion.perception.pipeline import SlzPipeline
from companion.perception.projection import HeadPlaneOccupancy
from companion.tools.replay import config_from_header
from sitl.campaign.hold_explain import TruthAt
from sitl.vehicle.truth import body_edges_m, read_truth

REPO_ROOT = Path(__file__).resolve().parent.parent


class Kept:
    """Why the per-ray check keeps an occupied cell of the footprint (the first such cell decides)."""

    NADIR = "at the nadir"
    REACHES_NADIR = "its run reaches the nadir"
    INNER_UNKNOWN = "its run's inner end is not seen"
    OUTER_UNKNOWN = "its run reaches the edge of the view"
    HEAD = "the head part of its run"
    SAMPLE = "the ray's sample is not occupied"


def per_ray_kept(
    head_plane: HeadPlaneOccupancy,
    nadir_ne_m: tuple[float, float],
    camera_height_m: float,
    head_height_m: float,
    north_m: float,
    east_m: float,
    radius_m: float,
) -> str | None:
    """Whether the per-ray check sees a person inside the disc of ``radius_m`` around a point: why it keeps the first
    occupied cell it keeps (a :class:`Kept` value), or None when it trims every occupied cell (or there is none). A
    cell is trimmed when it is the lower part of a run that reaches further out (see the module docstring).

    Parameters
    ----------
    head_plane : HeadPlaneOccupancy
        One map.
    nadir_ne_m : tuple of float
        The camera's position (north, east; NED, m): the rays start there.
    camera_height_m, head_height_m : float
        Above the ground (m).
    north_m, east_m, radius_m : float
        The footprint (m).
    """
    grid = head_plane.grid
    occupied = head_plane.known & ~head_plane.free
    if not footprint_view(head_plane, north_m, east_m, radius_m).occupied_seen:
        return None
    if camera_height_m <= head_height_m:
        return Kept.NADIR
    scale = camera_height_m / (camera_height_m - head_height_m)
    nn, ee = np.meshgrid(grid.north_centres_m, grid.east_centres_m, indexing="ij")
    inside = occupied & (np.hypot(nn - north_m, ee - east_m) <= radius_m)
    step = grid.resolution_m / 2.0
    radii = np.arange(0.0, grid.resolution_m * max(grid.rows, grid.cols), step)
    for row, col in zip(*np.nonzero(inside), strict=True):
        offset = np.array([nn[row, col] - nadir_ne_m[0], ee[row, col] - nadir_ne_m[1]])
        r_cell = float(np.hypot(*offset))
        if r_cell <= grid.resolution_m:
            return Kept.NADIR  # no ray to read
        known, hit = ray_samples(head_plane, occupied, np.asarray(nadir_ne_m), offset / r_cell, radii)
        at = int(np.argmin(np.abs(radii - r_cell)))
        if not hit[at]:
            return Kept.SAMPLE  # the cell and its ray's sample disagree: keep it
        inner = at
        while inner > 0 and hit[inner - 1]:
            inner -= 1
        outer = at
        while outer + 1 < len(hit) and hit[outer + 1]:
            outer += 1
        if inner == 0:
            return Kept.REACHES_NADIR
        if not known[inner - 1]:
            return Kept.INNER_UNKNOWN
        if outer + 1 >= len(hit) or not known[outer + 1]:
            return Kept.OUTER_UNKNOWN  # the head may lie beyond the view, where the network's reach is least sure
        if r_cell >= min(float(radii[inner]) * scale, float(radii[outer])) - step:
            return Kept.HEAD
    return None


def gate_maps(folder: Path) -> dict[str, Any]:
    """The gate's maps of one replayed flight: counts as flown, with the per-ray check, and against the truth."""
    flight = FlightLog.read(folder / "flight")
    header = flight.header
    if header is None:
        raise SystemExit(f"{folder}: no flight log header")
    config = config_from_header(header.config)
    guidance = config.guidance
    gate_m = guidance.perception_min_altitude_m + guidance.land_tolerance_m
    radius_m = config.perception.zones.min_radius_m
    head_height_m = config.perception.projection.head_height_m
    pipeline = SlzPipeline.from_config(config.perception, fence_ne_m=config.geofence.polygon_ne_m)
    truth_header, records = read_truth(folder / "truth.jsonl")
    truth = TruthAt(truth_header, records)
    targets: dict[int, tuple[float, float]] = {}
    for decision in flight.of(RecordKind.DECISION):
        target = decision["decision"].get("target")
        seq = (decision.get("stimulus") or {}).get("seq")
        if target is not None and seq is not None and decision["decision"].get("phase") == "descent":
            targets[int(seq)] = (float(target["north_m"]), float(target["east_m"]))
    paths = flight.frame_paths()
    counts = {"maps": 0, "occupied_as_flown": 0, "occupied_per_ray": 0, "body_inside": 0,
              "body_inside_seen_as_flown": 0, "body_inside_seen_per_ray": 0}  # fmt: skip
    reasons: dict[str, int] = {}
    for record in flight.of(RecordKind.FRAME_RESULT):
        seq = int(record["seq"])
        pose = Pose(np.asarray(record["T_world_body"], np.float64))
        altitude_m = -float(pose.position_ned_m[2])
        if seq not in targets or not (guidance.perception_min_altitude_m <= altitude_m <= gate_m + GATE_SLACK_M):
            continue
        raw = cv2.imread(str(paths[seq]), cv2.IMREAD_COLOR)
        if raw is None:
            raise SystemExit(f"{folder}: frame {seq} not saved (replay with png frames)")
        image: npt.NDArray[np.uint8] = np.asarray(raw, dtype=np.uint8)
        gsd = pipeline.projector.finest_gsd_m_per_px(pose)
        density = predict_downscaled(pipeline.density_model, image, input_scale(gsd, pipeline.min_gsd_m_per_px))
        density_camera = pipeline.projector.camera.scaled(1.0 / density.stride_x, 1.0 / density.stride_y)
        occupancy = pipeline.occupancy.compute(density, gsd)
        head_plane = pipeline.projector.project(occupancy.values, density_camera, pose)
        camera = pipeline.projector.T_world_camera(pose)[:3, 3]
        north_m, east_m = targets[seq]
        as_flown = footprint_view(head_plane, north_m, east_m, radius_m).occupied_seen
        kept = per_ray_kept(
            head_plane, (float(camera[0]), float(camera[1])), -float(camera[2]), head_height_m, north_m, east_m,
            radius_m,
        )  # fmt: skip
        per_ray = kept is not None
        if kept is not None:
            reasons[kept] = reasons.get(kept, 0) + 1
        edges = body_edges_m(truth_header, truth.at(float(record["t_s"])), north_m, east_m)
        inside = bool(float(np.min(edges)) < radius_m)
        counts["maps"] += 1
        counts["occupied_as_flown"] += as_flown
        counts["occupied_per_ray"] += per_ray
        counts["body_inside"] += inside
        counts["body_inside_seen_as_flown"] += inside and as_flown
        counts["body_inside_seen_per_ray"] += inside and per_ray
    return {**counts, "kept_because": reasons}


def main() -> int:
    parser = argparse.ArgumentParser(description="The gate's footprint check as flown and per ray, on replays.")
    parser.add_argument("folders", type=Path, nargs="+", help="replayed mission folders (png frames, truth)")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench/results/gate_footprint.json")
    args = parser.parse_args()
    flights = {}
    sys.stdout.write(
        "| flight | gate maps | footprint seen occupied, as flown | per ray | body inside (truth) | "
        "of those seen, as flown / per ray |\n| --- | --- | --- | --- | --- | --- |\n"
    )
    for folder in args.folders:
        c = gate_maps(folder)
        flights[str(folder)] = c
        sys.stdout.write(
            f"| {folder} | {c['maps']} | {c['occupied_as_flown']} | {c['occupied_per_ray']} | {c['body_inside']} | "
            f"{c['body_inside_seen_as_flown']} / {c['body_inside_seen_per_ray']} |\n"
        )
    keys = [key for key in next(iter(flights.values())) if key != "kept_because"]
    total: dict[str, Any] = {key: sum(c[key] for c in flights.values()) for key in keys}
    kept_because: dict[str, int] = {}
    for c in flights.values():
        for why, n in c["kept_because"].items():
            kept_because[why] = kept_because.get(why, 0) + n
    total["kept_because"] = kept_because
    share = {key: round(total[key] / max(1, total["maps"]), 3) for key in ("occupied_as_flown", "occupied_per_ray")}
    sys.stdout.write(f"total: {total}; share of gate maps seen occupied: {share}\n")
    save_report({"machine": machine_context(), "flights": flights, "total": total, "share": share}, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
