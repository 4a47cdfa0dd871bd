"""The main job's current form: the SLZ pipeline on a seeded scene, over a scripted descent.

The scene is the SITL's world (park, crowd, pyrender camera). The vehicle's path here is kinematic (no autopilot
yet): from a random start pose above the region of interest it moves towards the current target and descends at a
fixed rate, one camera frame per step, with a small attitude wobble, so tracking sees a moving camera. Outputs an
annotated PNG (camera view + top view with ground truth) and a JSON summary, and returns the outcome.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from companion.perception.config import PerceptionConfig
from companion.perception.geometry import Pose
from companion.perception.pipeline import FrameResult, SlzPipeline, camera_from_config
from companion.perception.visualize import draw_camera_overlay, draw_top_view, side_by_side
from sitl.render.camera import Light, WorldRenderer
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import ScenarioConfig

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class DemoOutcome:
    """What the demo found.

    Attributes
    ----------
    seed : int
        Scene and start-pose seed.
    n_people : int
        People in the scene.
    frames : int
        Frames processed.
    target_north_m, target_east_m, target_radius_m : float
        The final target (world NED, m); NaN if none was ever selected.
    target_clearance_m : float
        Ground truth: distance from the target centre to the nearest person's body edge.
    final_altitude_m : float
        Altitude of the last frame.
    median_stage_ms : dict
        Median wall time per stage.
    image_path : str
        The annotated PNG.
    """

    seed: int
    n_people: int
    frames: int
    target_north_m: float
    target_east_m: float
    target_radius_m: float
    target_clearance_m: float
    final_altitude_m: float
    median_stage_ms: dict[str, float]
    image_path: str


def run(
    out_dir: Path,
    config: PerceptionConfig,
    seed: int = 1,
    start_altitude_m: float = 20.0,
    stop_altitude_m: float = 8.0,
    descent_per_frame_m: float = 0.4,
    frame_period_s: float = 0.1,
) -> DemoOutcome:
    """Fly the scripted descent and write ``perception.png`` and ``summary.json`` into ``out_dir``."""
    if not (start_altitude_m >= stop_altitude_m > 0 and descent_per_frame_m > 0 and frame_period_s > 0):
        raise ValueError(
            f"need start_altitude_m >= stop_altitude_m > 0 and positive steps, got {start_altitude_m}, "
            f"{stop_altitude_m}, {descent_per_frame_m}, {frame_period_s}"
        )
    pipeline = SlzPipeline.from_config(config)  # first: a model that does not load fails before any work
    rng = np.random.default_rng(seed)
    # The SITL's world: the paper's crowd density (80-120 people in a 30 m square) in a park, rendered in 3-D.
    crowd = Crowd(ScenarioConfig(), seed)
    camera, T_body_camera = camera_from_config(config.camera)
    light = Light.from_angles(float(rng.uniform(35, 75)), float(rng.uniform(0, 360)), 0.5)
    renderer = WorldRenderer(Park(seed), crowd, camera, T_body_camera, light)
    north, east = (float(v) for v in rng.uniform(-8.0, 8.0, size=2))
    yaw = float(rng.uniform(-math.pi, math.pi))
    altitude = start_altitude_m
    t_s = 0.0
    results: list[FrameResult] = []
    frames = []
    try:
        while altitude >= stop_altitude_m:
            wobble = 0.03 * math.sin(2.0 * t_s)
            pose = Pose.from_ned_euler(north, east, -altitude, wobble, -wobble, yaw)
            frame = renderer.render(pose, t_s, with_mask=False, with_depth=False).image_bgr
            frames.append(frame)
            result = pipeline.process(frame, pose, t_s, area_centre_ne_m=(0.0, 0.0))
            results.append(result)
            if result.target is not None:
                dn, de = result.target.north_m - north, result.target.east_m - east
                step = min(1.0, 0.5 / max(math.hypot(dn, de), 1e-9))
                north, east = north + dn * step, east + de * step
            altitude -= descent_per_frame_m
            t_s += frame_period_s
    finally:
        renderer.close()
    last = results[-1]
    image = side_by_side(
        draw_camera_overlay(frames[-1], last, pipeline.projector),
        draw_top_view(last, crowd.positions_ne_m, crowd.radii_m),
    )
    out_dir.mkdir(parents=True, exist_ok=True)
    image_path = out_dir / "perception.png"
    cv2.imwrite(str(image_path), image)
    target = last.target
    nan = float("nan")
    outcome = DemoOutcome(
        seed=seed,
        n_people=len(crowd),
        frames=len(results),
        target_north_m=target.north_m if target else nan,
        target_east_m=target.east_m if target else nan,
        target_radius_m=target.radius_m if target else nan,
        target_clearance_m=crowd.clearance_m(target.north_m, target.east_m) if target else nan,
        final_altitude_m=last.pose.altitude_m,
        median_stage_ms={stage: float(np.median([r.timings_ms[stage] for r in results])) for stage in last.timings_ms},
        image_path=str(image_path),
    )
    (out_dir / "summary.json").write_text(json.dumps(asdict(outcome), indent=2) + "\n", encoding="utf-8")
    return outcome
