"""Milliseconds per SITL camera frame at 320x240, 640x480 and 960x720, 120 people, 20 % walking, weather on.

Run: ``.venv/bin/python -m bench.render``. pyrender offscreen through EGL (Mesa llvmpipe on a CPU-only machine).
Measures the colour frame alone, with depth, and with depth and the person-mask pass, then the weather effect; writes
``bench/results/render.json`` with the machine's context. Then procedural against MakeHuman people at 640x480 on the
same scene (same places, same walkers), in alternating rounds so that both see the machine at the same moment, from
20 m (as above; MakeHuman people at their coarse level of detail there) and from 10 m (their fine level).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from bench.machine import machine_context, save_report
from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from sitl.render.camera import Light, WorldRenderer
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import PeopleModel, ScenarioConfig, WalkerKind, WeatherKind
from sitl.world.weather import WeatherState, apply_weather

REPO_ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds of the people A/B")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench" / "results" / "render.json")
    args = parser.parse_args()
    config = ScenarioConfig(people_min=120, people_max=120, moving_fraction=0.2)
    rows: dict[str, dict[str, float]] = {}
    for width, height in ((320, 240), (640, 480), (960, 720)):
        camera = PinholeCamera.from_hfov(width, height, 90.0)
        renderer = WorldRenderer(
            Park(1), Crowd(config, 1), camera, T_body_camera_from_mount(), Light.from_angles(50, 120, 0.45)
        )
        row: dict[str, float] = {}
        try:
            for label, with_mask, with_depth in (
                ("colour_ms", False, False),
                ("colour_and_depth_ms", False, True),
                ("colour_depth_and_mask_ms", True, True),
            ):
                times = []
                for k in range(args.frames + 10):
                    pose = Pose.from_ned_euler(0.05 * k, 0.0, -20.0, 0.03 * np.sin(k), 0.0, 0.4)
                    start = time.perf_counter()
                    t_s = 0.1 * k + 100.0 * len(row)
                    view = renderer.render(pose, t_s, with_mask=with_mask, with_depth=with_depth)
                    times.append((time.perf_counter() - start) * 1e3)
                row[label] = float(np.median(times[10:]))  # after warm-up (shader compilation)
            weather_times = []
            for k in range(args.frames):
                start = time.perf_counter()
                apply_weather(view.image_bgr, WeatherState(WeatherKind.RAIN, 0.6), k, view.depth_m)
                weather_times.append((time.perf_counter() - start) * 1e3)
            row["weather_rain_ms"] = float(np.median(weather_times))
        finally:
            renderer.close()
        rows[f"{width}x{height}"] = row
    people = _people_ab(args.frames, args.rounds, 20.0)
    people_low = _people_ab(args.frames, args.rounds, 10.0)
    report = {
        "benchmark": "render",
        "people": 120,
        "moving_fraction": 0.2,
        "machine": machine_context(),
        "sizes": rows,
        "people_ab_640x480": people,
        "people_ab_640x480_10m": people_low,
    }
    sys.stdout.write(f"SITL camera, median ms per frame, {report['machine']}\n")
    for size, row in rows.items():
        sys.stdout.write(f"{size:<9} " + "  ".join(f"{k} {v:.1f}" for k, v in row.items()) + "\n")
    for altitude, ab in (("20 m", people), ("10 m", people_low)):
        for model, row in ab.items():
            line = "  ".join(f"{k} {v:.2f}" for k, v in row.items())
            sys.stdout.write(f"640x480 from {altitude} {model:<26} {line}\n")
    save_report(report, args.out)
    return 0


def _people_ab(frames: int, rounds: int, altitude_m: float) -> dict[str, dict[str, float]]:
    """Procedural against MakeHuman people, 640x480, 120 people, 20 % walking pedestrians, alternating rounds, the
    camera ``altitude_m`` over the ground."""
    camera = PinholeCamera.from_hfov(640, 480, 90.0)
    times: dict[str, dict[str, list[float]]] = {
        m.value: {"colour_ms": [], "colour_depth_and_mask_ms": []} for m in PeopleModel
    }
    for round_ in range(rounds):
        for model in PeopleModel:
            config = ScenarioConfig(
                people_min=120, people_max=120, moving_fraction=0.2, walker=WalkerKind.PERSISTENT, people=model
            )
            renderer = WorldRenderer(
                Park(1), Crowd(config, 1), camera, T_body_camera_from_mount(), Light.from_angles(50, 120, 0.45)
            )
            try:
                for label, with_mask in (("colour_ms", False), ("colour_depth_and_mask_ms", True)):
                    for k in range(frames + 10):
                        pose = Pose.from_ned_euler(0.05 * k, 0.0, -altitude_m, 0.03 * np.sin(k), 0.0, 0.4)
                        t_s = 0.1 * k + 100.0 * round_ + (50.0 if with_mask else 0.0)
                        start = time.perf_counter()
                        renderer.render(pose, t_s, with_mask=with_mask, with_depth=with_mask)
                        if k >= 10:  # after warm-up
                            times[model.value][label].append((time.perf_counter() - start) * 1e3)
            finally:
                renderer.close()
    out = {model: {label: float(np.median(v)) for label, v in row.items()} for model, row in times.items()}
    base, new = out[PeopleModel.PROCEDURAL.value], out[PeopleModel.MAKEHUMAN.value]
    out["makehuman_over_procedural"] = {label: new[label] / base[label] for label in base}
    return out


if __name__ == "__main__":
    sys.exit(main())
