"""A contact sheet of what the SITL camera sees: weather conditions x altitudes, the person mask beside each frame."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from sitl.render.camera import Light, WorldRenderer
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import ScenarioConfig, WeatherKind
from sitl.world.weather import WeatherState, apply_weather

CONDITIONS = (
    (WeatherKind.CLEAR, 0.0),
    (WeatherKind.FOG, 0.6),
    (WeatherKind.RAIN, 0.7),
    (WeatherKind.SNOW, 0.6),
    (WeatherKind.DUST, 0.5),
    (WeatherKind.DUSK, 0.7),
)
ALTITUDES_M = (10.0, 25.0, 40.0)


def contact_sheet(seed: int, out_path: Path, width_px: int = 320, height_px: int = 240) -> Path:
    """Render the sheet for ``seed`` (rows: conditions; columns: altitudes, each frame then its mask) to a PNG."""
    config = ScenarioConfig(moving_fraction=0.2)
    rng = np.random.default_rng([seed, 7])
    light = Light.from_angles(
        float(rng.uniform(config.sun_elevation_deg.low, config.sun_elevation_deg.high)),
        float(rng.uniform(config.sun_azimuth_deg.low, config.sun_azimuth_deg.high)),
        float(rng.uniform(config.ambient.low, config.ambient.high)),
    )
    camera = PinholeCamera.from_hfov(width_px, height_px, 90.0)
    renderer = WorldRenderer(Park(seed), Crowd(config, seed), camera, T_body_camera_from_mount(), light)
    rows = []
    try:
        for r, (kind, strength) in enumerate(CONDITIONS):
            cells = []
            for altitude in ALTITUDES_M:
                view = renderer.render(Pose.from_ned_euler(0.0, 0.0, -altitude, 0.0, 0.0, 0.3), t_s=0.0)
                frame = apply_weather(view.image_bgr, WeatherState(kind, strength), seed * 100 + r, view.depth_m)
                mask = cv2.cvtColor(view.person_mask.astype(np.uint8) * 255, cv2.COLOR_GRAY2BGR)
                label = f"{kind.value} {strength:.1f}, {altitude:.0f} m"
                cv2.putText(frame, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 2, cv2.LINE_AA)
                cv2.putText(frame, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
                cells += [frame, mask, np.full((height_px, 4, 3), 255, np.uint8)]
            rows.append(np.hstack(cells))
    finally:
        renderer.close()
    sheet = np.vstack([np.vstack([row, np.full((4, row.shape[1], 3), 255, np.uint8)]) for row in rows])
    out_path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out_path), sheet)
    return out_path
