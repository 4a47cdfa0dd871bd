"""The SITL controller's loops written on Python floats compute what their vector form computed, to the bit.

Issue 34 rewrote ``CascadedController.update_position`` (numpy 3-vectors) and ``update_attitude`` (tuples built per
axis) as scalar code with the same operations in the same order, so that every mission decides exactly as before.
The vector form is kept here as the reference (the code of ``7d2d50e``), and both fly the same closed loop: takeoff
from the ground, steps, yaw changes, wind and a landing, every physics step compared bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl.autopilot.controller import CascadedController, Setpoint
from sitl.dynamics.base import F64Array, VehicleState
from sitl.dynamics.rigid_body import GRAVITY_MPS2, RigidBodyQuadrotor, quaternion_to_matrix

pytestmark = pytest.mark.unit


class VectorReference(CascadedController):
    """The loops as they were before the float rewrite (``7d2d50e``)."""

    def reset(self) -> None:
        """Clear integrators and memories (on arming, or when landed)."""
        self._v_integral = np.zeros(3)
        self._rate_integral: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._last_rate_error: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._v_thrust = np.array([0.0, 0.0, -self.airframe.hover_thrust])
        self._yaw_sp = math.nan
        self.collective = 0.0

    # -- outer loops ------------------------------------------------------------------------------------
    def update_position(self, state: VehicleState, setpoint: Setpoint, dt_s: float, integrate: bool = True) -> None:
        """Position and velocity loops: produce the thrust vector and yaw setpoint for the inner loops."""
        g, lim = self.gains, self.limits
        pos, vel = state.position_ned_m, state.velocity_ned_mps
        vel_sp = np.zeros(3)
        ff = np.nan_to_num(setpoint.velocity_ned_mps)
        for axis in range(3):
            p_sp = setpoint.position_ned_m[axis]
            if math.isnan(p_sp):
                vel_sp[axis] = ff[axis]
            else:
                gain = g.pos_p_z if axis == 2 else g.pos_p_xy
                vel_sp[axis] = gain * (p_sp - pos[axis]) + ff[axis]
        horizontal = math.hypot(vel_sp[0], vel_sp[1])
        if horizontal > lim.xy_vel_max_mps:
            vel_sp[:2] *= lim.xy_vel_max_mps / horizontal
        vel_sp[2] = min(max(vel_sp[2], -lim.z_vel_max_up_mps), lim.z_vel_max_down_mps)

        err = vel_sp - vel
        kp = np.array([g.vel_p_xy, g.vel_p_xy, g.vel_p_z])
        ki = np.array([g.vel_i_xy, g.vel_i_xy, g.vel_i_z])
        acc_sp = (
            kp * err + ki * self._v_integral - np.array([g.vel_d_xy, g.vel_d_xy, 0.0]) * state.acceleration_ned_mps2
        )
        # Thrust vector in normalized units: hover thrust counters gravity.
        thrust = (acc_sp - np.array([0.0, 0.0, GRAVITY_MPS2])) * (self.airframe.hover_thrust / GRAVITY_MPS2)
        thrust[2] = min(thrust[2], -lim.thrust_min)  # always some upward thrust in flight
        vertical = -thrust[2]
        if vertical > lim.thrust_max:
            thrust[2] = -lim.thrust_max
            vertical = lim.thrust_max
        max_horizontal = min(
            vertical * math.tan(math.radians(lim.tilt_max_deg)), math.sqrt(lim.thrust_max**2 - vertical**2)
        )
        h = math.hypot(thrust[0], thrust[1])
        saturated_xy = h > max_horizontal
        if saturated_xy:
            thrust[:2] *= max_horizontal / h
        if integrate:
            # Anti-windup: do not integrate an axis pushing further into saturation.
            grow = err.copy()
            if saturated_xy:
                grow[:2] = 0.0
            self._v_integral += grow * dt_s
            self._v_integral = np.clip(self._v_integral, -3.0, 3.0)
        self._v_thrust = thrust
        yaw = setpoint.yaw_rad
        if math.isnan(yaw):
            if math.isnan(self._yaw_sp):
                R = quaternion_to_matrix(state.quaternion_wxyz)
                self._yaw_sp = math.atan2(R[1, 0], R[0, 0])
        else:
            self._yaw_sp = yaw

    # -- inner loops ------------------------------------------------------------------------------------
    # Scalar arithmetic: they run at every physics step (400 Hz), where numpy's per-call overhead on 3-vectors and
    # 3x3 matrices was most of their cost (issue 34).
    def update_attitude(self, state: VehicleState, dt_s: float, integrate: bool = True) -> F64Array:
        """Attitude and rate loops plus the mixer; returns ESC commands (4,) in [0, 1]."""
        g, lim = self.gains, self.limits
        qw, qx, qy, qz = (float(v) for v in state.quaternion_wxyz)
        # R (body -> world) by columns: c0 = body x, c1 = body y, c2 = body z, in the world frame.
        c0 = (1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy + qw * qz), 2 * (qx * qz - qw * qy))
        c1 = (2 * (qx * qy - qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz + qw * qx))
        c2 = (2 * (qx * qz + qw * qy), 2 * (qy * qz - qw * qx), 1 - 2 * (qx * qx + qy * qy))
        tx, ty, tz = (float(v) for v in self._v_thrust)
        norm = math.sqrt(tx * tx + ty * ty + tz * tz)
        z_b = (-tx / norm, -ty / norm, -tz / norm) if norm > 1e-6 else (0.0, 0.0, 1.0)
        yaw = self._yaw_sp if not math.isnan(self._yaw_sp) else math.atan2(c0[1], c0[0])
        cy, sy = math.cos(yaw), math.sin(yaw)
        y_b = (-z_b[2] * sy, z_b[2] * cy, z_b[0] * sy - z_b[1] * cy)  # z_b x (cos yaw, sin yaw, 0)
        y_norm = math.sqrt(y_b[0] * y_b[0] + y_b[1] * y_b[1] + y_b[2] * y_b[2])
        y_b = (y_b[0] / y_norm, y_b[1] / y_norm, y_b[2] / y_norm) if y_norm > 1e-6 else c1
        x_b = _cross(y_b, z_b)
        # Geometric attitude error (Lee et al.) in the body frame: e_R = vee(R_sp^T R - R^T R_sp) / 2.
        e_x = 0.5 * (_dot(z_b, c1) - _dot(c2, y_b))
        e_y = 0.5 * (_dot(x_b, c2) - _dot(c0, z_b))
        e_z = 0.5 * (_dot(y_b, c0) - _dot(c1, x_b))
        rp_max, y_max = math.radians(lim.rate_max_roll_pitch_dps), math.radians(lim.rate_max_yaw_dps)
        (kx, ky, kz) = g.att_p
        rate_sp = (
            min(max(-kx * e_x, -rp_max), rp_max),
            min(max(-ky * e_y, -rp_max), rp_max),
            min(max(-kz * e_z, -y_max), y_max),
        )
        rates = state.rates_frd_radps
        err = tuple(rate_sp[i] - float(rates[i]) for i in range(3))
        last = self._last_rate_error
        d_err = tuple((err[i] - last[i]) / dt_s for i in range(3)) if dt_s > 0 else (0.0, 0.0, 0.0)
        self._last_rate_error = err
        integral = self._rate_integral
        torque = tuple(g.rate_p[i] * err[i] + g.rate_i[i] * integral[i] + g.rate_d[i] * d_err[i] for i in range(3))
        if integrate:
            self._rate_integral = tuple(min(max(integral[i] + err[i] * dt_s, -0.3), 0.3) for i in range(3))

        collective = max(0.0, -(tx * c2[0] + ty * c2[1] + tz * c2[2]))  # thrust along the current body axis
        self.collective = collective
        return self._mix(collective, torque)


def _dot(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def fly(controller: CascadedController, quad: RigidBodyQuadrotor) -> np.ndarray:
    """Motor commands, state and collective after every 400 Hz step of a fixed closed-loop flight."""
    dt_s = 1.0 / 400.0
    legs = [
        ((0.0, 0.0, -10.0), 0.0, 12.0),  # takeoff from the ground
        ((5.0, 0.0, -10.0), 0.7, 6.0),  # step north, yaw
        ((5.0, -3.0, -4.0), -2.0, 6.0),
        ((-2.0, 4.0, -12.0), math.nan, 5.0),  # heading held
        ((-2.0, 4.0, 0.5), math.nan, 12.0),  # down to the ground and pushing into it
    ]
    quad.set_wind(np.array([1.5, -0.7, 0.1]))
    rows = []
    k = 0
    for goal, yaw, duration_s in legs:
        setpoint = Setpoint.hold(np.array(goal), yaw)
        for _ in range(int(duration_s * 400)):
            state = quad.state()
            if k % 8 == 0:
                controller.update_position(state, setpoint, 8 * dt_s, integrate=not state.on_ground)
            motors = controller.update_attitude(state, dt_s)
            quad.set_motor_commands(motors)
            quad.step(dt_s)
            s = quad.state()
            rows.append(
                np.concatenate(
                    [
                        motors,
                        s.position_ned_m,
                        s.velocity_ned_mps,
                        s.quaternion_wxyz,
                        s.rates_frd_radps,
                        [float(s.on_ground), controller.collective],
                    ]
                )
            )
            k += 1
    return np.array(rows)


def test_the_float_loops_fly_the_vector_loops_flight_to_the_bit() -> None:
    quad_a, quad_b = RigidBodyQuadrotor(), RigidBodyQuadrotor()
    flown = fly(CascadedController(quad_a.airframe), quad_a)
    reference = fly(VectorReference(quad_b.airframe), quad_b)
    assert flown[:, -2].sum() > 1000  # the flight rests on the ground at both ends
    assert np.abs(flown[:, 4:7]).max() > 9.0  # and flies
    assert np.array_equal(flown, reference)  # every step, every bit
