"""A camera that looks like a camera (sitl/render/sensor.py): each effect does what it says, can be switched off,
and the same seeds give the same pixels; the SITL's camera and the training data apply it."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.geometry import Pose, T_body_camera_from_mount
from sitl.render.sensor import (
    SensorConfig,
    exposure_at,
    image_velocity_px_s,
    motion_kernel,
    optics,
    readout,
)

GREY = np.full((120, 160, 3), 128, np.uint8)
ONLY = {
    "defocus": False,
    "motion_blur": False,
    "vignetting": False,
    "exposure_drift": False,
    "noise": False,
    "compression": False,
}


def only(**on: object) -> SensorConfig:
    """The sensor with every effect off but those named (and their settings)."""
    return SensorConfig.model_validate({"enabled": True, **ONLY, **on})


@pytest.mark.unit
def test_off_by_default_and_when_switched_off_the_picture_is_the_renderers() -> None:
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (120, 160, 3)).astype(np.uint8)
    assert optics(image, SensorConfig(), 1) is image
    assert readout(image, SensorConfig(), 1, 2, 3.0) is image
    assert np.array_equal(readout(optics(image, only(), 1), only(), 1, 2, 3.0), image)


@pytest.mark.unit
def test_the_same_seeds_give_the_same_pixels_and_each_frame_its_own_noise() -> None:
    full = SensorConfig(enabled=True)
    a = readout(optics(GREY, full, 7, (40.0, 0.0)), full, 7, 3, 12.5)
    b = readout(optics(GREY, full, 7, (40.0, 0.0)), full, 7, 3, 12.5)
    c = readout(optics(GREY, full, 7, (40.0, 0.0)), full, 7, 4, 12.5)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.unit
def test_vignetting_darkens_the_corners_by_the_cos4_law_it_keeps() -> None:
    out = optics(GREY, only(vignetting=True, vignetting_strength=0.35), 1, fx_px=80.0)
    corner, centre = float(out[0, 0].mean()), float(out[60, 80].mean())
    r2 = ((159 / 2) ** 2 + (119 / 2) ** 2) / 80.0**2
    want = 128 * (1 - 0.35 * (1 - 1 / (1 + r2) ** 2))
    assert centre == pytest.approx(128, abs=1)
    assert corner == pytest.approx(want, abs=1.5)


@pytest.mark.unit
def test_motion_blur_smears_along_the_motion_only() -> None:
    lines = np.zeros((60, 60, 3), np.uint8)
    lines[:, 30] = 255  # a vertical line
    along_u = optics(lines, only(motion_blur=True, exposure_s=0.01), 1, (800.0, 0.0))  # 8 px across it
    along_v = optics(lines, only(motion_blur=True, exposure_s=0.01), 1, (0.0, 800.0))  # 8 px along it
    assert int((along_u[30, :, 0] > 10).sum()) >= 7
    assert int((along_v[30, :, 0] > 10).sum()) == 1
    kernel = motion_kernel((300.0, 400.0), 0.01)  # 5 px at (3, 4)
    assert kernel is not None
    assert float(kernel.sum()) == pytest.approx(1.0)
    assert motion_kernel((10.0, 0.0), 0.01) is None  # a tenth of a pixel: no blur


@pytest.mark.unit
def test_noise_grows_with_the_gain() -> None:
    low = readout(GREY, only(noise=True, gain_range=(1.0, 1.0)), 1, 1, 0.0).astype(np.float32)
    high = readout(GREY, only(noise=True, gain_range=(4.0, 4.0)), 1, 1, 0.0).astype(np.float32)
    sd_low, sd_high = float(low.std()), float(high.std())
    assert sd_low == pytest.approx(math.sqrt(0.5 * 1 * 128 + 1.2**2), rel=0.1)
    assert sd_high == pytest.approx(math.sqrt(0.5 * 4 * 128 + (1.2 * 4) ** 2), rel=0.1)


@pytest.mark.unit
def test_exposure_and_white_balance_drift_slowly_within_their_amplitude() -> None:
    config = SensorConfig(enabled=True)
    ev = [math.log2(exposure_at(config, 3, 0.1 * k).factor) for k in range(600)]
    assert max(abs(e) for e in ev) <= 0.3 + 1e-9
    assert max(ev) - min(ev) > 0.1  # it does drift over a minute
    assert max(abs(a - b) for a, b in itertools.pairwise(ev)) < 0.02  # slowly: frame to frame
    blue = [exposure_at(config, 3, 0.1 * k).blue_gain for k in range(600)]
    assert max(abs(g - 1.0) for g in blue) <= 0.05 + 1e-9
    steady = only()
    assert exposure_at(steady, 3, 17.0).factor == 1.0


@pytest.mark.unit
def test_compression_leaves_jpeg_blocks() -> None:
    rng = np.random.default_rng(5)
    image = cv2.GaussianBlur(rng.integers(0, 256, (64, 64, 3)).astype(np.uint8), (0, 0), 1.5)
    out = readout(np.asarray(image, np.uint8), only(compression=True, jpeg_quality=(60, 60)), 1, 1, 0.0)
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 60])
    assert ok
    assert np.array_equal(out, np.asarray(cv2.imdecode(data, cv2.IMREAD_COLOR)))  # the frame, as that JPEG decodes
    assert float(np.abs(out.astype(int) - image.astype(int)).mean()) > 0.5


@pytest.mark.unit
def test_flying_north_moves_the_ground_down_the_picture_of_a_nadir_camera() -> None:
    T_body_camera = T_body_camera_from_mount()  # nadir: the picture's top is the nose
    pose = Pose.from_ned_quaternion(0.0, 0.0, -10.0, [1.0, 0.0, 0.0, 0.0])
    R_world_camera = (pose.T_world_body @ T_body_camera)[:3, :3]
    du, dv = image_velocity_px_s(
        [5.0, 0.0, 0.0], [0.0, 0.0, 0.0], R_world_camera.T, T_body_camera[:3, :3].T, 320.0, 10.0
    )
    assert (du, dv) == pytest.approx((0.0, 160.0), abs=1e-6)


@pytest.mark.sitl
def test_the_sitl_camera_applies_it_deterministically(instance: int) -> None:
    from sitl.config import SitlConfig
    from sitl.dynamics.base import VehicleState
    from sitl.vehicle.sim_camera import SimCamera

    state = VehicleState(position_ned_m=np.array([0.0, 0.0, -15.0]), velocity_ned_mps=np.array([3.0, 1.0, 0.0]))
    frames = []
    for sensor in ({}, {"enabled": True}, {"enabled": True}):
        config = SitlConfig.model_validate(
            {"instance": instance, "seed": 2, "camera": {"enabled": True, "sensor": sensor}}
        )
        camera = SimCamera(config)
        try:
            frames.append(camera.draw(4.0, state))
        finally:
            camera.close()
    plain, first, second = frames
    assert np.array_equal(first, second)
    assert float(np.abs(first.astype(int) - plain.astype(int)).mean()) > 2.0


@pytest.mark.sitl
def test_the_training_data_can_be_rendered_through_the_sensor(tmp_path: Path) -> None:
    from models.data.generate import Split, generate

    plain = generate(tmp_path / "plain", Split.TRAIN, 2, frames_per_scene=2)
    sensed = generate(tmp_path / "sensor", Split.TRAIN, 2, frames_per_scene=2, sensor=SensorConfig(enabled=True))
    assert [f.heads for f in plain] == [f.heads for f in sensed]  # the same scenes and labels
    for stem in ("000000", "000001"):
        a = np.asarray(cv2.imread(str(tmp_path / "plain" / "train" / f"{stem}.png")))
        b = np.asarray(cv2.imread(str(tmp_path / "sensor" / "train" / f"{stem}.png")))
        assert float(np.abs(a.astype(int) - b.astype(int)).mean()) > 2.0
        label_a = json.loads((tmp_path / "plain" / "train" / f"{stem}.json").read_text())
        label_b = json.loads((tmp_path / "sensor" / "train" / f"{stem}.json").read_text())
        assert label_a == label_b
