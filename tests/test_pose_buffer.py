"""Pose buffer: a frame is paired with the pose at its capture time, interpolated; never with a stale one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.geometry import R_world_body_from_euler
from companion.vehicle.pose_buffer import PoseBuffer, PoseBufferError, slerp

pytestmark = pytest.mark.unit


def _q_yaw(yaw_rad: float) -> np.ndarray:
    return np.array([math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2)])


def test_position_and_attitude_are_interpolated_at_the_capture_time() -> None:
    buffer = PoseBuffer()
    for k in range(11):  # 50 Hz, moving north at 2 m/s, yawing at 0.5 rad/s
        t = 10.0 + 0.02 * k
        buffer.add_position(t, 2.0 * (t - 10.0), 1.0, -20.0)
        buffer.add_attitude(t + 0.005, _q_yaw(0.5 * (t + 0.005 - 10.0)))
    pose = buffer.pose_at(10.113)
    assert pose is not None
    assert pose.position_ned_m == pytest.approx([0.226, 1.0, -20.0], abs=1e-9)
    expected = R_world_body_from_euler(0.0, 0.0, 0.5 * 0.113)
    assert np.abs(pose.T_world_body[:3, :3] - expected).max() < 1e-6  # a microradian


def test_no_pose_outside_the_buffer_or_across_a_dropout() -> None:
    buffer = PoseBuffer(max_gap_s=0.1)
    for t in (1.0, 1.02, 1.04, 1.5, 1.52):  # 1.04 -> 1.5 is a telemetry dropout
        buffer.add_position(t, 0.0, 0.0, -10.0)
        buffer.add_attitude(t, [1.0, 0.0, 0.0, 0.0])
    assert buffer.pose_at(0.99) is None  # before the first sample
    assert buffer.pose_at(1.53) is None  # after the last one: never extrapolated
    assert buffer.pose_at(1.2) is None  # inside the dropout
    assert buffer.pose_at(1.03) is not None
    assert buffer.pose_at(1.5) is not None
    assert buffer.latest_t_s == pytest.approx(1.52)


def test_slerp_takes_the_short_way_and_stays_unit() -> None:
    q0, q1 = _q_yaw(0.1), -_q_yaw(0.3)  # -q is the same rotation
    mid = slerp(q0, q1, 0.5)
    assert float(np.linalg.norm(mid)) == pytest.approx(1.0)
    assert abs(float(np.dot(mid, _q_yaw(0.2)))) == pytest.approx(1.0, abs=1e-12)


def test_bad_telemetry_is_refused_with_its_value() -> None:
    buffer = PoseBuffer()
    buffer.add_position(2.0, 0.0, 0.0, 0.0)
    with pytest.raises(PoseBufferError, match="backwards"):
        buffer.add_position(1.0, 0.0, 0.0, 0.0)
    with pytest.raises(PoseBufferError, match="non-finite"):
        buffer.add_position(3.0, math.nan, 0.0, 0.0)
    with pytest.raises(PoseBufferError, match="invalid attitude"):
        buffer.add_attitude(3.0, [0.0, 0.0, 0.0, 0.0])
    buffer.add_position(2.0, 5.0, 0.0, 0.0)  # the same instant again replaces the sample
    buffer.add_attitude(2.0, [1.0, 0.0, 0.0, 0.0])
    pose = buffer.pose_at(2.0)
    assert pose is not None
    assert pose.position_ned_m[0] == 5.0


def test_the_vehicle_clock_takes_the_least_delayed_stamp_and_follows_a_reboot() -> None:
    from companion.vehicle.clock import VehicleClock

    clock = VehicleClock(window=10)
    assert not clock.synced
    with pytest.raises(RuntimeError, match="not synchronised"):
        clock.now_s(0.0)
    # True offset: vehicle = wall + 100. Messages arrive 2-20 ms after their stamp.
    for k, delay in enumerate([0.02, 0.005, 0.012, 0.002, 0.015]):
        stamp = 100.0 + 0.02 * k
        clock.observe(stamp, wall_s=stamp - 100.0 + delay)
    assert clock.now_s(1.0) == pytest.approx(101.0, abs=0.0025)
    clock.observe(0.5, wall_s=10.0)  # rebooted autopilot: clock back to 0.5 s
    assert clock.now_s(11.0) == pytest.approx(1.5)


def test_the_delay_spread_ignores_one_held_up_stamp_but_not_an_uneven_link() -> None:
    from companion.vehicle.clock import VehicleClock

    clock = VehicleClock(window=100)
    assert clock.delay_spread_s() is None
    # 100 stamps 2-12 ms late, one of them held up 130 ms (a loaded machine's scheduling hiccup).
    for k in range(100):
        delay = 0.13 if k == 50 else 0.002 + 0.01 * (k % 5) / 4
        clock.observe(100.0 + 0.02 * k, wall_s=0.02 * k + delay)
    assert clock.offset_spread_s == pytest.approx(0.128)
    assert clock.delay_spread_s(0.95) == pytest.approx(0.01)
    assert clock.delay_spread_s(1.0) == pytest.approx(clock.offset_spread_s)
    # A link that holds up one stamp in ten by 130 ms: 95 % of them no longer arrive within 100 ms of the fastest.
    for k in range(100, 200):
        delay = 0.13 if k % 10 == 0 else 0.002
        clock.observe(100.0 + 0.02 * k, wall_s=0.02 * k + delay)
    spread = clock.delay_spread_s(0.95)
    assert spread == pytest.approx(0.128)
    with pytest.raises(ValueError, match="fraction"):
        clock.delay_spread_s(0.0)
