"""Lens distortion (OpenCV's model): the SITL's camera distorts what it renders, the pipeline undistorts it back to
the pinhole image, and scripts/calibrate_camera.py recovers a lens from chessboard photographs."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from companion.app.mission import camera_mismatches
from companion.geometry import PinholeCamera
from companion.perception.config import PerceptionConfig
from companion.perception.errors import PerceptionError
from companion.perception.lens import LensDistortion
from companion.perception.pipeline import SlzPipeline
from sitl.config import SitlCameraConfig, SitlConfig
from sitl.dynamics.base import VehicleState
from sitl.testing.helpers import run_python

REPO_ROOT = Path(__file__).resolve().parent.parent
CAMERA = PinholeCamera.from_hfov(640, 480, 90.0)
BARREL = [-0.28, 0.09, 0.0008, -0.0006, -0.012]  # a wide-angle board camera's order of magnitude


def interior(image: np.ndarray) -> np.ndarray:
    """The middle of a frame (its edges hold the pixels a lens pushes out of view)."""
    h, w = image.shape[:2]
    return image[h // 5 : h - h // 5, w // 5 : w - w // 5].astype(np.int16)


@pytest.mark.unit
def test_no_coefficients_or_all_zero_is_no_lens_and_a_wrong_count_is_refused() -> None:
    assert LensDistortion.from_coefficients(CAMERA, []) is None
    assert LensDistortion.from_coefficients(CAMERA, [0.0, 0.0, 0.0, 0.0, 0.0]) is None
    with pytest.raises(PerceptionError, match="3 distortion coefficients: OpenCV's model takes 4, 5, 8, 12 or 14"):
        LensDistortion.from_coefficients(CAMERA, [0.1, 0.0, 0.0])
    with pytest.raises(ValueError, match="distortion: 3 coefficients"):
        PerceptionConfig.model_validate({"camera": {"distortion": [0.1, 0.0, 0.0]}})


@pytest.mark.unit
def test_a_distorted_frame_undistorts_back_to_the_pinhole_image() -> None:
    rng = np.random.default_rng(3)
    noise = rng.integers(0, 256, (480, 640, 3)).astype(np.uint8)
    pinhole = np.asarray(cv2.GaussianBlur(noise, (0, 0), 3), dtype=np.uint8)
    lens = LensDistortion(CAMERA, BARREL)
    distorted = lens.distort(pinhole)
    assert np.abs(interior(distorted) - interior(pinhole)).mean() > 5.0  # the lens moves pixels
    restored = lens.undistort(distorted)
    error = np.abs(interior(restored) - interior(pinhole))
    assert error.mean() < 0.5, error.mean()
    assert error.max() <= 8


@pytest.mark.sitl
def test_the_sitl_camera_flies_a_lens_the_pipeline_takes_off_again(instance: int) -> None:
    from sitl.vehicle.sim_camera import SimCamera

    state = VehicleState(position_ned_m=np.array([0.0, 0.0, -15.0]), on_ground=False)
    plain_config = SitlConfig.model_validate({"instance": instance, "seed": 5, "camera": {"enabled": True}})
    lens_config = SitlConfig.model_validate(
        {"instance": instance, "seed": 5, "camera": {"enabled": True, "distortion": BARREL}}
    )
    plain = SimCamera(plain_config)
    try:
        pinhole = plain.draw(0.0, state)
    finally:
        plain.close()
    with_lens = SimCamera(lens_config)
    try:
        distorted = with_lens.draw(0.0, state)
    finally:
        with_lens.close()
    assert np.abs(interior(distorted) - interior(pinhole)).mean() > 3.0
    # The companion configured with the same lens undistorts each frame before its model sees it.
    perception = PerceptionConfig.model_validate({"camera": {"distortion": BARREL}})
    assert camera_mismatches(perception, lens_config.camera) == []
    pipeline = SlzPipeline.from_config(perception)
    assert pipeline.lens is not None
    restored = pipeline.lens.undistort(distorted)
    assert np.abs(interior(restored) - interior(pinhole)).mean() < 2.0
    # A SITL lens the companion does not know (or the other way round) is refused before a mission flies.
    problems = camera_mismatches(PerceptionConfig(), lens_config.camera)
    assert len(problems) == 1
    assert problems[0].startswith("perception.camera.distortion: [] does not match sitl.camera.distortion")
    assert camera_mismatches(perception, SitlCameraConfig()) != []


def chessboard_photographs(lens: LensDistortion, count: int, out: Path) -> list[Path]:
    """``count`` photographs of a flat 10 x 7 chessboard (25 mm squares) from seeded poses 0.3-0.5 m away, taken by
    the pinhole camera ``lens.camera`` through ``lens``."""
    square_px, square_m = 40, 0.025
    board = np.kron((np.indices((7, 10)).sum(axis=0) % 2) * 255, np.ones((square_px, square_px))).astype(np.uint8)
    board = np.asarray(
        cv2.copyMakeBorder(board, square_px, square_px, square_px, square_px, cv2.BORDER_CONSTANT, value=255),
        dtype=np.uint8,
    )
    # Board texture pixel -> board plane (metres, the first inner corner at the origin).
    m_per_px = square_m / square_px
    texture_to_plane = np.array([[m_per_px, 0, -2 * square_m], [0, m_per_px, -2 * square_m], [0, 0, 1]])
    rng = np.random.default_rng(11)
    paths = []
    for k in range(count):
        rvec = rng.normal(0.0, 0.35, 3)
        R, _ = cv2.Rodrigues(rvec)
        centre_plane = np.array([4.5 * square_m, 3.0 * square_m, 0.0])  # the board's middle
        t = np.array([rng.uniform(-0.12, 0.12), rng.uniform(-0.09, 0.09), rng.uniform(0.3, 0.5)]) - R @ centre_plane
        plane_to_image = lens.camera.K @ np.column_stack([R[:, 0], R[:, 1], t])
        H = plane_to_image @ texture_to_plane
        pinhole = cv2.warpPerspective(board, H, (640, 480), flags=cv2.INTER_AREA, borderValue=128)
        photo = lens.distort(np.asarray(cv2.cvtColor(pinhole, cv2.COLOR_GRAY2BGR), dtype=np.uint8))
        paths.append(out / f"board-{k:02d}.png")
        cv2.imwrite(str(paths[-1]), photo)
    return paths


@pytest.mark.integration
def test_the_calibration_script_recovers_a_lens_from_chessboard_photographs(tmp_path: Path) -> None:
    truth = LensDistortion(CAMERA, BARREL)
    photos = chessboard_photographs(truth, 20, tmp_path)
    out = tmp_path / "camera.yaml"
    done = run_python(
        "scripts/calibrate_camera.py", *map(str, photos), "--pattern", "9x6", "--square-m", "0.025", "--out", str(out)
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("# 20 views, RMS reprojection error")
    camera = yaml.safe_load(out.read_text())["perception"]["camera"]
    config = PerceptionConfig.model_validate({"camera": camera})  # pasted as it is
    recovered = SlzPipeline.from_config(config).lens
    assert recovered is not None
    # Where the recovered lens sends pixels agrees with the true lens across the frame (to a fraction of a pixel);
    # the intrinsics are those of the photographs' pinhole camera.
    x, y = np.meshgrid(np.linspace(-0.6, 0.6, 13), np.linspace(-0.45, 0.45, 11))  # rays within the boards' views
    rays = np.stack([x.ravel(), y.ravel(), np.ones(x.size)], axis=1)
    at_origin = (np.zeros(3), np.zeros(3))
    true_px, _ = cv2.projectPoints(rays, *at_origin, CAMERA.K, np.asarray(BARREL))
    got_px, _ = cv2.projectPoints(rays, *at_origin, recovered.camera.K, recovered.coefficients)
    assert np.abs(got_px - true_px).max() < 1.0
    assert camera["fx_px"] == pytest.approx(CAMERA.fx_px, rel=0.02)
