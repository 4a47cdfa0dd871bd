"""How wide a berth the occupancy map keeps around people, measured against the truth on replayed flights.

The holds of the ROI table are the map's caution (``bench/hold_replays.py``): the points it refused for a person had
the nearest body 2-3 m away, while a disc of 3 m or more was truly free. This measures that caution directly. For
frames of replayed missions (folders with ``flight/`` recorded with png frames and ``truth.jsonl``, as ``slz campaign
replay`` writes them), the density model runs once per frame and the occupancy and head-plane projection run for
each variant of the occupancy config (threshold, dilation); then, on every known head-plane cell inside the landing
area whose true clearance (to the nearest body's edge) is between 0.5 and 6 m:

- **berth** = true clearance - the map's clearance (distance to the nearest cell it calls occupied), metres: how much
  further from people the map keeps a landing point than the bodies ask. Reported by the vehicle's altitude band.
- **the head plane's own share** (``geometry`` in the output): the same berth for a perfect body detector, each body
  a column of its radius from the ground to the head plane, projected from the camera onto the head plane as the map
  is. A standing person's lower body meets the head plane nearer the nadir than the person stands (by ``d * h_t / h``
  at ``d`` from the nadir, ``h`` the camera's height): no threshold or dilation takes that part away.
- **bodies seen**: of the bodies whose head cell lies well inside the known map, the share with an occupied cell
  within 0.3 m of it (the recall of the map on the head plane).
- **the blob's reach** (``reach`` in the output; the shipped variant): how far each body's occupied run reaches from
  its head towards the camera's nadir, and what a per-ray rule that reads the run's inner end as the body's lowest
  point (a height ``z``: 0 the feet) would make of it. Such a rule places the body at ``r_in (h - z) / (h - h_t)``
  from the nadir instead of ``r_in``; its **margin** is the body's true inner edge minus that estimate (negative: the
  rule would free ground the body stands on). The network is trained on head points, not bodies: whether its blobs
  reach the feet is this measurement's question.
- **ground called occupied**: of the known cells in the landing area more than 2 m from every body's edge, the share
  the map calls occupied (false positives away from people), by the scene's sun elevation: below 30 degrees a
  person's shadow is more than 2.9 m long.

Run: ``.venv/bin/python -m bench.map_berth runs/hold_replays/paper_table1_roi/*/*/* [--every 25]`` (one model run
per sampled frame, about 30 ms, then the variants). Prints the table with the machine's context and writes JSON.
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
from companion.config import load_yaml_config
from companion.flightlog.flight_log import FlightLog, RecordKind
from companion.geometry import Pose, inside_polygon
from companion.perception.density import input_scale, predict_downscaled
from companion.perception.occupancy import OccupancyMapper
from companion.perception.pipeline import SlzPipeline
from companion.perception.projection import HeadPlaneOccupancy
from companion.tools.replay import config_from_header
from sitl.campaign.hold_explain import TruthAt
from sitl.config import SitlConfig
from sitl.vehicle.sim_camera import scene_light
from sitl.vehicle.truth import clearance_m, people_at, read_truth

REPO_ROOT = Path(__file__).resolve().parent.parent


VARIANTS: dict[str, tuple[float, float]] = {
    "shipped (threshold 0.01, dilation 0.5 m)": (0.01, 0.5),
    "dilation 0.25 m": (0.01, 0.25),
    "dilation 0": (0.01, 0.0),
    "threshold 0.03": (0.03, 0.5),
    "threshold 0.03, dilation 0.25 m": (0.03, 0.25),
}
"""Name: (density_threshold people per cell, dilation_m)."""
FIRST_VARIANT = next(iter(VARIANTS))
BANDS = ((20.0, "above 20 m"), (8.0, "8-20 m"), (6.0, "6-8 m"), (0.0, "below 6 m"))
SEEN_WITHIN_CELLS = 3  # 0.3 m on the 0.1 m head-plane grid
CLEARANCE_RANGE_M = (0.5, 6.0)
AWAY_FROM_PEOPLE_M = 2.0
LOW_SUN_DEG = 30.0


def band_of(altitude_m: float) -> str:
    """The altitude band a frame's numbers go into."""
    return next(name for floor, name in BANDS if altitude_m > floor)


