"""A camera that looks like a camera: what a real drone camera does to the picture the renderer draws.

The renderer draws a perfect pinhole image: sharp, evenly lit, noise-free, its colours exact. A drone's camera
blurs it by the vehicle's own motion during the exposure and a slightly soft focus, darkens its corners
(vignetting), lets its exposure and white balance drift as the scene's light changes, adds sensor noise that grows
with the gain, and compresses each frame. The density network learns what it is shown, so the SITL's stream and the
training data (``models/data/generate.py --sensor``) can show it these effects, each of which can be switched off
(:class:`SensorConfig`).

Two stages, as in a real camera, around the lens (``companion.perception.lens``): :func:`optics` (defocus, motion
blur, vignetting) before it, :func:`readout` (exposure and white balance, noise, JPEG) after it. Every random part
is seeded: the same ``mission_seed``, frame seed and time give the same pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt
from pydantic import Field, model_validator

from companion.config import StrictModel

U8Image = npt.NDArray[np.uint8]
F32Image = npt.NDArray[np.float32]


class SensorConfig(StrictModel):
    """The camera's effects on the picture; ``enabled`` switches them all, each flag one of them."""

    enabled: bool = Field(default=False, description="Apply the effects below (off: the renderer's picture).")
    defocus: bool = True
    defocus_sigma_px: tuple[float, float] = Field(
        default=(0.3, 0.9), description="Range of the Gaussian blur of a slightly soft focus (px), drawn per mission."
    )
    motion_blur: bool = True
    exposure_s: float = Field(
        default=0.006, gt=0.0, le=0.1, description="Exposure time: the vehicle's motion smears the picture over it."
    )
    vignetting: bool = True
    vignetting_strength: float = Field(
        default=0.35, ge=0.0, le=1.0, description="Share of the cos^4 falloff the lens leaves (0: none, 1: all)."
    )
    exposure_drift: bool = True
    exposure_drift_ev: float = Field(
        default=0.3, ge=0.0, le=2.0, description="Amplitude of the auto-exposure's slow drift (EV)."
    )
    white_balance_drift: float = Field(
        default=0.05, ge=0.0, le=0.5, description="Amplitude of the blue and red gains' slow drift (fraction)."
    )
    noise: bool = True
    gain_range: tuple[float, float] = Field(
        default=(1.0, 4.0), description="Sensor gain (ISO / 100): darker exposures are read at higher gain."
    )
    read_noise_dn: float = Field(default=1.2, ge=0.0, le=20.0, description="Read noise at gain 1 (8-bit steps).")
    shot_noise_dn: float = Field(
        default=0.5, ge=0.0, le=5.0, description="Shot noise scale: variance = this x gain x level (8-bit steps)."
    )
    compression: bool = True
    jpeg_quality: tuple[int, int] = Field(default=(60, 92), description="JPEG quality range, drawn per frame.")

    @model_validator(mode="after")
    def _ranges(self) -> SensorConfig:
        for name in ("defocus_sigma_px", "gain_range", "jpeg_quality"):
            low, high = getattr(self, name)
            if not 0 <= low <= high:
                raise ValueError(f"{name}: must be (low, high) with 0 <= low <= high, got {(low, high)}")
        if not (self.jpeg_quality[0] >= 1 and self.jpeg_quality[1] <= 100):
            raise ValueError(f"jpeg_quality: within 1..100, got {self.jpeg_quality}")
        if self.gain_range[0] < 1.0:
            raise ValueError(f"gain_range: the gain is at least 1, got {self.gain_range}")
        return self


@dataclass(frozen=True)
class Exposure:
    """One frame's exposure and white balance: a brightness factor and the blue and red channels' gains."""

    factor: float
    blue_gain: float
    red_gain: float


def exposure_at(config: SensorConfig, mission_seed: int, t_s: float) -> Exposure:
    """The auto-exposure and white balance at simulated time ``t_s``: slow drifts (sums of sines of periods 7-40 s,
    their phases seeded per mission), the same at any frame rate."""
    rng = np.random.default_rng([mission_seed, 51, 1])
    periods_s = rng.uniform(7.0, 40.0, size=6)
    phases = rng.uniform(0.0, 2.0 * math.pi, size=6)
    waves = [math.sin(2.0 * math.pi * t_s / p + ph) for p, ph in zip(periods_s, phases, strict=True)]
    ev = config.exposure_drift_ev * 0.5 * (waves[0] + waves[1]) if config.exposure_drift else 0.0
    wb = config.white_balance_drift if config.exposure_drift else 0.0
    return Exposure(2.0**ev, 1.0 + wb * 0.5 * (waves[2] + waves[3]), 1.0 + wb * 0.5 * (waves[4] + waves[5]))


def defocus_sigma_px(config: SensorConfig, mission_seed: int) -> float:
    """The mission's focus blur (px): one camera, one focus."""
    low, high = config.defocus_sigma_px
    return float(np.random.default_rng([mission_seed, 51, 2]).uniform(low, high))


def vignette(width_px: int, height_px: int, fx_px: float, strength: float) -> F32Image:
    """The lens's relative illumination, shape (H, W), 1 at the centre: ``1 - strength (1 - cos^4 theta)``."""
    u = np.arange(width_px, dtype=np.float32) - (width_px - 1) / 2.0
    v = np.arange(height_px, dtype=np.float32) - (height_px - 1) / 2.0
    r2 = (u[None, :] ** 2 + v[:, None] ** 2) / np.float32(fx_px * fx_px)
    cos4 = 1.0 / (1.0 + r2) ** 2
    return np.asarray(1.0 - strength * (1.0 - cos4), dtype=np.float32)


