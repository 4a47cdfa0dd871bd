"""Render a labelled crowd dataset from the SITL world: frames, person masks and head points.

Frames are rendered the way the SITL camera renders them for the companion (same renderer, weather and pinhole
camera), at 8-40 m altitude (``--altitude-m 2 40`` down to the final descent) with the tilts and lighting the SITL
samples. The held-out split is a *style* split, not only other seeds: disjoint seed ranges, the other half of the
grass colours, cool instead of warm clothing hues, three body types training never sees (elderly with cane,
stroller, umbrella), and only the weather kinds training never sees (fog, snow, dust; training has clear, rain,
dusk).

On-disk format (``OUT/<split>/``):

- ``NNNNNN.png``: the frame, 8-bit BGR;
- ``NNNNNN.mask.png``: 8-bit, 255 where a person is visible;
- ``NNNNNN.json``: ``{"index", "split", "seed", "altitude_m", "tilt_deg", "T_world_body" (4x4, NED/FRD),
  "T_body_camera" (4x4, OpenCV camera), "camera": {"width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px"},
  "weather": {"kind", "strength"}, "heads": [[u_px, v_px], ...], "people_in_view"}`` where ``heads`` are the
  pixel positions of the centres of the *visible* heads (a head hidden by a tree crown or an umbrella is not
  labelled) and ``people_in_view`` counts every person whose head projects into the frame;
- ``index.jsonl`` (``index.<first>.jsonl`` for a chunk that starts at frame ``first``): one line per frame with its
  file stem, altitude, weather and head count.

Frame ``i`` depends only on the split, the base seed and ``i``, so a split can be rendered in chunks by parallel
processes (``--first``) and gives the same files as one run.

Run: ``.venv/bin/python -m models.data.generate --split train --frames 500 --out data/synth``.
"""

from __future__ import annotations

import argparse
import enum
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from sitl.render.camera import Light, WorldRenderer
from sitl.render.sensor import SensorConfig, optics, readout
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import GroundKind, PeopleModel, ScenarioConfig, Style, WeatherKind
from sitl.world.weather import WeatherSchedule, apply_weather


class Split(str, enum.Enum):
    """Dataset splits."""

    TRAIN = "train"
    HELDOUT = "heldout"


SEED_OFFSET = {Split.TRAIN: 0, Split.HELDOUT: 1_000_000}
WEATHER = {
    Split.TRAIN: [WeatherKind.CLEAR, WeatherKind.RAIN, WeatherKind.DUSK],
    Split.HELDOUT: [WeatherKind.FOG, WeatherKind.SNOW, WeatherKind.DUST],
}
STYLE = {Split.TRAIN: Style.TRAIN, Split.HELDOUT: Style.HELDOUT}


@dataclass(frozen=True)
class GeneratedFrame:
    """What was written for one frame."""

    stem: str
    heads: int
    people_in_view: int
    altitude_m: float
    weather: str


