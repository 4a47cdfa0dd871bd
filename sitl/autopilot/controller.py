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
from sitl.dynamics.rigid_body import GRAVITY_MPS2, cross3, quaternion_to_matrix


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
        self._roll = -pos[:, 1] / extent
        self._pitch = pos[:, 0] / extent
        self._yaw = np.array(airframe.rotor_yaw_sign, dtype=np.float64)
        self.reset()

    def reset(self) -> None:
        """Clear integrators and memories (on arming, or when landed)."""
        self._vel_integral = np.zeros(3)
        self._rate_integral = np.zeros(3)
        self._last_rate_error = np.zeros(3)
        self._thrust_vector = np.array([0.0, 0.0, -self.airframe.hover_thrust])
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
            kp * err + ki * self._vel_integral - np.array([g.vel_d_xy, g.vel_d_xy, 0.0]) * state.acceleration_ned_mps2
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
            self._vel_integral += grow * dt_s
            self._vel_integral = np.clip(self._vel_integral, -3.0, 3.0)
        self._thrust_vector = thrust
        yaw = setpoint.yaw_rad
        if math.isnan(yaw):
            if math.isnan(self._yaw_sp):
                R = quaternion_to_matrix(state.quaternion_wxyz)
                self._yaw_sp = math.atan2(R[1, 0], R[0, 0])
        else:
            self._yaw_sp = yaw

    # -- inner loops ------------------------------------------------------------------------------------
    def update_attitude(self, state: VehicleState, dt_s: float, integrate: bool = True) -> F64Array:
        """Attitude and rate loops plus the mixer; returns ESC commands (4,) in [0, 1]."""
        g, lim = self.gains, self.limits
        R = quaternion_to_matrix(state.quaternion_wxyz)
        thrust = self._thrust_vector
        norm = float(np.linalg.norm(thrust))
        z_b = -thrust / norm if norm > 1e-6 else np.array([0.0, 0.0, 1.0])
        yaw = self._yaw_sp if not math.isnan(self._yaw_sp) else math.atan2(R[1, 0], R[0, 0])
        x_c = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        y_b = cross3(z_b, x_c)
        y_norm = float(np.linalg.norm(y_b))
        y_b = y_b / y_norm if y_norm > 1e-6 else R[:, 1]
        x_b = cross3(y_b, z_b)
        R_sp = np.column_stack([x_b, y_b, z_b])
        # Geometric attitude error (Lee et al.), in the body frame.
        E = R_sp.T @ R - R.T @ R_sp
        e_R = 0.5 * np.array([E[2, 1], E[0, 2], E[1, 0]])
        rate_sp = -np.array(g.att_p) * e_R
        rp_max, y_max = math.radians(lim.rate_max_roll_pitch_dps), math.radians(lim.rate_max_yaw_dps)
        rate_sp = np.clip(rate_sp, [-rp_max, -rp_max, -y_max], [rp_max, rp_max, y_max])

        rate_err = rate_sp - state.rates_frd_radps
        d_err = (rate_err - self._last_rate_error) / dt_s if dt_s > 0 else np.zeros(3)
        self._last_rate_error = rate_err
        torque = np.array(g.rate_p) * rate_err + np.array(g.rate_i) * self._rate_integral + np.array(g.rate_d) * d_err
        if integrate:
            self._rate_integral = np.clip(self._rate_integral + rate_err * dt_s, -0.3, 0.3)

        collective = max(0.0, float(-thrust @ R[:, 2]))  # thrust along the current body axis
        self.collective = collective
        return self._mix(collective, torque)

    def _mix(self, collective: float, torque: F64Array) -> F64Array:
        """Allocate collective thrust and torques to rotors; yaw only gets the headroom left."""
        rp = collective + self._roll * torque[0] + self._pitch * torque[1]
        low, high = float(rp.min()), float(rp.max())
        if high - low > 1.0:  # cannot fit roll/pitch: scale them down around the collective
            scale = 1.0 / (high - low)
            rp = collective + (rp - collective) * scale
            low, high = float(rp.min()), float(rp.max())
        if low < 0.0:
            rp -= low
        elif high > 1.0:
            rp -= high - 1.0
        yaw = self._yaw * torque[2]
        headroom_up = 1.0 - rp
        headroom_down = rp
        limit = math.inf
        for y, up, down in zip(yaw, headroom_up, headroom_down, strict=True):
            if y > 0:
                limit = min(limit, up / y)
            elif y < 0:
                limit = min(limit, down / -y)
        scale = min(1.0, limit)
        thrust: F64Array = np.clip(rp + yaw * scale, 0.0, 1.0)
        f = self.airframe.thrust_model_factor
        if f <= 1e-6:
            return thrust
        commands: F64Array = (-(1.0 - f) + np.sqrt((1.0 - f) ** 2 + 4.0 * f * thrust)) / (2.0 * f)
        return commands
