"""Height above the ground from the camera's motion (issue 64): rendered scenes flown past as the companion flies, the
renderer's depth as the truth."""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np
import pytest
from pydantic import ValidationError

from bench.motion_height import true_heights
from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from companion.perception.config import MotionHeightConfig, PerceptionConfig
from companion.perception.density import DensityMap
from companion.perception.errors import PerceptionError
from companion.perception.motion_height import (
    CELL_PX,
    HeightMap,
    HeightState,
    MotionHeight,
    sweep_heights_m,
    unknown_map,
)
from companion.perception.occupancy import OccupancyMapper
from companion.perception.pipeline import SlzPipeline
from sitl.render.camera import Light, RenderedView, WorldRenderer
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import ScenarioConfig

CAMERA = PinholeCamera.from_hfov(640, 480, 90.0)
T_BODY_CAMERA = T_body_camera_from_mount()
ALTITUDE_M = 20.0


@pytest.fixture(scope="module")
def renderer() -> Iterator[WorldRenderer]:
    scenario = ScenarioConfig(people_min=60, people_max=60, moving_fraction=0.0)
    r = WorldRenderer(Park(3), Crowd(scenario, 3), CAMERA, T_BODY_CAMERA, Light.from_angles(45.0, 80.0, 0.5))
    yield r
    r.close()


def _pose(north_m: float, roll_rad: float = 0.01) -> Pose:
    return Pose.from_ned_euler(north_m, 1.0, -ALTITUDE_M, roll_rad, -0.02, 0.4)


@pytest.fixture(scope="module")
def pair(renderer: WorldRenderer) -> tuple[RenderedView, RenderedView]:
    """Two frames 2 m apart along the search's straight flight, 1 s apart (static people)."""
    return renderer.render(_pose(-1.0), 0.0), renderer.render(_pose(1.0), 1.0)


