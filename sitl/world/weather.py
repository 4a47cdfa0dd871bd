"""Weather and light as image-space effects, with a seeded schedule for "dynamic weather" missions.

Each effect takes a BGR frame (and, for fog, optionally the depth along each pixel's ray) and a per-frame seed, so the
same mission renders the same weather on every machine. Strength is in [0, 1]; 0 leaves the frame unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from sitl.world.scenario import ScenarioConfig, WeatherKind

U8Image = npt.NDArray[np.uint8]
F32Array = npt.NDArray[np.float32]

FOG_AIRLIGHT_BGR = np.array([205.0, 200.0, 198.0], dtype=np.float32)
DUST_BGR = np.array([110.0, 150.0, 185.0], dtype=np.float32)


@dataclass(frozen=True)
class WeatherState:
    """The weather at one moment."""

    kind: WeatherKind
    strength: float


class WeatherSchedule:
    """The weather over a mission: fixed, or changing every ``weather_period_s`` when ``dynamic_weather`` is on.

    Parameters
    ----------
    config : ScenarioConfig
        Allowed kinds and strength range.
    seed : int
        Fixes every draw.
    """

    def __init__(self, config: ScenarioConfig, seed: int) -> None:
        self.config = config
        self._seed = seed

    def _draw(self, slot: int) -> WeatherState:
        rng = np.random.default_rng([self._seed, 3, slot])
        kinds = self.config.weather
        kind = kinds[int(rng.integers(len(kinds)))]
        strength = (
            0.0
            if kind is WeatherKind.CLEAR
            else float(rng.uniform(self.config.weather_strength.low, self.config.weather_strength.high))
        )
        return WeatherState(kind, strength)

    def state_at(self, t_s: float) -> WeatherState:
        """The weather at simulated time ``t_s``."""
        slot = int(t_s // self.config.weather_period_s) if self.config.dynamic_weather else 0
        return self._draw(slot)


def apply_weather(image_bgr: U8Image, state: WeatherState, frame_seed: int, depth_m: F32Array | None = None) -> U8Image:
    """The frame as seen through ``state``.

    Parameters
    ----------
    image_bgr : ndarray, shape (H, W, 3), uint8
        The clear-weather frame.
    state : WeatherState
        Kind and strength.
    frame_seed : int
        Seeds the random parts (drops, flakes, grain) of this frame.
    depth_m : ndarray, shape (H, W), float32, optional
        Distance along each pixel's ray; fog then thickens with distance (Koschmieder), else it is uniform.
    """
    s = float(np.clip(state.strength, 0.0, 1.0))
    if state.kind is WeatherKind.CLEAR or s == 0.0:
        return np.array(image_bgr, dtype=np.uint8)
    rng = np.random.default_rng([frame_seed, 4])
    img = image_bgr.astype(np.float32)
    h, w = image_bgr.shape[:2]
    area = h * w / (640 * 480)  # drop and flake counts scale with the image
    if state.kind is WeatherKind.FOG:
        if depth_m is not None:
            transmission = np.exp(-0.06 * s * np.nan_to_num(depth_m, nan=1e3, posinf=1e3))[:, :, None]
        else:
            transmission = np.float32(1.0 - 0.8 * s)
        img = img * transmission + FOG_AIRLIGHT_BGR * (1.0 - transmission)
    elif state.kind is WeatherKind.DUSK:
        gain = 1.0 - 0.65 * s
        tint = np.array([1.0 - 0.25 * s, 1.0 - 0.1 * s, 1.0], dtype=np.float32)
        mean = img.mean(axis=(0, 1), keepdims=True)
        img = (mean + (img - mean) * (1.0 - 0.4 * s)) * gain * tint
    elif state.kind is WeatherKind.DUST:
        img = img * (1.0 - 0.55 * s) + DUST_BGR * 0.55 * s
        img += rng.normal(0.0, 6.0 * s, size=(h, w, 1)).astype(np.float32)
    elif state.kind is WeatherKind.RAIN:
        img *= 1.0 - 0.25 * s
        streaks = np.zeros((h, w), dtype=np.uint8)
        angle = math.radians(rng.uniform(70.0, 110.0))
        for _ in range(int(400 * s * area)):
            x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
            length = float(rng.uniform(10.0, 30.0))
            end = (int(x + length * math.cos(angle)), int(y + length * math.sin(angle)))
            cv2.line(streaks, (x, y), end, 255, 1, cv2.LINE_AA)
        alpha = (streaks.astype(np.float32) / 255.0 * 0.6)[:, :, None]
        img = img * (1.0 - alpha) + 215.0 * alpha
    elif state.kind is WeatherKind.SNOW:
        img = img * (1.0 - 0.2 * s) + 45.0 * s
        flakes = np.zeros((h, w), dtype=np.uint8)
        for _ in range(int(1500 * s * area)):
            centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
            cv2.circle(flakes, centre, int(rng.integers(1, 3)), 255, -1, cv2.LINE_AA)
        alpha = (flakes.astype(np.float32) / 255.0 * 0.9)[:, :, None]
        img = img * (1.0 - alpha) + 250.0 * alpha
    return np.asarray(np.clip(img, 0.0, 255.0), dtype=np.uint8)
