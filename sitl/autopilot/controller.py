"""A PX4-like cascaded multicopter controller: position -> velocity -> attitude -> rates -> mixer.

Works in normalized units as PX4 does: collective thrust in [0, 1] of the maximum (hover at ``hover_thrust``),
torques as normalized rotor-thrust differences. The mixer de-prioritizes yaw: roll and pitch are allocated first,
yaw gets what is left before any rotor saturates. Default gains are PX4's for an F450-class quadrotor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sitl.dynamics.base import Airframe, F64Array, VehicleState
from sitl.dynamics.rigid_body import GRAVITY_MPS2, quaternion_to_matrix


@dataclass(frozen=True)
class ControllerLimits:
    """Speed, tilt and thrust limits (PX4: MPC_XY_VEL_MAX, MPC_Z_VEL_MAX_UP/DN, MPC_TILTMAX_AIR, ...)."""

    xy_vel_max_mps: float = 5.0
    z_vel_max_up_mps: float = 3.0
    z_vel_max_down_mps: float = 1.5
    tilt_max_deg: float = 35.0
    thrust_min: float = 0.08
    thrust_max: float = 0.95
    rate_max_roll_pitch_dps: float = 220.0
    rate_max_yaw_dps: float = 150.0


@dataclass(frozen=True)
class ControllerGains:
    """Loop gains (PX4 defaults, MPC_* and MC_* parameters)."""

    pos_p_xy: float = 0.95
    pos_p_z: float = 1.0
    vel_p_xy: float = 1.8
    vel_i_xy: float = 0.4
    vel_d_xy: float = 0.2
    vel_p_z: float = 4.0
    vel_i_z: float = 2.0
    att_p: tuple[float, float, float] = (6.5, 6.5, 2.8)
    rate_p: tuple[float, float, float] = (0.15, 0.15, 0.2)
    rate_i: tuple[float, float, float] = (0.2, 0.2, 0.1)
    rate_d: tuple[float, float, float] = (0.003, 0.003, 0.0)


@dataclass
class Setpoint:
    """What the position controller follows; NaN fields are not controlled (PX4 trajectory setpoint).

    ``velocity_ned_mps`` is a feed-forward when a position is given, the target otherwise. ``yaw_rad`` NaN holds
    the current heading.
    """

    position_ned_m: F64Array
    velocity_ned_mps: F64Array
    yaw_rad: float = math.nan

    @classmethod
    def hold(cls, position_ned_m: F64Array, yaw_rad: float) -> Setpoint:
        """Hold a position and heading."""
        return cls(np.asarray(position_ned_m, dtype=np.float64).copy(), np.full(3, math.nan), yaw_rad)


class CascadedController:
    """Position/velocity loops at the outer rate, attitude/rate loops and mixer at every step."""

    def __init__(
        self,
        airframe: Airframe,
        limits: ControllerLimits | None = None,
        gains: ControllerGains | None = None,
    ) -> None:
        self.airframe = airframe
        self.limits = limits or ControllerLimits()
        self.gains = gains or ControllerGains()
        pos = np.array(airframe.rotor_positions_frd_m)
        extent = float(np.max(np.abs(pos)))
        # Normalized rotor thrust t_i = c + roll_i * tau_r + pitch_i * tau_p + yaw_i * tau_y.
        self._roll = tuple(float(v) for v in -pos[:, 1] / extent)
        self._pitch = tuple(float(v) for v in pos[:, 0] / extent)
        self._yaw = tuple(float(v) for v in airframe.rotor_yaw_sign)
        self.reset()

    def reset(self) -> None:
        """Clear integrators and memories (on arming, or when landed)."""
        self._vel_integral: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._rate_integral: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._last_rate_error: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._thrust_vector: tuple[float, ...] = (0.0, 0.0, -self.airframe.hover_thrust)
        self._yaw_sp = math.nan
        self.collective = 0.0

    # -- outer loops ------------------------------------------------------------------------------------
    def update_position(self, state: VehicleState, setpoint: Setpoint, dt_s: float, integrate: bool = True) -> None:
        """Position and velocity loops: produce the thrust vector and yaw setpoint for the inner loops.

        On Python floats, axis by axis: the same operations in the same order as the numpy form (elementwise IEEE
        arithmetic either way), so the same bits at a third of its cost (issue 34).
        """
        g, lim = self.gains, self.limits
        pos = state.position_ned_m.tolist()
        vel = state.velocity_ned_mps.tolist()
        acc = state.acceleration_ned_mps2.tolist()
        ff = np.nan_to_num(setpoint.velocity_ned_mps).tolist()
        vel_sp = [0.0, 0.0, 0.0]
        for axis, p_sp in enumerate(setpoint.position_ned_m.tolist()):
            if math.isnan(p_sp):
                vel_sp[axis] = ff[axis]
            else:
                gain = g.pos_p_z if axis == 2 else g.pos_p_xy
                vel_sp[axis] = gain * (p_sp - pos[axis]) + ff[axis]
        horizontal = math.hypot(vel_sp[0], vel_sp[1])
        if horizontal > lim.xy_vel_max_mps:
            factor = lim.xy_vel_max_mps / horizontal
            vel_sp[0], vel_sp[1] = vel_sp[0] * factor, vel_sp[1] * factor
        vel_sp[2] = min(max(vel_sp[2], -lim.z_vel_max_up_mps), lim.z_vel_max_down_mps)

        err = [vel_sp[0] - vel[0], vel_sp[1] - vel[1], vel_sp[2] - vel[2]]
        kp = (g.vel_p_xy, g.vel_p_xy, g.vel_p_z)
        ki = (g.vel_i_xy, g.vel_i_xy, g.vel_i_z)
        kd = (g.vel_d_xy, g.vel_d_xy, 0.0)
        integral = self._vel_integral
        # Thrust vector in normalized units: hover thrust counters gravity.
        to_thrust = self.airframe.hover_thrust / GRAVITY_MPS2
        gravity = (0.0, 0.0, GRAVITY_MPS2)
        thrust = [((kp[i] * err[i] + ki[i] * integral[i] - kd[i] * acc[i]) - gravity[i]) * to_thrust for i in range(3)]
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
            factor = max_horizontal / h
            thrust[0], thrust[1] = thrust[0] * factor, thrust[1] * factor
        if integrate:
            # Anti-windup: do not integrate an axis pushing further into saturation.
            grow = [0.0, 0.0, err[2]] if saturated_xy else err
            self._vel_integral = tuple(min(max(integral[i] + grow[i] * dt_s, -3.0), 3.0) for i in range(3))
        self._thrust_vector = (thrust[0], thrust[1], thrust[2])
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
        """Attitude and rate loops plus the mixer; returns ESC commands (4,) in [0, 1].

        Written out axis by axis on Python floats (no tuples built per axis, no numpy scalars): the same operations in
        the same order as the loop form, so the same bits, at less than half its cost (issue 34).
        """
        g, lim = self.gains, self.limits
        qw, qx, qy, qz = state.quaternion_wxyz.tolist()
        # R (body -> world) by columns: c0 = body x, c1 = body y, c2 = body z, in the world frame.
        c00, c01, c02 = 1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy + qw * qz), 2 * (qx * qz - qw * qy)
        c10, c11, c12 = 2 * (qx * qy - qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz + qw * qx)
        c20, c21, c22 = 2 * (qx * qz + qw * qy), 2 * (qy * qz - qw * qx), 1 - 2 * (qx * qx + qy * qy)
        tx, ty, tz = self._thrust_vector
        norm = math.sqrt(tx * tx + ty * ty + tz * tz)
        if norm > 1e-6:
            zb0, zb1, zb2 = -tx / norm, -ty / norm, -tz / norm
        else:
            zb0, zb1, zb2 = 0.0, 0.0, 1.0
        yaw = self._yaw_sp if not math.isnan(self._yaw_sp) else math.atan2(c01, c00)
        cy, sy = math.cos(yaw), math.sin(yaw)
        yb0, yb1, yb2 = -zb2 * sy, zb2 * cy, zb0 * sy - zb1 * cy  # z_b x (cos yaw, sin yaw, 0)
        y_norm = math.sqrt(yb0 * yb0 + yb1 * yb1 + yb2 * yb2)
        if y_norm > 1e-6:
            yb0, yb1, yb2 = yb0 / y_norm, yb1 / y_norm, yb2 / y_norm
        else:
            yb0, yb1, yb2 = c10, c11, c12
        # x_b = y_b x z_b
        xb0, xb1, xb2 = yb1 * zb2 - yb2 * zb1, yb2 * zb0 - yb0 * zb2, yb0 * zb1 - yb1 * zb0
        # Geometric attitude error (Lee et al.) in the body frame: e_R = vee(R_sp^T R - R^T R_sp) / 2.
        e_x = 0.5 * ((zb0 * c10 + zb1 * c11 + zb2 * c12) - (c20 * yb0 + c21 * yb1 + c22 * yb2))
        e_y = 0.5 * ((xb0 * c20 + xb1 * c21 + xb2 * c22) - (c00 * zb0 + c01 * zb1 + c02 * zb2))
        e_z = 0.5 * ((yb0 * c00 + yb1 * c01 + yb2 * c02) - (c10 * xb0 + c11 * xb1 + c12 * xb2))
        rp_max, y_max = math.radians(lim.rate_max_roll_pitch_dps), math.radians(lim.rate_max_yaw_dps)
        kx, ky, kz = g.att_p
        sp_x = min(max(-kx * e_x, -rp_max), rp_max)
        sp_y = min(max(-ky * e_y, -rp_max), rp_max)
        sp_z = min(max(-kz * e_z, -y_max), y_max)
        r_x, r_y, r_z = state.rates_frd_radps.tolist()
        err_x, err_y, err_z = sp_x - r_x, sp_y - r_y, sp_z - r_z
        last_x, last_y, last_z = self._last_rate_error
        if dt_s > 0:
            d_x, d_y, d_z = (err_x - last_x) / dt_s, (err_y - last_y) / dt_s, (err_z - last_z) / dt_s
        else:
            d_x, d_y, d_z = 0.0, 0.0, 0.0
        self._last_rate_error = (err_x, err_y, err_z)
        i_x, i_y, i_z = self._rate_integral
        (p_x, p_y, p_z), (ki_x, ki_y, ki_z), (kd_x, kd_y, kd_z) = g.rate_p, g.rate_i, g.rate_d
        torque = (
            p_x * err_x + ki_x * i_x + kd_x * d_x,
            p_y * err_y + ki_y * i_y + kd_y * d_y,
            p_z * err_z + ki_z * i_z + kd_z * d_z,
        )
        if integrate:
            self._rate_integral = (
                min(max(i_x + err_x * dt_s, -0.3), 0.3),
                min(max(i_y + err_y * dt_s, -0.3), 0.3),
                min(max(i_z + err_z * dt_s, -0.3), 0.3),
            )

        collective = max(0.0, -(tx * c20 + ty * c21 + tz * c22))  # thrust along the current body axis
        self.collective = collective
        return self._mix(collective, torque)

    def _mix(self, collective: float, torque: F64Array | tuple[float, ...]) -> F64Array:
        """Allocate collective thrust and torques to rotors; yaw only gets the headroom left."""
        t_roll, t_pitch, t_yaw = (float(v) for v in torque)
        rp = [collective + r * t_roll + p * t_pitch for r, p in zip(self._roll, self._pitch, strict=True)]
        low, high = min(rp), max(rp)
        if high - low > 1.0:  # cannot fit roll/pitch: scale them down around the collective
            scale = 1.0 / (high - low)
            rp = [collective + (v - collective) * scale for v in rp]
            low, high = min(rp), max(rp)
        if low < 0.0:
            rp = [v - low for v in rp]
        elif high > 1.0:
            rp = [v - (high - 1.0) for v in rp]
        yaw = [s * t_yaw for s in self._yaw]
        limit = math.inf
        for y, v in zip(yaw, rp, strict=True):
            if y > 0:
                limit = min(limit, (1.0 - v) / y)
            elif y < 0:
                limit = min(limit, v / -y)
        scale = min(1.0, limit)
        thrust = [min(max(v + y * scale, 0.0), 1.0) for v, y in zip(rp, yaw, strict=True)]
        f = self.airframe.thrust_model_factor
        if f <= 1e-6:
            return np.array(thrust)
        return np.array([(-(1.0 - f) + math.sqrt((1.0 - f) ** 2 + 4.0 * f * t)) / (2.0 * f) for t in thrust])
