"""Head-plane projection: round trips, an independent pinhole model, unknown cells, GSD."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from companion.perception.config import ProjectionConfig
from companion.perception.errors import PerceptionError
from companion.perception.projection import FREE, OCCUPIED, HeadPlaneProjector

pytestmark = pytest.mark.unit

CAMERA = PinholeCamera(640, 480, 410.0, 405.0, 322.0, 236.5)
POSES = {
    "level": Pose.from_ned_euler(2.0, -3.0, -40.0),
    "rolled": Pose.from_ned_euler(5.0, 1.0, -40.0, roll_rad=math.radians(15), yaw_rad=math.radians(70)),
    "pitched_rolled": Pose.from_ned_euler(
        -7.0, 4.0, -40.0, roll_rad=math.radians(-10), pitch_rad=math.radians(12), yaw_rad=math.radians(-135)
    ),
}
MOUNTS = {
    "nadir": T_body_camera_from_mount(),
    "tilted": T_body_camera_from_mount(tilt_deg=25.0, yaw_deg=5.0, offset_frd_m=(0.1, 0.0, 0.05)),
    "tilted_rolled": T_body_camera_from_mount(tilt_deg=-15.0, roll_deg=10.0),
}


def projector(mount: str, head_height_m: float = 1.7) -> HeadPlaneProjector:
    return HeadPlaneProjector(CAMERA, MOUNTS[mount], ProjectionConfig(head_height_m=head_height_m))


@pytest.mark.parametrize("mount", MOUNTS)
@pytest.mark.parametrize("pose_name", POSES)
def test_round_trip_world_pixel_world_within_1cm_at_40m(mount: str, pose_name: str) -> None:
    proj = projector(mount)
    pose = POSES[pose_name]
    # Pixels spread over the whole image -> head plane -> pixels -> head plane.
    uv = np.array([(u, v) for u in np.linspace(0, 639, 9) for v in np.linspace(0, 479, 7)])
    world, hits = proj.pixel_to_plane(uv, pose)
    assert hits.all()
    pixels, in_front = proj.plane_to_pixel(world, pose)
    assert in_front.all()
    np.testing.assert_allclose(pixels, uv, atol=1e-6)
    world_again, _ = proj.pixel_to_plane(pixels, pose)
    assert np.max(np.hypot(*(world_again - world).T)) < 0.01


@pytest.mark.parametrize("mount", MOUNTS)
@pytest.mark.parametrize("pose_name", POSES)
def test_homography_matches_an_independent_pinhole_projection(mount: str, pose_name: str) -> None:
    proj = projector(mount)
    pose = POSES[pose_name]
    rng = np.random.default_rng(3)
    ne = pose.position_ned_m[:2] + rng.uniform(-8, 8, size=(50, 2))
    # Independent model: p_camera = R_cw (p_world - c), pixel = K p_camera / z.
    T_wc = pose.T_world_body @ MOUNTS[mount]
    p_world = np.column_stack([ne, np.full(len(ne), -1.7)])
    p_cam = (p_world - T_wc[:3, 3]) @ T_wc[:3, :3]
    expected = (p_cam @ CAMERA.K.T)[:, :2] / p_cam[:, 2:3]
    pixels, in_front = proj.plane_to_pixel(ne, pose)
    visible = p_cam[:, 2] > 0.5
    assert visible.any()
    np.testing.assert_array_equal(in_front, visible)
    np.testing.assert_allclose(pixels[visible], expected[visible], atol=1e-6)


def test_nadir_conventions_north_is_up_east_is_right() -> None:
    proj = projector("nadir")
    pose = Pose.from_ned_euler(0.0, 0.0, -20.0)
    pixels, _ = proj.plane_to_pixel([[5.0, 0.0], [0.0, 5.0]], pose)
    north, east = pixels
    assert north[1] < CAMERA.cy_px
    assert abs(north[0] - CAMERA.cx_px) < 1e-6
    assert east[0] > CAMERA.cx_px
    assert abs(east[1] - CAMERA.cy_px) < 1e-6
    # 5 m at a depth of 20 - 1.7 = 18.3 m spans fx * 5 / 18.3 pixels.
    assert east[0] - CAMERA.cx_px == pytest.approx(410.0 * 5.0 / 18.3)


def test_points_behind_the_camera_are_flagged() -> None:
    proj = projector("tilted")
    pose = Pose.from_ned_euler(0.0, 0.0, -10.0)
    _, in_front = proj.plane_to_pixel([[-200.0, 0.0]], pose)  # far behind a forward-tilted camera
    assert not in_front[0]
    _, hits = proj.pixel_to_plane([[320.0, 0.0]], Pose.from_ned_euler(0, 0, -10, pitch_rad=math.radians(80)))
    assert not hits[0]  # ray above the horizon never meets the plane


def test_projected_grid_marks_outside_the_image_unknown_and_not_free() -> None:
    proj = projector("nadir")
    pose = Pose.from_ned_euler(0.0, 0.0, -10.0)  # footprint ~ 16 m x 12 m, grid 40 m: most cells unseen
    cam = CAMERA.scaled(0.25, 0.25)
    all_free = np.full((cam.height_px, cam.width_px), FREE, dtype=np.uint8)
    hp = proj.project(all_free, cam, pose)
    assert hp.known.any()
    assert not hp.known.all()
    assert not (hp.free & ~hp.known).any()
    # Inside the footprint, well away from its border, everything is free.
    row, col = (round(v) for v in hp.grid.world_to_cell(0.0, 0.0))
    assert hp.free[row - 20 : row + 20, col - 20 : col + 20].all()
    # The known area matches the footprint: (10 - 1.7) m depth * 640 px / 410 px wide, 480/405 tall.
    expected_area_m2 = (8.3 * 640 / 410.0) * (8.3 * 480 / 405.0)
    assert hp.known.sum() * 0.01 == pytest.approx(expected_area_m2, rel=0.03)


def test_projected_obstacle_lands_at_its_world_position() -> None:
    proj = projector("tilted_rolled")
    pose = POSES["rolled"]
    cam = CAMERA.scaled(0.25, 0.25)
    occupancy = np.full((cam.height_px, cam.width_px), FREE, dtype=np.uint8)
    target_ne = pose.position_ned_m[:2] + np.array([3.0, -2.0])
    pixel, ok = HeadPlaneProjector(cam, MOUNTS["tilted_rolled"], ProjectionConfig()).plane_to_pixel([target_ne], pose)
    assert ok[0]
    u, v = (round(c) for c in pixel[0])
    occupancy[v - 1 : v + 2, u - 1 : u + 2] = OCCUPIED
    hp = proj.project(occupancy, cam, pose)
    # Cells at the footprint's edge sample the image border and are rightly not free: compare with the
    # projection of an all-free image to see only what the blob did.
    baseline = proj.project(np.full_like(occupancy, FREE), cam, pose)
    occupied_cells = np.argwhere(baseline.free & ~hp.free)
    row, col = hp.grid.world_to_cell(*target_ne)
    distances_m = np.hypot(occupied_cells[:, 0] - row, occupied_cells[:, 1] - col) * hp.grid.resolution_m
    # The 3x3-cell blob covers 12x12 frame pixels, under 2 m on the plane here: all of it around the target.
    assert len(occupied_cells) > 0
    assert distances_m.min() < 0.3
    assert distances_m.max() < 2.0


def test_finest_gsd() -> None:
    proj = projector("nadir")
    gsd = proj.finest_gsd_m_per_px(Pose.from_ned_euler(0.0, 0.0, -30.0))
    assert gsd == pytest.approx((30.0 - 1.7) / 410.0)
    tilted = projector("tilted").finest_gsd_m_per_px(Pose.from_ned_euler(0.0, 0.0, -30.0))
    assert tilted < gsd  # the near edge of a tilted view is closer than the nadir depth


def test_gsd_fails_when_the_plane_is_not_visible() -> None:
    with pytest.raises(PerceptionError, match=r"projection\.gsd"):
        projector("nadir").finest_gsd_m_per_px(Pose.from_ned_euler(0.0, 0.0, -1.0))  # below the head plane


def test_grid_is_snapped_and_centred_on_the_view() -> None:
    proj = projector("nadir")
    grid = proj.grid_for(Pose.from_ned_euler(3.14, -2.72, -20.0))
    assert grid.rows == grid.cols == 400
    assert grid.north_min_m / 0.1 == pytest.approx(round(grid.north_min_m / 0.1))
    centre = grid.cell_to_world((grid.rows - 1) / 2, (grid.cols - 1) / 2)
    assert np.hypot(centre[0] - 3.14, centre[1] + 2.72) < 0.1
