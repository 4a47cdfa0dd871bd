"""Per-stage latency of the SLZ perception pipeline on 640x480 frames, on one CPU thread.

Run: ``.venv/bin/python -m bench.perception [--frames N] [--motion-height] [--out F]``.
The density model is the one `mission_configs/perception.yaml` ships. Frames are rendered from seeded planar scenes
along a slow descent (20 m -> 8 m) so tracking sees a moving camera.
Prints median and p95 per stage and in total, with and without the network, and writes them as JSON
(``bench/results/perception.json``; with ``--motion-height``, the height from the camera's motion measured and fused
at every frame as ``perception.motion_height`` does, ``bench/results/perception_motion_height.json``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from bench.machine import machine_context, save_report
from companion.geometry import Pose
from companion.perception.config import load_perception_config
from companion.perception.pipeline import STAGES, SlzPipeline, camera_from_config
from sitl.render.flat_scene import FlatScene

REPO_ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--warmup", type=int, default=10)
    parser.add_argument("--motion-height", action="store_true", help="measure and fuse the height map too")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    name = "perception_motion_height.json" if args.motion_height else "perception.json"
    out = args.out or REPO_ROOT / "bench" / "results" / name

    cv2.setNumThreads(1)
    shipped = load_perception_config(REPO_ROOT / "mission_configs" / "perception.yaml")
    model_path = shipped.model.path if shipped.model.path.is_absolute() else REPO_ROOT / shipped.model.path
    config = shipped.model_copy(
        update={"model": shipped.model.model_copy(update={"path": model_path, "intra_op_threads": 1})}
    )
    if args.motion_height:
        height = config.motion_height.model_copy(update={"enabled": True, "fuse": True})
        config = config.model_copy(update={"motion_height": height})
    pipeline = SlzPipeline.from_config(config)
    camera, T_body_camera = camera_from_config(config.camera)
    scenes = [FlatScene(seed, n_people=180, roi_half_m=20.0) for seed in range(3)]
    frames = []
    for k in range(args.frames + args.warmup):
        altitude_m = 20.0 - 12.0 * (k % 100) / 100.0
        pose = Pose.from_ned_euler(2.0 * math.sin(0.05 * k), 1.0, -altitude_m, 0.03 * math.sin(k), 0.02, 0.4)
        frames.append((scenes[k // 100 % 3].render(camera, T_body_camera, pose).image_bgr, pose))

    stages = (*STAGES, "height") if args.motion_height else STAGES
    timings: dict[str, list[float]] = {stage: [] for stage in (*stages, "total", "total_without_network")}
    for k, (frame, pose) in enumerate(frames):
        if k % 100 == 0:
            pipeline.reset()
        start = time.perf_counter()
        result = pipeline.process(frame, pose, 0.1 * (k % 100))
        total_ms = (time.perf_counter() - start) * 1e3
        if k < args.warmup:
            continue
        for stage in stages:
            timings[stage].append(result.timings_ms[stage])
        timings["total"].append(total_ms)
        timings["total_without_network"].append(total_ms - result.timings_ms["density"])

    summary = {
        name: {"median_ms": float(np.median(v)), "p95_ms": float(np.percentile(v, 95))} for name, v in timings.items()
    }
    report = {
        "benchmark": "perception",
        "frame": f"{camera.width_px}x{camera.height_px}",
        "frames": args.frames,
        "threads": 1,
        "motion_height": args.motion_height,
        "model": str(config.model.path.relative_to(REPO_ROOT)),
        "grid": f"{config.projection.grid_extent_m} m at {config.projection.grid_resolution_m} m",
        "machine": machine_context(),
        "stages": summary,
    }
    sys.stdout.write(f"SLZ perception, {report['frame']}, 1 thread, {args.frames} frames, {report['machine']}\n")
    sys.stdout.write(f"{'stage':<24}{'median ms':>12}{'p95 ms':>12}\n")
    for name, row in summary.items():
        sys.stdout.write(f"{name:<24}{row['median_ms']:>12.2f}{row['p95_ms']:>12.2f}\n")
    save_report(report, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
