"""A numpy 6-DOF rigid-body quadrotor (F450-sized).

Per-rotor thrust ``T_i = T_max * w_i**2`` and drag torque ``Q_i = k_m * T_i`` from normalized rotor speeds ``w_i``
that follow the ESC commands with a first-order lag; linear aerodynamic drag on the air-relative velocity (wind is an
input); gravity; and ground contact through four landing legs, each a spring-damper normal force with regularized
Coulomb friction, so the vehicle rests, slides and tips physically and stays still after touchdown.
Integration: semi-implicit Euler at the caller's step (400 Hz or more recommended).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sitl.dynamics.base import Airframe, F64Array, VehicleState

GRAVITY_MPS2 = 9.80665


@dataclass(frozen=True)
class RigidBodyParameters:
    """Physical parameters; the defaults approximate a 1.4 kg F450 with 9-inch props."""

    mass_kg: float = 1.4
    inertia_kgm2: tuple[float, float, float] = (0.019, 0.019, 0.0252)
    arm_m: float = 0.1651  # rotor offset along each body axis (X configuration)
    max_thrust_per_rotor_n: float = 6.9  # thrust-to-weight 2.0
    torque_coefficient_m: float = 0.016  # drag torque / thrust
    motor_time_constant_s: float = 0.03
    linear_drag_nspm: float = 0.25  # N per m/s of airspeed, each axis
    angular_drag_nmsprad: float = 0.004
    leg_offset_frd_m: tuple[float, float, float] = (0.15, 0.15, 0.12)  # legs at (+-x, +-y, z below the CoM)
    leg_stiffness_npm: float = 2500.0
    leg_damping_nspm: float = 60.0
    friction_coefficient: float = 0.8


# Motor order as PX4's quad X: 1 front right, 2 rear left, 3 front left, 4 rear right. 1 and 2 spin
# counter-clockwise seen from above (reaction torque yaws the body clockwise: positive yaw in NED), 3 and 4 clockwise.
ROTOR_LAYOUT = ((1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0))
ROTOR_YAW_SIGN = (1.0, 1.0, -1.0, -1.0)


def cross3(a: F64Array, b: F64Array) -> F64Array:
    """Cross product of two 3-vectors (numpy's general ``np.cross`` costs ten times more on this size)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def quaternion_to_matrix(q: F64Array) -> F64Array:
    """Rotation matrix (3, 3) of a unit quaternion ``[w, x, y, z]``."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


class RigidBodyQuadrotor:
    """The default dynamics backend (see the module docstring)."""

    min_rate_hz = 200.0

    def __init__(self, params: RigidBodyParameters | None = None, home_position_ned_m: F64Array | None = None) -> None:
        self.params = p = params or RigidBodyParameters()
        self._inertia = np.array(p.inertia_kgm2)
        self._rotors = np.array([(sx * p.arm_m, sy * p.arm_m) for sx, sy in ROTOR_LAYOUT])
        self._yaw_sign = np.array(ROTOR_YAW_SIGN)
        lx, ly, lz = p.leg_offset_frd_m
        self._legs = np.array([(lx, ly, lz), (lx, -ly, lz), (-lx, ly, lz), (-lx, -ly, lz)])
        home = np.zeros(3) if home_position_ned_m is None else np.asarray(home_position_ned_m, dtype=np.float64)
        self._ground_down_m = float(home[2])
        self._pos = home.copy()
        self._pos[2] = self._ground_down_m - lz + p.mass_kg * GRAVITY_MPS2 / (4 * p.leg_stiffness_npm)  # at rest
        self._vel = np.zeros(3)
        self._q = np.array([1.0, 0.0, 0.0, 0.0])
        self._omega = np.zeros(3)
        self._rotor_speed = np.zeros(4)
        self._commands = np.zeros(4)
        self._wind = np.zeros(3)
        self._acc = np.zeros(3)
        self._on_ground = True
        self._airframe = Airframe(
            rotor_positions_frd_m=tuple((float(x), float(y)) for x, y in self._rotors),
            rotor_yaw_sign=ROTOR_YAW_SIGN,
            thrust_model_factor=1.0,
            hover_thrust=p.mass_kg * GRAVITY_MPS2 / (4 * p.max_thrust_per_rotor_n),
            mass_kg=p.mass_kg,
        )

    @property
    def airframe(self) -> Airframe:
        """Geometry and thrust model for the mixer."""
        return self._airframe

    def state(self) -> VehicleState:
        """A copy of the true state."""
        return VehicleState(
            self._pos.copy(), self._vel.copy(), self._q.copy(), self._omega.copy(), self._acc.copy(), self._on_ground
        )

    def set_motor_commands(self, commands: F64Array) -> None:
        """ESC commands (4,), clipped to [0, 1]; NaN counts as 0."""
        self._commands = np.clip(np.nan_to_num(np.asarray(commands, dtype=np.float64)), 0.0, 1.0)

    def set_wind(self, wind_ned_mps: F64Array) -> None:
        """Wind velocity in world NED."""
        self._wind = np.asarray(wind_ned_mps, dtype=np.float64).reshape(3).copy()

    def step(self, dt_s: float) -> None:
        """Advance by ``dt_s`` (semi-implicit Euler)."""
        p = self.params
        alpha = 1.0 - math.exp(-dt_s / p.motor_time_constant_s)
        self._rotor_speed += alpha * (self._commands - self._rotor_speed)
        thrust = p.max_thrust_per_rotor_n * self._rotor_speed**2
        R = quaternion_to_matrix(self._q)

        # Body-frame torque: r x F for each rotor with F = (0, 0, -T), plus drag torques, plus angular drag.
        torque = np.array(
            [
                -float(self._rotors[:, 1] @ thrust),
                float(self._rotors[:, 0] @ thrust),
                p.torque_coefficient_m * float(self._yaw_sign @ thrust),
            ]
        )
        torque -= p.angular_drag_nmsprad * self._omega
        force_world = R @ np.array([0.0, 0.0, -float(thrust.sum())])
        force_world += -p.linear_drag_nspm * (self._vel - self._wind)
        force_world[2] += p.mass_kg * GRAVITY_MPS2

        # Ground contact at the four legs (ground plane: down = ground_down_m).
        legs_world = self._pos + self._legs @ R.T
        penetration = legs_world[:, 2] - self._ground_down_m
        touching = penetration > 0.0
        self._on_ground = bool(touching.any())
        if self._on_ground:
            omega_world = R @ self._omega
            for i in np.nonzero(touching)[0]:
                r_world = legs_world[i] - self._pos
                v_point = self._vel + cross3(omega_world, r_world)
                normal = max(0.0, p.leg_stiffness_npm * penetration[i] + p.leg_damping_nspm * v_point[2])
                v_t = v_point[:2]
                speed_t = math.hypot(v_t[0], v_t[1])
                friction = -p.friction_coefficient * normal * v_t / max(speed_t, 0.05)
                f = np.array([friction[0], friction[1], -normal])
                force_world += f
                torque += R.T @ cross3(r_world, f)

        self._acc = force_world / p.mass_kg
        self._vel += self._acc * dt_s
        self._pos += self._vel * dt_s
        omega_dot = (torque - cross3(self._omega, self._inertia * self._omega)) / self._inertia
        self._omega += omega_dot * dt_s
        wx, wy, wz = self._omega
        w, x, y, z = self._q
        dq = 0.5 * np.array(
            [-x * wx - y * wy - z * wz, w * wx + y * wz - z * wy, w * wy - x * wz + z * wx, w * wz + x * wy - y * wx]
        )
        self._q = self._q + dq * dt_s
        self._q /= float(np.linalg.norm(self._q))
