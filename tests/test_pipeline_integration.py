"""The whole perception pipeline with the real onnxruntime model on rendered frames with ground truth."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from companion.geometry import Pose
from companion.perception.config import PerceptionConfig
from companion.perception.density import DensityMap, DensityModel, OnnxDensityModel, downscaled_size
from companion.perception.errors import PerceptionError
from companion.perception.pipeline import STAGES, FrameResult, SlzPipeline, camera_from_config
from sitl.render.flat_scene import FlatScene, RenderedFrame

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def scenes() -> list[FlatScene]:
    return [FlatScene(seed, n_people=180, roi_half_m=20.0) for seed in (11, 12, 13)]


class OracleDensity:
    """Perfect perception from the renderer's person mask: the fraction of each stride-4 cell covered by people.

    When the pipeline shrinks the frame (``scale`` < 1, set by the test from ``SlzPipeline.input_scale``), the mask
    is shrunk the same way into the top-left corner of the model's input, as a network would see it.
    """

    def __init__(self) -> None:
        self.mask: np.ndarray = np.zeros((480, 640), dtype=bool)
        self.scale = 1.0

    def predict(self, frame_bgr: np.ndarray) -> DensityMap:
        h, w = self.mask.shape
        coverage = self.mask.astype(np.float32)
        if self.scale < 1.0:
            small_w, small_h = downscaled_size(w, h, self.scale)
            coverage = np.zeros((h, w), np.float32)
            coverage[:small_h, :small_w] = cv2.resize(
                self.mask.astype(np.float32), (small_w, small_h), interpolation=cv2.INTER_AREA
            )
        cells = coverage.reshape(h // 4, 4, w // 4, 4).mean(axis=(1, 3)).astype(np.float32)
        return DensityMap(cells, frame_width_px=w, frame_height_px=h)


POSES = [  # (altitude_m, camera tilt_deg, roll_rad)
    (5.0, 0.0, 0.0),  # shrunk: the final descent
    (9.0, 10.0, 0.05),  # shrunk
    (12.0, 0.0, 0.0),
    (20.0, 0.0, 0.08),
    (25.0, 20.0, -0.05),
    (35.0, -15.0, 0.1),
]


def run_frames(
    scenes: list[FlatScene],
    config: PerceptionConfig,
    density: DensityModel,
    oracle: OracleDensity | None,
    altitude_m: float,
    tilt_deg: float,
    roll_rad: float,
) -> list[tuple[FlatScene, RenderedFrame, FrameResult]]:
    config = config.model_copy(update={"camera": config.camera.model_copy(update={"tilt_deg": tilt_deg})})
    pipeline = SlzPipeline.from_config(config, density_model=density)
    camera, T_body_camera = camera_from_config(config.camera)
    out = []
    for scene in scenes:
        pipeline.reset()
        pose = Pose.from_ned_euler(1.0, -2.0, -altitude_m, roll_rad, 0.02, 0.6)
        frame = scene.render(camera, T_body_camera, pose)
        if oracle is not None:
            oracle.mask = frame.person_mask
            oracle.scale = pipeline.input_scale(pose)
        result = pipeline.process(frame.image_bgr, pose, 0.0)
        assert set(result.timings_ms) == set(STAGES)
        out.append((scene, frame, result))
    return out


def assert_zones_free_of_people(runs: list[tuple[FlatScene, RenderedFrame, FrameResult]], min_radius_m: float) -> None:
    zones_seen = 0
    for scene, _, result in runs:
        for zone in result.zones:
            # Ground truth: no person's body reaches into a proposed zone.
            assert scene.clearance_m(zone.north_m, zone.east_m) >= zone.radius_m
            assert zone.radius_m >= min_radius_m
        zones_seen += len(result.zones)
    assert zones_seen >= len(runs)


@pytest.mark.parametrize(("altitude_m", "tilt_deg", "roll_rad"), POSES)
def test_with_perfect_perception_zones_never_contain_a_person(
    scenes: list[FlatScene], config: PerceptionConfig, altitude_m: float, tilt_deg: float, roll_rad: float
) -> None:
    """Geometry, projection, dilation and zones, isolated from the network's quality."""
    oracle = OracleDensity()
    runs = run_frames(scenes, config, oracle, oracle, altitude_m, tilt_deg, roll_rad)
    assert_zones_free_of_people(runs, config.zones.min_radius_m)
    shrunk = altitude_m < 15.0  # the default min_gsd_m_per_px (0.045) is the finest GSD at about 16 m
    for _, _, result in runs:
        assert (result.density.stride_x > 4.0) == shrunk


@pytest.mark.parametrize(("altitude_m", "tilt_deg", "roll_rad"), POSES[2:4])
def test_real_onnx_model_zones_contain_no_person(
    scenes: list[FlatScene],
    blob_model: OnnxDensityModel,
    config: PerceptionConfig,
    altitude_m: float,
    tilt_deg: float,
    roll_rad: float,
) -> None:
    """The placeholder blob network end to end on planar scenes, at the altitudes it is good for (it misses people
    far away). The trained model is tested on the 3-D world in test_density_model.py."""
    runs = run_frames(scenes, config, blob_model, None, altitude_m, tilt_deg, roll_rad)
    assert_zones_free_of_people(runs, config.zones.min_radius_m)
    for _, frame, result in runs:
        h, w = frame.person_mask.shape
        occupied = cv2.resize(result.occupancy.values, (w, h), interpolation=cv2.INTER_NEAREST) == 0
        assert occupied[frame.person_mask].mean() > 0.97  # pixel recall of the occupancy map


def test_tracks_follow_zones_over_a_descent(
    scenes: list[FlatScene], blob_model: OnnxDensityModel, config: PerceptionConfig
) -> None:
    pipeline = SlzPipeline.from_config(config, density_model=blob_model)
    camera, T_body_camera = camera_from_config(config.camera)
    scene = scenes[0]
    first_ids: set[int] = set()
    for k in range(20):
        pose = Pose.from_ned_euler(0.5 * math.sin(0.3 * k), 0.0, -(20.0 - 0.3 * k), 0.02 * math.sin(k), 0.0, 0.3)
        result = pipeline.process(scene.render(camera, T_body_camera, pose).image_bgr, pose, 0.1 * k)
        if k == 0:
            first_ids = {t.track_id for t in result.tracks}
    assert first_ids
    survivors = first_ids & {t.track_id for t in result.tracks}
    assert survivors, "no zone kept its identity over 2 s of a slow descent"
    target = result.target
    assert target is not None
    assert target.track_id in {t.track_id for t in result.tracks}
    assert scene.clearance_m(target.north_m, target.east_m) >= target.radius_m


def test_frame_of_the_wrong_size(blob_model: OnnxDensityModel, config: PerceptionConfig) -> None:
    pipeline = SlzPipeline.from_config(config, density_model=blob_model)
    with pytest.raises(PerceptionError, match="frame is 320x240, camera config says 640x480"):
        pipeline.process(np.zeros((240, 320, 3), np.uint8), Pose.from_ned_euler(0, 0, -10), 0.0)


def test_from_config_loads_the_model_named_in_the_config(config: PerceptionConfig) -> None:
    pipeline = SlzPipeline.from_config(config)
    assert isinstance(pipeline.density_model, OnnxDensityModel)
    assert pipeline.density_model.path == config.model.path
