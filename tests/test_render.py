"""The SITL camera: pyrender offscreen through EGL (Mesa llvmpipe here), real rendering, exact ground truth."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from companion.perception.config import ProjectionConfig
from companion.perception.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from companion.perception.projection import HeadPlaneProjector
from sitl.render.camera import Light, WorldRenderer
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import ScenarioConfig

pytestmark = pytest.mark.integration

CAMERA = PinholeCamera.from_hfov(320, 240, 90.0)
NADIR = T_body_camera_from_mount()
POSE = Pose.from_ned_euler(1.0, -2.0, -18.0, 0.04, -0.03, 0.6)


def renderer(seed: int, moving_fraction: float = 0.0) -> WorldRenderer:
    crowd = Crowd(ScenarioConfig(moving_fraction=moving_fraction), seed)
    return WorldRenderer(Park(seed), crowd, CAMERA, NADIR, Light.from_angles(50.0, 120.0, 0.45))


@pytest.fixture(scope="module")
def still_world() -> Iterator[WorldRenderer]:
    r = renderer(21)
    yield r
    r.close()


def test_same_seed_same_frame(still_world: WorldRenderer) -> None:
    again = renderer(21)
    try:
        a, b = still_world.render(POSE, 0.0), again.render(POSE, 0.0)
        np.testing.assert_array_equal(a.image_bgr, b.image_bgr)
        np.testing.assert_array_equal(a.person_mask, b.person_mask)
    finally:
        again.close()


def test_people_are_where_the_companions_geometry_says(still_world: WorldRenderer) -> None:
    view = still_world.render(POSE, 0.0)
    assert view.image_bgr.shape == (240, 320, 3)
    assert 0.005 < view.person_mask.mean() < 0.2
    crowd = still_world.crowd
    hits, checked = 0, 0
    for i, a in enumerate(crowd.appearances):
        # The torso's top, 0.75 of the height: project it with the companion's own head-plane projector.
        proj = HeadPlaneProjector(CAMERA, NADIR, ProjectionConfig(head_height_m=0.75 * a.height_m))
        pixel, ok = proj.plane_to_pixel(crowd.positions_ne_m[i : i + 1], POSE)
        u, v = (round(c) for c in pixel[0])
        if not ok[0] or not (3 <= u < 317 and 3 <= v < 237):
            continue
        checked += 1
        hits += bool(view.person_mask[v - 1 : v + 2, u - 1 : u + 2].any())
    assert checked > 30
    assert hits / checked > 0.9  # a few are hidden under tree crowns or umbrellas of others
    # Depth: the ground 18 m below a nearly level camera.
    ground = view.depth_m[~view.person_mask & (view.depth_m > 0)]
    assert np.median(ground) == pytest.approx(18.0, rel=0.05)


def test_walkers_move_between_frames_and_the_rest_stays() -> None:
    r = renderer(22, moving_fraction=0.2)
    try:
        first = r.render(POSE, 0.0)
        later = r.render(POSE, 3.0)
        changed = np.any(first.image_bgr != later.image_bgr, axis=2)
        assert 0.0005 < changed.mean() < 0.1  # some pixels changed: only around walkers
        assert not np.array_equal(first.person_mask, later.person_mask)
        lean = r.render(POSE, 3.0, with_mask=False, with_depth=False)
        assert lean.person_mask.sum() == 0
        assert lean.depth_m.max() == 0.0
        np.testing.assert_array_equal(lean.image_bgr, later.image_bgr)  # the lean read-back sees the same frame
    finally:
        r.close()
