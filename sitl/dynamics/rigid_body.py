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
    """The default dynamics backend (see the module docstring).

    The state is kept in Python floats and a step is scalar arithmetic: on 3- and 4-vectors, numpy's per-call
    overhead was most of a step's cost. The model and its order of integration are the same as the numpy version's
    (issue 34: results may change in the last bits of rounding).
    """

    min_rate_hz = 200.0

    def __init__(self, params: RigidBodyParameters | None = None, home_position_ned_m: F64Array | None = None) -> None:
        self.params = p = params or RigidBodyParameters()
        self._rotors = tuple((sx * p.arm_m, sy * p.arm_m) for sx, sy in ROTOR_LAYOUT)
        lx, ly, lz = p.leg_offset_frd_m
        self._legs = ((lx, ly, lz), (lx, -ly, lz), (-lx, ly, lz), (-lx, -ly, lz))
        home = np.zeros(3) if home_position_ned_m is None else np.asarray(home_position_ned_m, dtype=np.float64)
        self._ground_down_m = float(home[2])
        at_rest_m = self._ground_down_m - lz + p.mass_kg * GRAVITY_MPS2 / (4 * p.leg_stiffness_npm)
        self._pos = (float(home[0]), float(home[1]), at_rest_m)
        self._vel = (0.0, 0.0, 0.0)
        self._q = (1.0, 0.0, 0.0, 0.0)
        self._omega = (0.0, 0.0, 0.0)
        self._rotor_speed = (0.0, 0.0, 0.0, 0.0)
        self._commands = (0.0, 0.0, 0.0, 0.0)
        self._wind = (0.0, 0.0, 0.0)
        self._acc = (0.0, 0.0, 0.0)
        self._on_ground = True
        self._alpha_dt_s = math.nan
        self._alpha = 0.0
        self._airframe = Airframe(
            rotor_positions_frd_m=self._rotors,
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
            np.array(self._pos),
            np.array(self._vel),
            np.array(self._q),
            np.array(self._omega),
            np.array(self._acc),
            self._on_ground,
        )

    def set_motor_commands(self, commands: F64Array) -> None:
        """ESC commands (4,), clipped to [0, 1]; NaN counts as 0."""
        c1, c2, c3, c4 = (0.0 if math.isnan(c) else min(max(c, 0.0), 1.0) for c in map(float, commands))
        self._commands = (c1, c2, c3, c4)

    def set_wind(self, wind_ned_mps: F64Array) -> None:
        """Wind velocity in world NED."""
        w = np.asarray(wind_ned_mps, dtype=np.float64).reshape(3)
        self._wind = (float(w[0]), float(w[1]), float(w[2]))

    def step(self, dt_s: float) -> None:
        """Advance by ``dt_s`` (semi-implicit Euler)."""
        p = self.params
        if dt_s != self._alpha_dt_s:
            self._alpha_dt_s, self._alpha = dt_s, 1.0 - math.exp(-dt_s / p.motor_time_constant_s)
        alpha = self._alpha
        w1, w2, w3, w4 = (w + alpha * (c - w) for w, c in zip(self._rotor_speed, self._commands, strict=True))
        self._rotor_speed = (w1, w2, w3, w4)
        t_max = p.max_thrust_per_rotor_n
        t1, t2, t3, t4 = t_max * w1 * w1, t_max * w2 * w2, t_max * w3 * w3, t_max * w4 * w4
        (x1, y1), (x2, y2), (x3, y3), (x4, y4) = self._rotors
        qw, qx, qy, qz = self._q
        # R: body -> world, as quaternion_to_matrix.
        r00, r01, r02 = 1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)
        r10, r11, r12 = 2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)
        r20, r21, r22 = 2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)

        # Body-frame torque: r x F for each rotor with F = (0, 0, -T), plus drag torques, plus angular drag.
        ox, oy, oz = self._omega
        drag = p.angular_drag_nmsprad
        s1, s2, s3, s4 = ROTOR_YAW_SIGN
        tau_x = -(y1 * t1 + y2 * t2 + y3 * t3 + y4 * t4) - drag * ox
        tau_y = (x1 * t1 + x2 * t2 + x3 * t3 + x4 * t4) - drag * oy
        tau_z = p.torque_coefficient_m * (s1 * t1 + s2 * t2 + s3 * t3 + s4 * t4) - drag * oz
        total = t1 + t2 + t3 + t4
        vx, vy, vz = self._vel
        k = p.linear_drag_nspm
        wind_n, wind_e, wind_d = self._wind
        fx = -r02 * total - k * (vx - wind_n)
        fy = -r12 * total - k * (vy - wind_e)
        fz = -r22 * total - k * (vz - wind_d) + p.mass_kg * GRAVITY_MPS2

        # Ground contact at the four legs (ground plane: down = ground_down_m).
        px, py, pz = self._pos
        on_ground = False
        for lx, ly, lz in self._legs:
            rx = r00 * lx + r01 * ly + r02 * lz  # the leg in the world frame, from the centre of mass
            ry = r10 * lx + r11 * ly + r12 * lz
            rz = r20 * lx + r21 * ly + r22 * lz
            penetration = pz + rz - self._ground_down_m
            if penetration <= 0.0:
                continue
            on_ground = True
            owx = r00 * ox + r01 * oy + r02 * oz  # angular velocity in the world frame
            owy = r10 * ox + r11 * oy + r12 * oz
            owz = r20 * ox + r21 * oy + r22 * oz
            v_px = vx + (owy * rz - owz * ry)
            v_py = vy + (owz * rx - owx * rz)
            v_pz = vz + (owx * ry - owy * rx)
            normal = max(0.0, p.leg_stiffness_npm * penetration + p.leg_damping_nspm * v_pz)
            scale = -p.friction_coefficient * normal / max(math.hypot(v_px, v_py), 0.05)
            gx, gy, gz = scale * v_px, scale * v_py, -normal
            fx, fy, fz = fx + gx, fy + gy, fz + gz
            cx, cy, cz = ry * gz - rz * gy, rz * gx - rx * gz, rx * gy - ry * gx  # r x f, world frame
            tau_x += r00 * cx + r10 * cy + r20 * cz  # ... in the body frame (R^T)
            tau_y += r01 * cx + r11 * cy + r21 * cz
            tau_z += r02 * cx + r12 * cy + r22 * cz
        self._on_ground = on_ground

        m = p.mass_kg
        ax, ay, az = fx / m, fy / m, fz / m
        self._acc = (ax, ay, az)
        vx, vy, vz = vx + ax * dt_s, vy + ay * dt_s, vz + az * dt_s
        self._vel = (vx, vy, vz)
        self._pos = (px + vx * dt_s, py + vy * dt_s, pz + vz * dt_s)
        ix, iy, iz = p.inertia_kgm2
        hx, hy, hz = ix * ox, iy * oy, iz * oz  # angular momentum, body frame
        ox, oy, oz = (
            ox + (tau_x - (oy * hz - oz * hy)) / ix * dt_s,
            oy + (tau_y - (oz * hx - ox * hz)) / iy * dt_s,
            oz + (tau_z - (ox * hy - oy * hx)) / iz * dt_s,
        )
        self._omega = (ox, oy, oz)
        qw, qx, qy, qz = (
            qw + 0.5 * (-qx * ox - qy * oy - qz * oz) * dt_s,
            qx + 0.5 * (qw * ox + qy * oz - qz * oy) * dt_s,
            qy + 0.5 * (qw * oy - qx * oz + qz * ox) * dt_s,
            qz + 0.5 * (qw * oz + qx * oy - qy * ox) * dt_s,
        )
        norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        self._q = (qw / norm, qx / norm, qy / norm, qz / norm)