def motion_kernel(velocity_px_s: tuple[float, float], exposure_s: float) -> F32Image | None:
    """A line kernel along the picture's motion during the exposure (``velocity_px_s``: its (u, v) velocity, px/s);
    None when the smear is under half a pixel."""
    du, dv = velocity_px_s[0] * exposure_s, velocity_px_s[1] * exposure_s
    length = math.hypot(du, dv)
    if length < 0.5:
        return None
    size = 2 * math.ceil(length / 2.0) + 1
    kernel = np.zeros((size, size), np.float32)
    c = size // 2
    steps = max(2, math.ceil(length * 4))
    for k in range(steps + 1):  # samples along the segment, bilinear weights on the kernel's grid
        x, y = c + du * (k / steps - 0.5), c + dv * (k / steps - 0.5)
        x0, y0 = math.floor(x), math.floor(y)
        fx, fy = x - x0, y - y0
        for xi, yi, w in ((x0, y0, (1 - fx) * (1 - fy)), (x0 + 1, y0, fx * (1 - fy)), (x0, y0 + 1, (1 - fx) * fy)):
            if 0 <= xi < size and 0 <= yi < size:
                kernel[yi, xi] += w
        if 0 <= x0 + 1 < size and 0 <= y0 + 1 < size:
            kernel[y0 + 1, x0 + 1] += fx * fy
    return np.asarray(kernel / kernel.sum(), dtype=np.float32)


def optics(
    image_bgr: U8Image,
    config: SensorConfig,
    mission_seed: int,
    velocity_px_s: tuple[float, float] = (0.0, 0.0),
    fx_px: float | None = None,
) -> U8Image:
    """Defocus, motion blur and vignetting of a rendered frame, shape (H, W, 3) BGR uint8 (before the lens).

    ``velocity_px_s`` is how fast the picture moves in the image during the exposure (px/s: the vehicle's motion
    seen through the camera); ``fx_px`` the focal length for the vignetting (default: a 90-degree lens)."""
    if not config.enabled:
        return image_bgr
    h, w = image_bgr.shape[:2]
    out = image_bgr
    if config.defocus:
        sigma = defocus_sigma_px(config, mission_seed)
        if sigma > 0.0:
            out = np.asarray(cv2.GaussianBlur(out, (0, 0), sigma), dtype=np.uint8)
    if config.motion_blur:
        kernel = motion_kernel(velocity_px_s, config.exposure_s)
        if kernel is not None:
            out = np.asarray(cv2.filter2D(out, -1, kernel, borderType=cv2.BORDER_REFLECT), dtype=np.uint8)
    if config.vignetting and config.vignetting_strength > 0.0:
        gain = vignette(w, h, fx_px if fx_px is not None else w / 2.0, config.vignetting_strength)
        out = np.clip(out.astype(np.float32) * gain[:, :, None], 0.0, 255.0).astype(np.uint8)
    return out


def readout(image_bgr: U8Image, config: SensorConfig, mission_seed: int, frame_seed: int, t_s: float) -> U8Image:
    """Exposure and white balance, sensor noise and JPEG compression of a frame, shape (H, W, 3) BGR uint8 (after
    the lens). ``frame_seed`` seeds this frame's noise and JPEG quality; ``t_s`` places it in the drifts."""
    if not config.enabled:
        return image_bgr
    rng = np.random.default_rng([mission_seed, 51, 3, frame_seed])
    exposure = exposure_at(config, mission_seed, t_s)
    img = image_bgr.astype(np.float32)
    if config.exposure_drift:
        img *= np.array([exposure.blue_gain, 1.0, exposure.red_gain], np.float32) * np.float32(exposure.factor)
    if config.noise:
        low, high = config.gain_range
        # A darker scene (the exposure drifting down) is read at a higher gain: brighter and noisier.
        gain = float(np.clip(low / min(exposure.factor, 1.0) if config.exposure_drift else low, low, high))
        level = np.clip(img, 0.0, 255.0)
        sigma = np.sqrt(config.shot_noise_dn * gain * level + (config.read_noise_dn * gain) ** 2)
        img = level + rng.standard_normal(img.shape, dtype=np.float32) * sigma.astype(np.float32)
    out = np.clip(np.rint(img), 0.0, 255.0).astype(np.uint8)
    if config.compression:
        quality = int(rng.integers(config.jpeg_quality[0], config.jpeg_quality[1] + 1))
        ok, data = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, quality])
        if ok:
            out = np.asarray(cv2.imdecode(data, cv2.IMREAD_COLOR), dtype=np.uint8)
    return out


def image_velocity_px_s(
    velocity_ned_mps: npt.ArrayLike,
    rates_frd_radps: npt.ArrayLike,
    R_camera_world: npt.ArrayLike,
    R_camera_body: npt.ArrayLike,
    fx_px: float,
    depth_m: float,
) -> tuple[float, float]:
    """How fast the picture's centre moves in the image (px/s) while the vehicle moves at ``velocity_ned_mps`` and
    turns at ``rates_frd_radps``, seen by a camera at ``depth_m`` from the ground along its axis: the translation
    (``-f v_camera / depth``) plus the turn (``f`` times the rate about the image's axes)."""
    v_cam = np.asarray(R_camera_world, np.float64) @ np.asarray(velocity_ned_mps, np.float64)
    w_cam = np.asarray(R_camera_body, np.float64) @ np.asarray(rates_frd_radps, np.float64)
    depth = max(depth_m, 0.5)
    du = -fx_px * v_cam[0] / depth - fx_px * w_cam[1]
    dv = -fx_px * v_cam[1] / depth + fx_px * w_cam[0]
    return float(du), float(dv)
