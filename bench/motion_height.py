"""The height map from the camera's motion (issue 64) against the SITL's truth, and what it costs.

Run: ``.venv/bin/python -m bench.motion_height [--seeds 0 1 2 ...] [--out bench/results/motion_height.json]``.
Renders seeded park scenes (MakeHuman people, a fifth of them walking) with the SITL's renderer and flies the camera
through them as the companion does: the search's and the approach's straight flight at ``--speed-mps`` (2 m/s) at 15,
20 and 30 m, and the final descent (1.5 m/s down from 12 m), frames at 10 Hz; each frame goes through
:class:`~companion.perception.motion_height.MotionHeight` as in flight (the earlier frame chosen for its baseline).
The renderer's depth gives the true height of every pixel. For the last frame of each flight it counts, per person
(the cells within a person's outline), whether geometry alone flagged them above the ground or moving (standing people
taller than 1.5 m, walking, sitting), the share of open ground wrongly flagged (cells farther than 1 m from anything
taller than 0.2 m), the median absolute height error of the people's and objects' cells the map measured, and the
share of cells measured at all; per pose, the share of people the occupancy the zones are built from misses (no cell
of their outline occupied), from the shipped density model alone and fused with the height map, and the open ground
each occupies; and the median time of one update (one thread), wall and the thread's CPU time (the cost a busy host
hides less). Prints a table and saves JSON with the machine's context.
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from bench.machine import machine_context, save_report
from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from companion.perception.config import (
    ModelConfig,
    MotionHeightConfig,
    OccupancyConfig,
    ProjectionConfig,
)
from companion.perception.density import OnnxDensityModel, input_scale, predict_downscaled
from companion.perception.motion_height import CELL_PX, HeightMap, HeightState, MotionHeight
from companion.perception.occupancy import OccupancyMapper
from companion.perception.projection import HeadPlaneProjector
from sitl.render.camera import Light, WorldRenderer
from sitl.world.crowd import BodyType, Crowd
from sitl.world.park import Park
from sitl.world.scenario import ScenarioConfig

REPO_ROOT = Path(__file__).resolve().parent.parent
SITTING = (BodyType.ADULT_SITTING, BodyType.CHILD_SITTING)
FRAME_RATE_HZ = 10.0


@dataclass
class FlightScore:
    """What one flight's last height map got right and wrong."""

    kind: str
    altitude_m: float
    standing: list[bool] = field(default_factory=list)
    walking: list[bool] = field(default_factory=list)
    sitting: list[bool] = field(default_factory=list)
    ground_cells: int = 0
    ground_flagged: int = 0
    ground_measured: int = 0
    errors_people_m: list[float] = field(default_factory=list)
    errors_objects_m: list[float] = field(default_factory=list)
    objects_cells: int = 0
    objects_flagged: int = 0
    update_ms: list[float] = field(default_factory=list)
    update_cpu_ms: list[float] = field(default_factory=list)
    parallax_px_per_m: float = 0.0
    # Found by the occupancy the zones are built from (a cell of the person's outline occupied): the density map
    # alone, and fused with the height map. By pose.
    density_found: dict[str, list[bool]] = field(default_factory=lambda: {"standing": [], "walking": [], "sitting": []})
    fused_found: dict[str, list[bool]] = field(default_factory=lambda: {"standing": [], "walking": [], "sitting": []})
    density_ground_occupied: int = 0
    fused_ground_occupied: int = 0


def true_heights(view_depth: npt.NDArray[np.float32], pose: Pose, camera: PinholeCamera, T_body_camera: Any) -> Any:
    """Height above the ground (m) of what each pixel sees, from the renderer's depth along the optical axis."""
    T = pose.T_world_body @ T_body_camera
    h, w = view_depth.shape
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rays = np.stack([(uu - camera.cx_px) / camera.fx_px, (vv - camera.cy_px) / camera.fy_px, np.ones_like(uu)], -1)
    points = T[:3, 3] + (rays * view_depth[..., None]) @ T[:3, :3].T
    return np.where(view_depth > 0, -points[..., 2], np.nan)


def _cells_max(values: Any, shape: tuple[int, int]) -> Any:
    rows, cols = shape
    return np.nanmax(values[: rows * CELL_PX, : cols * CELL_PX].reshape(rows, CELL_PX, cols, CELL_PX), axis=(1, 3))


