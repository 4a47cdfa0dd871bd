"""The planar scene renderer: seeded, with ground truth that matches what it draws."""

from __future__ import annotations

import numpy as np
import pytest

from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from companion.perception.config import ProjectionConfig
from companion.perception.projection import HeadPlaneProjector
from sitl.render.flat_scene import FlatScene, SceneError

pytestmark = pytest.mark.integration

CAMERA = PinholeCamera.from_hfov(640, 480, 90.0)
NADIR = T_body_camera_from_mount()


def test_same_seed_same_scene_and_frames() -> None:
    pose = Pose.from_ned_euler(1.0, 2.0, -18.0, 0.05, -0.02, 0.7)
    a, b = FlatScene(5, n_people=50), FlatScene(5, n_people=50)
    np.testing.assert_array_equal(a.positions_ne_m, b.positions_ne_m)
    np.testing.assert_array_equal(a.render(CAMERA, NADIR, pose).image_bgr, b.render(CAMERA, NADIR, pose).image_bgr)
    c = FlatScene(6, n_people=50)
    assert not np.array_equal(a.positions_ne_m, c.positions_ne_m)


def test_people_do_not_overlap_and_stay_in_the_roi() -> None:
    scene = FlatScene(3, n_people=120, roi_half_m=15.0)
    pos, r = scene.positions_ne_m, scene.radii_m
    assert len(pos) == 120
    assert np.all(np.abs(pos) + r[:, None] <= 15.0)
    d = np.hypot(pos[:, None, 0] - pos[None, :, 0], pos[:, None, 1] - pos[None, :, 1])
    np.fill_diagonal(d, np.inf)
    assert np.all(d >= r[:, None] + r[None, :])


def test_person_mask_is_where_the_people_project() -> None:
    scene = FlatScene(2, n_people=80)
    pose = Pose.from_ned_euler(0.0, 0.0, -15.0, 0.1, 0.05, -0.4)
    frame = scene.render(CAMERA, NADIR, pose)
    pixels, ok = HeadPlaneProjector(CAMERA, NADIR, ProjectionConfig(head_height_m=1.7)).plane_to_pixel(
        scene.positions_ne_m, pose
    )
    inside = ok & (pixels[:, 0] >= 0) & (pixels[:, 0] < 639) & (pixels[:, 1] >= 0) & (pixels[:, 1] < 479)
    assert inside.sum() > 20
    uv = np.round(pixels[inside]).astype(int)
    assert frame.person_mask[uv[:, 1], uv[:, 0]].all()
    # Each body disc (0.2-0.3 m at a depth of 13.3 m, f = 320 px) covers its projected area in the mask.
    vv, uu = np.mgrid[0:480, 0:640]
    checked = 0
    for (u, v), radius_m in zip(pixels[inside], scene.radii_m[inside], strict=True):
        r_px = radius_m * CAMERA.fx_px / 13.3
        if not (r_px + 2 < u < 638 - r_px and r_px + 2 < v < 478 - r_px):
            continue
        disc = np.hypot(uu - u, vv - v) <= r_px - 1.0
        assert frame.person_mask[disc].all()
        ring = (np.hypot(uu - u, vv - v) > r_px + 1.5) & (np.hypot(uu - u, vv - v) < r_px + 2.5)
        checked += 1
        # Just outside the body: mostly ground (another person may stand close by).
        assert frame.person_mask[ring].mean() < 0.5
    assert checked > 20


def test_clearance() -> None:
    scene = FlatScene(1, n_people=10)
    p = scene.people[0]
    assert scene.clearance_m(p.north_m, p.east_m) == pytest.approx(-p.radius_m)


def test_impossible_scenes_are_rejected() -> None:
    with pytest.raises(SceneError, match="cannot place 500 people"):
        FlatScene(0, n_people=500, roi_half_m=3.0)
    with pytest.raises(SceneError, match="n_people=-1"):
        FlatScene(0, n_people=-1)