def bodies_seen(
    head_plane: HeadPlaneOccupancy, occupied: npt.NDArray[np.bool_], positions_ne_m: npt.NDArray[np.float64]
) -> tuple[int, int]:
    """Of the bodies whose head cell lies well inside the known map (a window of ``SEEN_WITHIN_CELLS`` around it all
    known), how many have an occupied cell in that window: (seen, counted)."""
    grid, k = head_plane.grid, SEEN_WITHIN_CELLS
    seen = counted = 0
    for n, e in positions_ne_m:
        row, col = (round(v) for v in grid.world_to_cell(float(n), float(e)))
        if k <= row < grid.rows - k and k <= col < grid.cols - k:
            window = (slice(row - k, row + k + 1), slice(col - k, col + k + 1))
            if head_plane.known[window].all():
                counted += 1
                seen += bool(occupied[window].any())
    return seen, counted


COLUMN_SAMPLES = 9
"""Points along a body's column (ground to head plane) projected onto the head plane for the geometric berth."""
GEOMETRY = "geometry"
"""The key of the perfect detector's berth in the output (not a variant of the occupancy config)."""


def head_plane_clearance_m(
    positions_ne_m: npt.NDArray[np.float64],
    radii_m: npt.NDArray[np.float64],
    camera_ned_m: npt.NDArray[np.float64],
    head_height_m: float,
    north_m: npt.NDArray[np.float64],
    east_m: npt.NDArray[np.float64],
) -> npt.NDArray[np.float64]:
    """Distance (m) from head-plane points to the nearest body as a perfect detector would map it: each body a column
    of its radius from the ground up to the head plane, every height projected from the camera onto the head plane
    (a point ``z`` m above the ground at ``p`` lands at ``c + (p - c) (h - h_t) / (h - z)``, ``c`` the camera's
    nadir, ``h`` its height; radii scale alike). Shapes as :func:`sitl.vehicle.truth.clearance_m`."""
    height_m = -float(camera_ned_m[2])
    nadir = np.asarray(camera_ned_m[:2], np.float64)
    if height_m <= head_height_m:
        return clearance_m(positions_ne_m, radii_m, north_m, east_m)
    clear = np.full(np.broadcast_shapes(north_m.shape, east_m.shape), np.inf)
    for z_m in np.linspace(0.0, head_height_m, COLUMN_SAMPLES):
        scale = (height_m - head_height_m) / (height_m - z_m)
        projected = nadir + (positions_ne_m - nadir) * scale
        np.minimum(clear, clearance_m(projected, radii_m * scale, north_m, east_m), out=clear)
    return clear


REACH_ASSUMED_LOWEST_M = (0.0, 0.5, 1.0)
"""Heights (m) a per-ray rule could assume a body's occupied run reaches down to (0: the feet)."""
REACH = "reach"
"""The key of the blob-reach measurement in the output."""