def generate(
    out_dir: Path,
    split: Split,
    frames: int,
    base_seed: int = 0,
    width_px: int = 640,
    height_px: int = 480,
    hfov_deg: float = 90.0,
    frames_per_scene: int = 8,
    first: int = 0,
    altitude_range_m: tuple[float, float] = (8.0, 40.0),
    ground: GroundKind = GroundKind.PROCEDURAL,
    sensor: SensorConfig | None = None,
    people: PeopleModel = PeopleModel.PROCEDURAL,
) -> list[GeneratedFrame]:
    """Render frames ``first .. first + frames - 1`` of ``split`` into ``out_dir/<split>`` (module docstring).

    ``altitude_range_m`` is the (lowest, highest) camera altitude in metres, drawn uniformly; the default 8-40 m
    gives the frames the shipped models were trained and evaluated on, 2-40 m adds the final descent. ``ground``
    ``real`` paints the parks' ground from the real frames held out from training (``sitl/world/ground.py``): the
    held-out split's real-ground variant. ``sensor`` (``--sensor``): the SITL camera's effects (motion blur for a
    speed drawn per frame up to 5 m/s, defocus, vignetting, exposure and white balance drift, noise, JPEG;
    ``sitl/render/sensor.py``), seeded per scene and frame; None draws the frames as before, bit for bit.
    ``people`` (``--people makehuman``): MakeHuman bodies in the same places (``sitl/render/bodies``); heads are
    labelled at each body's own head height.
    """
    lo_m, hi_m = altitude_range_m
    if not (math.isfinite(lo_m) and math.isfinite(hi_m) and 2.0 <= lo_m < hi_m <= 120.0):
        raise ValueError(f"altitude_range_m must satisfy 2 <= low < high <= 120 m, got {altitude_range_m}")
    split_dir = out_dir / split.value
    split_dir.mkdir(parents=True, exist_ok=True)
    camera = PinholeCamera.from_hfov(width_px, height_px, hfov_deg)
    written: list[GeneratedFrame] = []
    index_lines = []
    scene_seed = -1
    renderer: WorldRenderer | None = None
    for i in range(first, first + frames):
        scene = i // frames_per_scene
        seed = SEED_OFFSET[split] + base_seed + scene
        rng = np.random.default_rng([seed, 9, i])
        tilt_deg = float(rng.choice([0.0, 0.0, 10.0, 20.0, 30.0]))
        if scene != scene_seed:
            scene_seed = scene
            scenario = ScenarioConfig(
                moving_fraction=0.2, weather=WEATHER[split], style=STYLE[split], child_fraction=0.15, people=people
            )
            crowd = Crowd(scenario, seed)
            park = Park(seed, style=STYLE[split], ground=ground)
            light_rng = np.random.default_rng([seed, 8])
            light = Light.from_angles(
                float(light_rng.uniform(20, 80)), float(light_rng.uniform(0, 360)), float(light_rng.uniform(0.3, 0.7))
            )
            weather = WeatherSchedule(scenario, seed).state_at(0.0)
            if renderer is not None:
                renderer.close()
            renderer = WorldRenderer(park, crowd, camera, T_body_camera_from_mount(), light)
        assert renderer is not None
        renderer.T_body_camera = T_body_camera_from_mount(tilt_deg=tilt_deg)  # read at each render
        altitude_m = float(rng.uniform(lo_m, hi_m))
        north, east = (float(v) for v in rng.uniform(-10.0, 10.0, size=2))
        pose = Pose.from_ned_euler(
            north,
            east,
            -altitude_m,
            float(rng.normal(0, 0.05)),
            float(rng.normal(0, 0.05)),
            float(rng.uniform(-math.pi, math.pi)),
        )
        t_s = 0.1 * (i % frames_per_scene) * 10  # a second apart: walkers move between a scene's frames
        view = renderer.render(pose, t_s, with_mask=True, with_depth=True)
        image = apply_weather(view.image_bgr, weather, seed * 1000 + i, view.depth_m)
        if sensor is not None and sensor.enabled:
            motion_rng = np.random.default_rng([seed, 51, i])  # its own stream: the frames' other draws stay put
            speed_mps, heading = float(motion_rng.uniform(0.0, 5.0)), float(motion_rng.uniform(0.0, 2.0 * math.pi))
            px_s = camera.fx_px * speed_mps / altitude_m
            velocity_px_s = (px_s * math.cos(heading), px_s * math.sin(heading))
            image = optics(image, sensor, seed, velocity_px_s, camera.fx_px)
            image = readout(image, sensor, seed, i, t_s)
        heads, in_view = _visible_heads(renderer, pose, view.person_mask)
        stem = f"{i:06d}"
        cv2.imwrite(str(split_dir / f"{stem}.png"), image)
        cv2.imwrite(str(split_dir / f"{stem}.mask.png"), view.person_mask.astype(np.uint8) * 255)
        label = {
            "index": i,
            "split": split.value,
            "seed": seed,
            "altitude_m": altitude_m,
            "tilt_deg": tilt_deg,
            "T_world_body": pose.T_world_body.tolist(),
            "T_body_camera": renderer.T_body_camera.tolist(),
            "camera": {
                "width_px": camera.width_px,
                "height_px": camera.height_px,
                "fx_px": camera.fx_px,
                "fy_px": camera.fy_px,
                "cx_px": camera.cx_px,
                "cy_px": camera.cy_px,
            },
            "weather": {"kind": weather.kind.value, "strength": weather.strength},
            "heads": heads,
            "people_in_view": in_view,
        }
        (split_dir / f"{stem}.json").write_text(json.dumps(label) + "\n", encoding="utf-8")
        index_lines.append(
            json.dumps({"stem": stem, "altitude_m": altitude_m, "weather": weather.kind.value, "heads": len(heads)})
        )
        written.append(GeneratedFrame(stem, len(heads), in_view, altitude_m, weather.kind.value))
    if renderer is not None:
        renderer.close()
    index_name = "index.jsonl" if first == 0 else f"index.{first}.jsonl"
    (split_dir / index_name).write_text("\n".join(index_lines) + "\n", encoding="utf-8")
    return written


def _visible_heads(renderer: WorldRenderer, pose: Pose, mask: np.ndarray) -> tuple[list[list[float]], int]:
    """Pixel centres of the visible heads, and how many heads project into the frame at all."""
    heads: list[list[float]] = []
    in_view = 0
    h, w = mask.shape
    for (u, v), front in zip(*renderer.head_pixels(pose), strict=True):
        u, v = float(u), float(v)
        if not front or not (0.0 <= u < w and 0.0 <= v < h):
            continue
        in_view += 1
        ui, vi = int(u), int(v)
        if mask[max(0, vi - 1) : vi + 2, max(0, ui - 1) : ui + 2].any():  # the head is visible there
            heads.append([round(u, 2), round(v, 2)])
    return heads, in_view


def main() -> int:
    parser = argparse.ArgumentParser(description="Render a labelled crowd dataset from the SITL world.")
    parser.add_argument("--split", choices=[s.value for s in Split], required=True)
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--out", type=Path, default=Path("data/synth"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--first", type=int, default=0, help="index of the first frame (to render in chunks)")
    parser.add_argument(
        "--altitude-m",
        type=float,
        nargs=2,
        default=(8.0, 40.0),
        metavar=("LOW", "HIGH"),
        help="camera altitude range in metres (default 8 40; 2 40 adds the final descent)",
    )
    parser.add_argument(
        "--ground",
        choices=[g.value for g in GroundKind],
        default=GroundKind.PROCEDURAL.value,
        help="the parks' ground (real: the real frames held out from training)",
    )
    parser.add_argument(
        "--people",
        choices=[p.value for p in PeopleModel],
        default=PeopleModel.PROCEDURAL.value,
        help="how people are drawn (makehuman: MakeHuman bodies, clothes, hair and poses)",
    )
    parser.add_argument(
        "--sensor",
        action="store_true",
        help="a camera that looks like a camera: the SITL's sensor effects (sitl/render/sensor.py, all on)",
    )
    args = parser.parse_args()
    written = generate(
        args.out,
        Split(args.split),
        args.frames,
        args.seed,
        first=args.first,
        altitude_range_m=tuple(args.altitude_m),
        ground=GroundKind(args.ground),
        sensor=SensorConfig(enabled=True) if args.sensor else None,
        people=PeopleModel(args.people),
    )
    heads = sum(f.heads for f in written)
    sys.stdout.write(f"wrote {len(written)} frames, {heads} visible heads, to {args.out / args.split}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