def _cells(mask: np.ndarray) -> np.ndarray:
    h, w = mask.shape
    return np.asarray(mask.reshape(h // CELL_PX, CELL_PX, w // CELL_PX, CELL_PX).any(axis=(1, 3)))


def _truth(view: RenderedView, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """Cells with anything taller than 0.2 m within 1 m, and the cells of people."""
    heights = np.nan_to_num(true_heights(view.depth_m, pose, CAMERA, T_BODY_CAMERA), nan=0.0)
    standing = _cells(heights > 0.2).astype(np.uint8)
    near = cv2.dilate(standing, np.ones((7, 7), np.uint8)) > 0  # 3 cells: about 1 m at 20 m
    return near, _cells(view.person_mask)


def _people_flagged(renderer: WorldRenderer, pose: Pose, flagged: np.ndarray) -> float:
    heads, front = renderer.head_pixels(pose)
    hits = []
    for i, ((u, v), ok) in enumerate(zip(heads, front, strict=True)):
        if not ok or renderer.head_height_m(i) < 1.4 or not (8 <= u < 632 and 8 <= v < 472):
            continue
        r, c = int(v // CELL_PX), int(u // CELL_PX)
        hits.append(bool(flagged[r - 2 : r + 3, c - 2 : c + 3].any()))
    assert len(hits) > 20
    return sum(hits) / len(hits)


def _measure(pair: tuple[RenderedView, RenderedView], second: Pose) -> HeightMap:
    estimator = MotionHeight(CAMERA, T_BODY_CAMERA, MotionHeightConfig(enabled=True))
    estimator.update(pair[0].image_bgr, _pose(-1.0), 0.0)
    return estimator.update(pair[1].image_bgr, second, 1.0)


@pytest.mark.integration
def test_standing_people_stand_above_the_ground_and_open_ground_does_not(
    renderer: WorldRenderer, pair: tuple[RenderedView, RenderedView]
) -> None:
    height = _measure(pair, _pose(1.0))
    assert height.reason == ""
    assert height.baseline_m == pytest.approx(2.0)
    assert height.parallax_px_per_m > 1.5  # 320 px focal length, 2 m across the view from 20 m
    near, _ = _truth(pair[1], _pose(1.0))
    open_ground = ~near
    assert float(height.not_ground[open_ground].mean()) < 0.02
    assert _people_flagged(renderer, _pose(1.0), height.not_ground) >= 0.8
    raised = height.state == HeightState.RAISED
    assert np.all(height.height_m[raised] >= MotionHeightConfig().raised_m)


@pytest.mark.integration
def test_an_attitude_error_of_the_poses_is_taken_out_on_the_ground(
    renderer: WorldRenderer, pair: tuple[RenderedView, RenderedView]
) -> None:
    wrong = _pose(1.0, roll_rad=0.01 + np.radians(0.4))  # the pose says 0.4 degrees more roll than the camera had
    height = _measure(pair, wrong)
    near, _ = _truth(pair[1], _pose(1.0))
    assert float(height.not_ground[~near].mean()) < 0.03
    assert _people_flagged(renderer, _pose(1.0), height.not_ground) >= 0.7


@pytest.mark.integration
def test_without_a_baseline_the_map_is_unknown_not_flat(pair: tuple[RenderedView, RenderedView]) -> None:
    estimator = MotionHeight(CAMERA, T_BODY_CAMERA, MotionHeightConfig(enabled=True))
    first = estimator.update(pair[0].image_bgr, _pose(-1.0), 0.0)
    assert first.reason == "no earlier frame"
    hovering = estimator.update(pair[0].image_bgr, _pose(-1.0), 0.5)  # hovering: the same place
    assert hovering.reason.startswith("no usable baseline")
    assert (hovering.state == HeightState.UNKNOWN).all()
    assert not hovering.not_ground.any()
    with pytest.raises(PerceptionError, match="out of order"):
        estimator.update(pair[0].image_bgr, _pose(-1.0), 0.2)
    estimator.reset()
    assert estimator.update(pair[0].image_bgr, _pose(-1.0), 0.0).reason == "no earlier frame"


@pytest.mark.integration
def test_the_earlier_frame_is_the_newest_with_enough_baseline(renderer: WorldRenderer) -> None:
    config = MotionHeightConfig(enabled=True, target_parallax_px_per_m=1.5)
    estimator = MotionHeight(CAMERA, T_BODY_CAMERA, config)
    frame = np.zeros((480, 640, 3), np.uint8)
    for k in range(21):  # 2 m/s for 2 s at 10 Hz
        height = estimator.update(frame, _pose(0.2 * k), 0.1 * k)
    assert height.parallax_px_per_m >= 1.5
    assert height.dt_s < 2.0  # not the oldest: the newest that reaches the target
    assert height.baseline_m == pytest.approx(0.2 * round(height.dt_s / 0.1))


@pytest.mark.integration
def test_fused_the_cells_standing_above_the_ground_are_occupied_whatever_the_density_says(
    pair: tuple[RenderedView, RenderedView],
) -> None:
    class Empty:
        """A density model that sees nobody."""

        def predict(self, frame_bgr: np.ndarray) -> DensityMap:
            return DensityMap(np.zeros((120, 160), np.float32), 640, 480)

    config = PerceptionConfig.model_validate({"motion_height": {"enabled": True, "fuse": True}})
    pipeline = SlzPipeline.from_config(config, density_model=Empty())
    pipeline.process(pair[0].image_bgr, _pose(-1.0), 0.0)
    fused = pipeline.process(pair[1].image_bgr, _pose(1.0), 1.0)
    assert fused.height is not None
    assert "height" in fused.timings_ms
    _, people = _truth(pair[1], _pose(1.0))
    occupied = fused.occupancy.values == 0
    assert float(occupied[people].mean()) > 0.5  # the network saw nobody; geometry did
    plain = SlzPipeline.from_config(PerceptionConfig(), density_model=Empty())
    plain.process(pair[0].image_bgr, _pose(-1.0), 0.0)
    alone = plain.process(pair[1].image_bgr, _pose(1.0), 1.0)
    assert alone.height is None
    assert not (alone.occupancy.values == 0).any()


@pytest.mark.unit
def test_a_coarser_density_grid_keeps_every_cell_that_stands() -> None:
    state = np.full((120, 160), HeightState.GROUND, np.uint8)
    state[50, 70] = HeightState.RAISED
    state[10, 10] = HeightState.MOVING
    nan = np.full((120, 160), np.nan, np.float32)
    height = HeightMap(nan, nan, state, CELL_PX, 2.0, 2.0, 1.0)
    coarse = height.resampled((48, 64))  # a frame shrunk to 0.4 for the network
    assert coarse.sum() == 2
    assert coarse[20, 28]
    assert coarse[4, 4]
    assert height.resampled((120, 160)).sum() == 2
    mapper = OccupancyMapper(PerceptionConfig().occupancy)
    density = DensityMap(np.zeros((48, 64), np.float32), 640, 480)
    occupied = mapper.compute(density, 0.06, also_occupied=coarse).values == 0
    assert occupied[20, 28]
    assert occupied.sum() > 2  # dilated like a person the network saw
    with pytest.raises(PerceptionError, match="also_occupied"):
        mapper.compute(density, 0.06, also_occupied=height.not_ground)


@pytest.mark.unit
def test_the_swept_planes_shift_by_the_pixels_asked_and_stay_below_the_camera() -> None:
    config = MotionHeightConfig()
    heights = sweep_heights_m(2.0, 20.0, config)
    assert heights[0] == 0.0
    assert np.all(np.diff(heights) > 0)
    assert heights[-1] <= 18.0
    h1 = heights[1]  # 1 px at 2 px per metre: about 0.5 m
    assert 2.0 * h1 * 20.0 / (20.0 - h1) == pytest.approx(config.sweep_shifts_px[0])
    assert unknown_map((120, 160), "why").share(HeightState.UNKNOWN) == 1.0


@pytest.mark.unit
def test_a_bad_motion_height_config_names_the_field() -> None:
    with pytest.raises(ValidationError, match="min_parallax_px_per_m"):
        MotionHeightConfig(min_parallax_px_per_m=3.0, target_parallax_px_per_m=2.0)
    with pytest.raises(ValidationError, match="fuse needs"):
        MotionHeightConfig(fuse=True)
    with pytest.raises(ValidationError, match="sweep_shifts_px"):
        MotionHeightConfig(sweep_shifts_px=[3.0, 1.0])
    with pytest.raises(ValidationError, match="raised_m"):
        MotionHeightConfig(raised_m=0.0)