def ray_samples(
    head_plane: HeadPlaneOccupancy,
    occupied: npt.NDArray[np.bool_],
    nadir_ne_m: npt.NDArray[np.float64],
    direction_ne: npt.NDArray[np.float64],
    radii_m: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """A map sampled along the ray from the nadir in ``direction_ne`` (a unit vector, north and east) at ``radii_m``
    (N,): whether each sample's cell is known (inside the grid and seen), and whether it is occupied, each (N,)."""
    grid = head_plane.grid
    points = nadir_ne_m + np.outer(radii_m, direction_ne)
    rows = np.rint((points[:, 0] - grid.north_min_m) / grid.resolution_m - 0.5).astype(np.intp)
    cols = np.rint((points[:, 1] - grid.east_min_m) / grid.resolution_m - 0.5).astype(np.intp)
    inside = (rows >= 0) & (rows < grid.rows) & (cols >= 0) & (cols < grid.cols)
    rows, cols = np.clip(rows, 0, grid.rows - 1), np.clip(cols, 0, grid.cols - 1)
    known = inside & head_plane.known[rows, cols]
    return known, known & occupied[rows, cols]


def run_inner_end_m(
    head_plane: HeadPlaneOccupancy,
    occupied: npt.NDArray[np.bool_],
    nadir_ne_m: npt.NDArray[np.float64],
    body_ne_m: npt.NDArray[np.float64],
    search_from_m: float,
) -> float | None:
    """Distance (m) from the nadir of the inner end of a body's occupied run on the head plane, along the ray from the
    nadir through the body: the first occupied sample walking inward from the body (at ``d`` from the nadir) to
    ``search_from_m``, then on inward while occupied. None where the body's part of the ray is not occupied (not seen)
    or the walk leaves the known map before the run ends (nothing to measure)."""
    grid = head_plane.grid
    offset = body_ne_m - nadir_ne_m
    d = float(np.hypot(*offset))
    if d <= grid.resolution_m:
        return None
    step = grid.resolution_m / 2.0
    radii = np.arange(d, -step / 2.0, -step)  # from the body inward to the nadir
    known, hit = ray_samples(head_plane, occupied, nadir_ne_m, offset / d, radii)
    candidates = np.nonzero(hit & (radii >= search_from_m - 1e-9))[0]
    if not len(candidates):
        return None
    first = int(candidates[0])
    ends = np.nonzero(~hit[first:])[0]
    if not len(ends):
        return 0.0  # occupied all the way to the nadir
    last = first + int(ends[0]) - 1
    if not known[last + 1]:
        return None  # the run runs off the known map
    return float(radii[last])


def reach_margins_m(
    inner_end_m: float, body_distance_m: float, body_radius_m: float, camera_height_m: float, head_height_m: float
) -> dict[float, float]:
    """For each assumed lowest height of a run (:data:`REACH_ASSUMED_LOWEST_M`), the body's true inner edge minus
    where a per-ray rule would put it (``inner_end_m (h - z) / (h - h_t)`` from the nadir): negative where the rule
    would free ground the body stands on."""
    return {
        z_m: body_distance_m - body_radius_m - inner_end_m * (camera_height_m - z_m) / (camera_height_m - head_height_m)
        for z_m in REACH_ASSUMED_LOWEST_M
    }


def measure(folders: list[Path], every: int) -> dict[str, Any]:
    """Berths (a sample of cells) and bodies seen, per variant and altitude band."""
    out: dict[str, Any] = {v: {"berth_m": {}, "seen": 0, "bodies": 0, "ground": {}} for v in VARIANTS}
    geometry: dict[str, list[float]] = {}
    reach: dict[str, dict[str, Any]] = {}
    frames = 0
    suns = {}
    for folder in folders:
        sun_deg = scene_light(load_yaml_config(SitlConfig, folder / "sitl.yaml", section="sitl")).elevation_deg
        suns[str(folder)] = round(sun_deg, 1)
        sun_band = f"sun below {LOW_SUN_DEG:g} deg" if sun_deg < LOW_SUN_DEG else f"sun {LOW_SUN_DEG:g} deg or higher"
        flight = FlightLog.read(folder / "flight")
        header = flight.header
        if header is None:
            raise SystemExit(f"{folder}: no flight log header")
        config = config_from_header(header.config)
        pipeline = SlzPipeline.from_config(config.perception, fence_ne_m=config.geofence.polygon_ne_m)
        area = np.asarray(config.perception.zones.landing_area_ne_m or config.geofence.polygon_ne_m, np.float64)
        truth_header, records = read_truth(folder / "truth.jsonl")
        truth = TruthAt(truth_header, records)
        paths = flight.frame_paths()
        for record in flight.of(RecordKind.FRAME_RESULT)[::every]:
            raw = cv2.imread(str(paths[int(record["seq"])]), cv2.IMREAD_COLOR)
            if raw is None:
                raise SystemExit(f"{folder}: frame {record['seq']} not saved (replay with png frames)")
            image = np.asarray(raw, dtype=np.uint8)
            frames += 1
            pose = Pose(np.asarray(record["T_world_body"], np.float64))
            band = band_of(-float(pose.position_ned_m[2]))
            gsd = pipeline.projector.finest_gsd_m_per_px(pose)
            density = predict_downscaled(pipeline.density_model, image, input_scale(gsd, pipeline.min_gsd_m_per_px))
            density_camera = pipeline.projector.camera.scaled(1.0 / density.stride_x, 1.0 / density.stride_y)
            positions, radii = people_at(truth_header, truth.at(float(record["t_s"])))
            camera_ned_m = pipeline.projector.T_world_camera(pose)[:3, 3]
            head_height_m = config.perception.projection.head_height_m
            # The grid is the pose's, the same for every variant: its cells' true clearance once per frame.
            grid = pipeline.projector.grid_for(pose)
            north, east = np.meshgrid(grid.north_centres_m, grid.east_centres_m, indexing="ij")
            true_clearance = clearance_m(positions, radii, north, east)
            in_area = inside_polygon(area, north, east)
            for name, (threshold, dilation_m) in VARIANTS.items():
                occupancy_config = config.perception.occupancy.model_copy(
                    update={"density_threshold": threshold, "dilation_m": dilation_m}
                )
                occupancy = OccupancyMapper(occupancy_config).compute(density, gsd)
                head_plane = pipeline.projector.project(occupancy.values, density_camera, pose)
                occupied = head_plane.known & ~head_plane.free
                not_occupied = (~occupied).astype(np.uint8)
                map_clearance = cv2.distanceTransform(not_occupied, cv2.DIST_L2, 5) * grid.resolution_m
                known_in_area = head_plane.known & in_area
                low, high = CLEARANCE_RANGE_M
                cells = known_in_area & (true_clearance > low) & (true_clearance < high)
                berth = (true_clearance[cells] - map_clearance[cells])[::7]  # a sample: neighbours agree
                out[name]["berth_m"].setdefault(band, []).extend(berth.tolist())
                if name == FIRST_VARIANT:  # the same grid and cells for every variant: once per frame
                    perfect = head_plane_clearance_m(
                        positions, radii, camera_ned_m, head_height_m, north[cells], east[cells]
                    )
                    perfect = np.maximum(perfect, 0.0)  # as the map: 0 inside what it calls occupied
                    geometry.setdefault(band, []).extend((true_clearance[cells] - perfect)[::7].tolist())
                    measure_reach(
                        reach.setdefault(band, {"not_measured": 0, "margins_m": {}}),
                        head_plane, occupied, camera_ned_m, positions, radii, head_height_m,
                    )  # fmt: skip
                away = known_in_area & (true_clearance > AWAY_FROM_PEOPLE_M)
                ground = out[name]["ground"].setdefault(sun_band, [0, 0])
                ground[0] += int((away & occupied).sum())
                ground[1] += int(away.sum())
                seen, counted = bodies_seen(head_plane, occupied, positions)
                out[name]["seen"] += seen
                out[name]["bodies"] += counted
        sys.stdout.write(f"{folder}: sun {sun_deg:.1f} deg, done\n")
    return {"frames": frames, "variants": out, GEOMETRY: geometry, REACH: reach, "sun_elevation_deg": suns}


def measure_reach(
    into: dict[str, Any],
    head_plane: HeadPlaneOccupancy,
    occupied: npt.NDArray[np.bool_],
    camera_ned_m: npt.NDArray[np.float64],
    positions_ne_m: npt.NDArray[np.float64],
    radii_m: npt.NDArray[np.float64],
    head_height_m: float,
) -> None:
    """Adds one map's bodies in view to ``into`` (those whose head and feet points on the head plane both lie in known
    cells): ``not_measured``, those of them whose ray holds no occupied cell between the two points or whose run leaves
    the known map; ``margins_m``, per assumed height, the others' margins (:func:`reach_margins_m`)."""
    height_m = -float(camera_ned_m[2])
    if height_m <= head_height_m:
        return
    nadir = np.asarray(camera_ned_m[:2], np.float64)
    feet_share = (height_m - head_height_m) / height_m
    grid = head_plane.grid
    for body, radius in zip(positions_ne_m, radii_m, strict=True):
        feet = nadir + (body - nadir) * feet_share
        cells = [tuple(round(v) for v in grid.world_to_cell(float(n), float(e))) for n, e in (body, feet)]
        if not all(0 <= r < grid.rows and 0 <= c < grid.cols and head_plane.known[r, c] for r, c in cells):
            continue  # not in view
        d = float(np.hypot(*(body - nadir)))
        inner = run_inner_end_m(head_plane, occupied, nadir, body, d * feet_share - float(radius))
        if inner is None:
            into["not_measured"] += 1
            continue
        for z_m, margin in reach_margins_m(inner, d, float(radius), height_m, head_height_m).items():
            into["margins_m"].setdefault(str(z_m), []).append(round(margin, 3))


def main() -> int:
    parser = argparse.ArgumentParser(description="The occupancy map's berth around people, against the truth.")
    parser.add_argument("folders", type=Path, nargs="+", help="replayed mission folders (png frames, truth)")
    parser.add_argument("--every", type=int, default=25, help="use every N-th processed frame")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench/results/map_berth.json")
    args = parser.parse_args()
    measured = measure(args.folders, max(1, args.every))
    rows = []
    sys.stdout.write(f"{measured['frames']} frames of {len(args.folders)} missions\n")
    sys.stdout.write(
        "| variant | berth m, median [p10, p90] | by altitude band (median) | bodies seen | ground called occupied |\n"
    )
    sys.stdout.write("| --- | --- | --- | --- | --- |\n")
    for name, found in measured["variants"].items():
        every_band = np.concatenate([np.asarray(v) for v in found["berth_m"].values()])
        by_band = {band: round(float(np.median(v)), 2) for band, v in found["berth_m"].items()}
        q10, q50, q90 = (float(q) for q in np.quantile(every_band, (0.1, 0.5, 0.9)))
        seen = found["seen"] / max(1, found["bodies"])
        ground = {sun: occupied / max(1, total) for sun, (occupied, total) in sorted(found["ground"].items())}
        rows.append(
            {
                "variant": name,
                "berth_m_p10_p50_p90": [round(q, 3) for q in (q10, q50, q90)],
                "berth_m_median_by_band": by_band,
                "cells_sampled": len(every_band),
                "bodies_seen": found["seen"],
                "bodies": found["bodies"],
                "ground_called_occupied": ground,
            }
        )
        bands = ", ".join(f"{band} {value:.2f}" for band, value in by_band.items())
        grounds = ", ".join(f"{sun} {100 * share:.1f} %" for sun, share in ground.items())
        sys.stdout.write(
            f"| {name} | {q50:.2f} [{q10:.2f}, {q90:.2f}] | {bands} | {found['seen']} / {found['bodies']} "
            f"({100 * seen:.2f} %) | {grounds} |\n"
        )
    every_geometry = np.concatenate([np.asarray(v) for v in measured[GEOMETRY].values()])
    geometry_by_band = {band: round(float(np.median(v)), 2) for band, v in measured[GEOMETRY].items()}
    g10, g50, g90 = (float(q) for q in np.quantile(every_geometry, (0.1, 0.5, 0.9)))
    bands = ", ".join(f"{band} {value:.2f}" for band, value in geometry_by_band.items())
    sys.stdout.write(
        f"| the head plane's own share (a perfect body detector, no dilation) | {g50:.2f} [{g10:.2f}, {g90:.2f}] | "
        f"{bands} | - | - |\n"
    )
    reach_rows = reach_table(measured[REACH])
    for row in reach_rows:
        sys.stdout.write(
            f"reach {row['band']}, run read down to {row['assumed_lowest_m']:g} m: {row['bodies']} bodies "
            f"({row['not_measured']} more in view not measured), margin "
            f"median {row['margin_m_p50']:.2f} m, p5 {row['margin_m_p5']:.2f} m, below 0: {row['below_0']} "
            f"({100 * row['below_0'] / max(1, row['bodies']):.1f} %)\n"
        )
    geometry_row = {"berth_m_p10_p50_p90": [round(q, 3) for q in (g10, g50, g90)],
                    "berth_m_median_by_band": geometry_by_band}  # fmt: skip
    save_report(
        {"machine": machine_context(), "folders": [str(f) for f in args.folders], "frames": measured["frames"],
         "every": args.every, "sun_elevation_deg": measured["sun_elevation_deg"], "variants": rows,
         GEOMETRY: geometry_row, REACH: reach_rows},
        args.out,
    )  # fmt: skip
    return 0


def reach_table(reach: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per altitude band and assumed lowest height: bodies measured, in view but not measured, margin
    quantiles, how many below 0 (the rule would free ground under the body)."""
    rows = []
    for _, band in BANDS:
        found = reach.get(band)
        if found is None:
            continue
        for z_key, margins in found["margins_m"].items():
            values = np.asarray(margins, np.float64)
            p5, p50 = (float(q) for q in np.quantile(values, (0.05, 0.5)))
            rows.append(
                {"band": band, "assumed_lowest_m": float(z_key), "bodies": len(values),
                 "not_measured": found["not_measured"], "margin_m_p5": round(p5, 3), "margin_m_p50": round(p50, 3),
                 "margin_m_min": round(float(values.min()), 3), "below_0": int((values < 0).sum())}
            )  # fmt: skip
    return rows


if __name__ == "__main__":
    sys.exit(main())
