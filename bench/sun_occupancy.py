"""Does a low sun fill the map with people? The same scenes rendered under a low and a high sun, mapped and compared.

The ROI table's holds come mostly from scenes with the sun low (``bench/map_berth.py`` prints each replay's sun): a
person's shadow is ``1.7 m / tan(elevation)`` long, 4.7 m at 20 degrees and 1.0 m at 60. This holds everything else
fixed: for each seed, the same park and crowd (standing still) are drawn from the same poses (40, 20 and 8 m above
the region of interest, level) under each sun elevation (same azimuth and ambient light), and the shipped pipeline
maps each frame onto the head plane. Against the crowd's true positions it reports, per sun elevation:

- **ground called occupied**: of the known head-plane cells in the region of interest more than 3 m from every
  body's edge, the share the map calls occupied (false positives away from people);
- **largest zone**: the largest free circle the zone finder finds in the region (mean over frames), m;
- **bodies seen**: bodies whose head cell has an occupied cell within 0.3 m.

Run: ``.venv/bin/python -m bench.sun_occupancy [--seeds 12] [--suns 22 45 70]`` (a few seconds per seed).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from bench.machine import machine_context, save_report
from bench.map_berth import bodies_seen
from companion.config import load_yaml_config
from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount, inside_polygon
from companion.perception.config import PerceptionConfig
from companion.perception.pipeline import SlzPipeline
from sitl.render.camera import Light, WorldRenderer
from sitl.vehicle.truth import clearance_m
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import ScenarioConfig

REPO_ROOT = Path(__file__).resolve().parent.parent


ALTITUDES_M = (40.0, 20.0, 8.0)
AWAY_FROM_PEOPLE_M = 3.0
AZIMUTH_DEG = 135.0
AMBIENT = 0.45


def measure(seeds: int, suns_deg: list[float]) -> dict[str, Any]:
    """Per sun elevation: ground called occupied, largest zone, bodies seen, over every seed and altitude."""
    perception = load_yaml_config(PerceptionConfig, REPO_ROOT / "mission_configs/perception.yaml", section="perception")
    scenario = ScenarioConfig(moving_fraction=0.0)
    half = scenario.roi_side_m / 2
    roi = np.array([[-half, -half], [-half, half], [half, half], [half, -half]])
    roi_perception = perception.model_copy(
        update={"zones": perception.zones.model_copy(update={"landing_area_ne_m": [tuple(v) for v in roi]})}
    )
    pipeline = SlzPipeline.from_config(roi_perception)
    camera = PinholeCamera.from_hfov(
        perception.camera.width_px, perception.camera.height_px, perception.camera.hfov_deg
    )
    out: dict[str, Any] = {
        f"{sun:g}": {"occupied": 0, "away": 0, "zones_m": [], "seen": 0, "bodies": 0} for sun in suns_deg
    }
    for seed in range(seeds):
        park, crowd = Park(seed), Crowd(scenario, seed)
        positions, radii = crowd.positions_ne_m, crowd.radii_m
        for sun in suns_deg:
            renderer = WorldRenderer(
                park, crowd, camera, T_body_camera_from_mount(), Light.from_angles(sun, AZIMUTH_DEG, AMBIENT)
            )
            found = out[f"{sun:g}"]
            try:
                for altitude_m in ALTITUDES_M:
                    pose = Pose.from_ned_euler(0.0, 0.0, -altitude_m, 0.0, 0.0, 0.0)
                    view = renderer.render(pose, t_s=0.0, with_mask=False, with_depth=False)
                    pipeline.reset()
                    result = pipeline.process(view.image_bgr, pose, 0.0)
                    head_plane = result.head_plane
                    grid = head_plane.grid
                    occupied = head_plane.known & ~head_plane.free
                    north, east = np.meshgrid(grid.north_centres_m, grid.east_centres_m, indexing="ij")
                    clearance = clearance_m(positions, radii, north, east)
                    away = head_plane.known & inside_polygon(roi, north, east) & (clearance > AWAY_FROM_PEOPLE_M)
                    found["occupied"] += int((away & occupied).sum())
                    found["away"] += int(away.sum())
                    found["zones_m"].append(max((z.radius_m for z in result.zones), default=0.0))
                    seen, counted = bodies_seen(head_plane, occupied, positions)
                    found["seen"] += seen
                    found["bodies"] += counted
            finally:
                renderer.close()
        sys.stdout.write(f"seed {seed}: done\n")
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description="The same scenes mapped under a low and a high sun.")
    parser.add_argument("--seeds", type=int, default=12)
    parser.add_argument("--suns", type=float, nargs="+", default=[22.0, 45.0, 70.0], help="sun elevations, degrees")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench/results/sun_occupancy.json")
    args = parser.parse_args()
    measured = measure(args.seeds, args.suns)
    frames = args.seeds * len(ALTITUDES_M)
    altitudes = ", ".join(f"{a:g}" for a in ALTITUDES_M)
    sys.stdout.write(
        f"{args.seeds} scenes x {len(ALTITUDES_M)} altitudes ({altitudes} m) per sun elevation, standing crowds, "
        "shipped perception\n"
    )
    sys.stdout.write(
        "| sun elevation | shadow of 1.7 m | ground called occupied | largest zone m (mean) | bodies seen |\n"
    )
    sys.stdout.write("| --- | --- | --- | --- | --- |\n")
    rows = []
    for sun, found in measured.items():
        share = found["occupied"] / max(1, found["away"])
        zone_m = float(np.mean(found["zones_m"]))
        seen = found["seen"] / max(1, found["bodies"])
        shadow_m = 1.7 / np.tan(np.radians(float(sun)))
        rows.append({"sun_elevation_deg": float(sun), "shadow_m": round(float(shadow_m), 2), "ground_called_occupied":
                     share, "largest_zone_m": zone_m, "bodies_seen": found["seen"], "bodies": found["bodies"],
                     "frames": frames})  # fmt: skip
        sys.stdout.write(
            f"| {sun} deg | {shadow_m:.1f} m | {100 * share:.1f} % | {zone_m:.2f} | {found['seen']} / "
            f"{found['bodies']} ({100 * seen:.1f} %) |\n"
        )
    save_report({"machine": machine_context(), "seeds": args.seeds, "altitudes_m": ALTITUDES_M, "rows": rows}, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
