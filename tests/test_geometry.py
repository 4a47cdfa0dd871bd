"""Rotations, poses and camera mounting: conventions checked against hand-worked answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.geometry import (
    GeometryError,
    PinholeCamera,
    Pose,
    R_world_body_from_euler,
    R_world_body_from_quaternion,
    T_body_camera_from_mount,
    invert_transform,
    make_transform,
    polygon_centroid_ne_m,
    quaternion_from_euler,
)

pytestmark = pytest.mark.unit


@pytest.mark.parametrize(("roll", "pitch", "yaw"), [(0.0, 0.0, 0.0), (0.3, -0.2, 2.5), (-0.7, 0.4, -1.2)])
def test_quaternion_and_euler_give_the_same_attitude(roll: float, pitch: float, yaw: float) -> None:
    R_euler = R_world_body_from_euler(roll, pitch, yaw)
    R_quat = R_world_body_from_quaternion(quaternion_from_euler(roll, pitch, yaw))
    np.testing.assert_allclose(R_euler, R_quat, atol=1e-12)
    np.testing.assert_allclose(R_euler @ R_euler.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R_euler) == pytest.approx(1.0)


def test_yaw_90_points_the_nose_east() -> None:
    nose_world = R_world_body_from_euler(0.0, 0.0, math.pi / 2) @ np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(nose_world, [0.0, 1.0, 0.0], atol=1e-12)


def test_positive_pitch_raises_the_nose() -> None:
    nose_world = R_world_body_from_euler(0.0, 0.2, 0.0) @ np.array([1.0, 0.0, 0.0])
    assert nose_world[2] < 0  # NED: up is negative down


def test_zero_quaternion_is_rejected() -> None:
    with pytest.raises(GeometryError, match=r"geometry\.quaternion"):
        R_world_body_from_quaternion([0.0, 0.0, 0.0, 0.0])


def test_transform_inverse() -> None:
    T = make_transform(R_world_body_from_euler(0.1, 0.2, 0.3), (1.0, -2.0, -30.0))
    np.testing.assert_allclose(T @ invert_transform(T), np.eye(4), atol=1e-12)


def test_nadir_mount_looks_down_with_image_top_forward() -> None:
    T = T_body_camera_from_mount()
    R = T[:3, :3]
    np.testing.assert_allclose(R @ [0, 0, 1], [0, 0, 1], atol=1e-12)  # optical axis = body down
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)  # image right = body right
    np.testing.assert_allclose(R @ [0, -1, 0], [1, 0, 0], atol=1e-12)  # image up = body forward


def test_tilt_turns_the_axis_towards_the_nose_and_roll_to_the_right() -> None:
    axis_tilted = T_body_camera_from_mount(tilt_deg=30.0)[:3, :3] @ [0, 0, 1]
    np.testing.assert_allclose(axis_tilted, [math.sin(math.radians(30)), 0, math.cos(math.radians(30))], atol=1e-12)
    axis_rolled = T_body_camera_from_mount(roll_deg=20.0)[:3, :3] @ [0, 0, 1]
    assert axis_rolled[1] > 0
    assert axis_rolled[2] > 0


def test_pose_accessors() -> None:
    pose = Pose.from_ned_euler(3.0, -4.0, -25.0, 0.1, 0.0, 0.0)
    np.testing.assert_allclose(pose.position_ned_m, [3.0, -4.0, -25.0])
    assert pose.altitude_m == pytest.approx(25.0)


def test_camera_from_hfov_and_scaling() -> None:
    cam = PinholeCamera.from_hfov(640, 480, 90.0)
    assert cam.fx_px == pytest.approx(320.0)
    quarter = cam.scaled(0.25, 0.25)
    assert (quarter.width_px, quarter.height_px) == (160, 120)
    assert quarter.fx_px == pytest.approx(80.0)
    # The centre of the image stays the centre: (319.5 + 0.5) / 4 - 0.5 = 79.5.
    assert quarter.cx_px == pytest.approx(79.5)


def test_the_centroid_of_a_polygon_is_its_centre_of_area_in_either_direction() -> None:
    square = [(-25.0, -25.0), (-25.0, 25.0), (25.0, 25.0), (25.0, -25.0)]  # mission_configs/sitl.yaml's geofence
    assert polygon_centroid_ne_m(square) == pytest.approx((0.0, 0.0))
    # An L: a 2 x 1 bar (area 2, centre (1, 0.5)) and a unit square (area 1, centre (0.5, 1.5)) -> (5/6, 5/6).
    ell = [(0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (1.0, 1.0), (1.0, 2.0), (0.0, 2.0)]
    assert polygon_centroid_ne_m(ell) == pytest.approx((5 / 6, 5 / 6))
    assert polygon_centroid_ne_m(ell[::-1]) == pytest.approx((5 / 6, 5 / 6))
    # Not the vertex mean: many vertices on one side do not pull it.
    dense = [(0.0, 0.0), (1.0, 0.0), (2.0, 0.0), (3.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)]
    assert polygon_centroid_ne_m(dense) == pytest.approx((2.0, 2.0))
    assert polygon_centroid_ne_m([(0.0, 0.0), (2.0, 2.0), (4.0, 4.0)]) == pytest.approx((2.0, 2.0))  # no area