def occupancy_cells(
    model: OnnxDensityModel, frame_bgr: Any, pose: Pose, camera: PinholeCamera, T_body_camera: Any, height: HeightMap
) -> tuple[Any, Any]:
    """The occupied cells (the height map's grid) of a frame as the companion makes them: density alone, and fused."""
    projector = HeadPlaneProjector(camera, T_body_camera, ProjectionConfig())
    gsd = projector.finest_gsd_m_per_px(pose)
    density = predict_downscaled(model, frame_bgr, input_scale(gsd, ModelConfig().min_gsd_m_per_px))
    mapper = OccupancyMapper(OccupancyConfig())
    alone = mapper.compute(density, gsd).values == 0
    fused = mapper.compute(density, gsd, also_occupied=height.resampled(density.values.shape)).values == 0
    size = (height.state.shape[1], height.state.shape[0])

    def on_grid(mask: Any) -> Any:
        return cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0

    return on_grid(alone), on_grid(fused)


def score(
    kind: str,
    renderer: WorldRenderer,
    camera: PinholeCamera,
    T_body_camera: Any,
    poses: list[Pose],
    config: Any,
    model: OnnxDensityModel | None = None,
) -> FlightScore:
    """Fly ``poses`` (one per frame at 10 Hz) and score the last frame's height map."""
    estimator = MotionHeight(camera, T_body_camera, config)
    result = FlightScore(kind, poses[-1].altitude_m)
    last: HeightMap | None = None
    view = None
    for k, pose in enumerate(poses):
        t_s = k / FRAME_RATE_HZ
        view = renderer.render(pose, t_s, with_mask=True, with_depth=True)
        start, start_cpu = time.perf_counter(), time.thread_time()
        last = estimator.update(view.image_bgr, pose, t_s)
        result.update_ms.append(1e3 * (time.perf_counter() - start))
        result.update_cpu_ms.append(1e3 * (time.thread_time() - start_cpu))  # this thread's CPU: what a busy host hides
    assert last is not None
    assert view is not None
    result.parallax_px_per_m = last.parallax_px_per_m
    heights = true_heights(view.depth_m, poses[-1], camera, T_body_camera)
    shape = last.state.shape
    tall = _cells_max(heights, shape)
    person_cells = _cells_max(view.person_mask.astype(np.float32), shape) > 0
    flagged = last.not_ground
    measured = last.state != HeightState.UNKNOWN
    anything = (np.nan_to_num(tall, nan=0.0) > 0.2).astype(np.uint8)
    gsd = poses[-1].altitude_m / camera.fx_px
    near = max(1, round(1.0 / (gsd * CELL_PX)))
    near_anything = cv2.dilate(anything, np.ones((2 * near + 1, 2 * near + 1), np.uint8)) > 0
    open_ground = ~near_anything & np.isfinite(tall)
    result.ground_cells = int(open_ground.sum())
    result.ground_flagged = int((flagged & open_ground).sum())
    result.ground_measured = int((measured & open_ground).sum())
    if model is not None:
        alone, fused = occupancy_cells(model, view.image_bgr, poses[-1], camera, T_body_camera, last)
        result.density_ground_occupied = int((alone & open_ground).sum())
        result.fused_ground_occupied = int((fused & open_ground).sum())
    else:
        alone = fused = np.zeros(shape, bool)
    objects = (np.nan_to_num(tall, nan=0.0) > 0.5) & ~person_cells
    result.objects_cells = int(objects.sum())
    result.objects_flagged = int((flagged & objects).sum())
    good = measured & np.isfinite(last.height_m)
    result.errors_objects_m = [float(x) for x in np.abs(last.height_m - tall)[objects & good]]
    result.errors_people_m = [float(x) for x in np.abs(last.height_m - tall)[person_cells & good]]
    # Per person: the cells of their outline (the person mask within their radius of their head's pixel).
    heads, front = renderer.head_pixels(poses[-1])
    crowd = renderer.crowd
    rows, cols = shape
    for i in range(len(crowd)):
        if not front[i]:
            continue
        u, v = heads[i]
        radius_px = (float(crowd.radii_m[i]) + 0.3) / gsd
        r0, r1 = int((v - radius_px) // CELL_PX), int((v + radius_px) // CELL_PX) + 1
        c0, c1 = int((u - radius_px) // CELL_PX), int((u + radius_px) // CELL_PX) + 1
        if r0 < 0 or c0 < 0 or r1 > rows or c1 > cols:
            continue  # partly out of view
        outline = person_cells[r0:r1, c0:c1]
        if not outline.any():
            continue  # hidden (under a crown)
        hit = bool(flagged[r0:r1, c0:c1][outline].any())
        if crowd.moving[i]:
            pose_name = "walking"
        elif crowd.appearances[i].body in SITTING:
            pose_name = "sitting"
        elif renderer.head_height_m(i) >= 1.4:  # taller than about 1.5 m
            pose_name = "standing"
        else:
            continue
        getattr(result, pose_name).append(hit)
        if model is not None:
            result.density_found[pose_name].append(bool(alone[r0:r1, c0:c1][outline].any()))
            result.fused_found[pose_name].append(bool(fused[r0:r1, c0:c1][outline].any()))
    return result


def flights(altitudes_m: tuple[float, ...], speed_mps: float, seconds: float) -> list[tuple[str, list[Pose]]]:
    """The flights: straight and level at each altitude, and the final descent."""
    n = round(seconds * FRAME_RATE_HZ) + 1
    out = []
    for altitude in altitudes_m:
        out.append(
            (
                f"level {altitude:g} m",
                [
                    Pose.from_ned_euler(
                        -speed_mps * seconds / 2 + speed_mps * k / FRAME_RATE_HZ, 1.0, -altitude, 0.01, -0.03, 0.4
                    )
                    for k in range(n)
                ],
            )
        )
    out.append(
        (
            "descent 12 m",
            [Pose.from_ned_euler(0.5, 1.0, -(12.0 - 1.5 * k / FRAME_RATE_HZ), 0.01, -0.02, 0.4) for k in range(n)],
        )
    )
    return out


def summarise(scores: list[FlightScore]) -> dict[str, Any]:
    """Per kind of flight: the shares and medians over its scenes."""

    def share(values: list[bool]) -> float | None:
        return round(sum(values) / len(values), 3) if values else None

    def miss(values: list[bool]) -> float | None:
        return round(1.0 - sum(values) / len(values), 3) if values else None

    out: dict[str, Any] = {}
    for kind in dict.fromkeys(s.kind for s in scores):
        group = [s for s in scores if s.kind == kind]

        def flat(name: str, group: list[FlightScore] = group) -> list[Any]:
            return [x for s in group for x in getattr(s, name)]

        ground = sum(s.ground_cells for s in group)
        people_errors, object_errors = flat("errors_people_m"), flat("errors_objects_m")
        out[kind] = {
            "scenes": len(group),
            "standing_flagged": share(flat("standing")),
            "standing_people": len(flat("standing")),
            "walking_flagged": share(flat("walking")),
            "walking_people": len(flat("walking")),
            "sitting_flagged": share(flat("sitting")),
            "sitting_people": len(flat("sitting")),
            "open_ground_flagged": round(sum(s.ground_flagged for s in group) / max(ground, 1), 4),
            "open_ground_measured": round(sum(s.ground_measured for s in group) / max(ground, 1), 3),
            "objects_flagged": round(
                sum(s.objects_flagged for s in group) / max(sum(s.objects_cells for s in group), 1), 3
            ),
            "median_abs_error_people_m": round(statistics.median(people_errors), 2) if people_errors else None,
            "median_abs_error_objects_m": round(statistics.median(object_errors), 2) if object_errors else None,
            "parallax_px_per_m": round(statistics.median(s.parallax_px_per_m for s in group), 2),
            **{
                f"{which}_miss_{pose}": miss([x for s in group for x in getattr(s, f"{which}_found")[pose]])
                for which in ("density", "fused")
                for pose in ("standing", "walking", "sitting")
            },
            "density_open_ground_occupied": round(sum(s.density_ground_occupied for s in group) / max(ground, 1), 4),
            "fused_open_ground_occupied": round(sum(s.fused_ground_occupied for s in group) / max(ground, 1), 4),
            "update_ms_median": round(statistics.median(flat("update_ms")[1:]), 2),
            "update_cpu_ms_median": round(statistics.median(flat("update_cpu_ms")[1:]), 2),
        }
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(6)))
    parser.add_argument("--speed-mps", type=float, default=2.0)
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench" / "results" / "motion_height.json")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    camera = PinholeCamera.from_hfov(640, 480, 90.0)
    T_body_camera = T_body_camera_from_mount()
    config = MotionHeightConfig(enabled=True)
    model = OnnxDensityModel(REPO_ROOT / "models" / "density" / "slz_yolox.onnx")
    scores = []
    for seed in args.seeds:
        scenario = ScenarioConfig(people_min=80, people_max=100, moving_fraction=0.2)
        light = Light.from_angles(30.0 + 7.0 * (seed % 7), 40.0 * seed, 0.5)
        for kind, poses in flights((15.0, 20.0, 30.0), args.speed_mps, args.seconds):
            renderer = WorldRenderer(Park(seed), Crowd(scenario, seed), camera, T_body_camera, light)
            try:
                scores.append(score(kind, renderer, camera, T_body_camera, poses, config, model))
            finally:
                renderer.close()
    summary = summarise(scores)
    for kind, row in summary.items():
        print(kind, row, flush=True)
    report = {
        "machine": machine_context(),
        "config": config.model_dump(mode="json"),
        "seeds": args.seeds,
        "speed_mps": args.speed_mps,
        "seconds": args.seconds,
        "summary": summary,
        "flights": [
            asdict(s) | {"update_ms": None, "update_cpu_ms": None, "errors_people_m": None, "errors_objects_m": None}
            for s in scores
        ],
    }
    save_report(report, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
