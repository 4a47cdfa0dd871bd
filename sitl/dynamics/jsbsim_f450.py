"""JSBSim's F450 quadrotor (shipped in the ``jsbsim`` package) behind the same interface as the numpy model.

Motors are driven through ``fcs/cmd{FR,AL,FL,AR}_ext_nd`` with JSBSim's own stability augmentation off
(``fcs/ScasEngage = 0``), in PX4's quad-X order (1 front right, 2 aft left, 3 front left, 4 aft right). The model
starts from its ``initGrnd`` conditions, trimmed on the ground. Its landing-gear contact needs 300 Hz or more.
JSBSim is an optional dependency (no aarch64 wheel): install the ``sitl`` extra.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from companion.geometry import quaternion_from_euler
from sitl.dynamics.base import Airframe, DynamicsError, F64Array, VehicleState
from sitl.geodesy import geodetic_to_ned

FT_M = 0.3048
MOTORS = ("FR", "AL", "FL", "AR")
ARM_M = 0.1651


class JsbsimF450:
    """The JSBSim backend (see the module docstring)."""

    min_rate_hz = 300.0

    def __init__(self, home_position_ned_m: F64Array | None = None, rate_hz: float = 400.0) -> None:
        try:
            import jsbsim
        except ImportError:
            raise DynamicsError("jsbsim_f450", "the jsbsim package is not installed (pip install '.[sitl]')") from None
        # JSBSim prints a banner, property warnings and a version notice while loading: keep the process output
        # clean (a failed load is still reported below).
        saved = (os.dup(1), os.dup(2))
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, 1)
            os.dup2(devnull, 2)
            self._fdm: Any = jsbsim.FGFDMExec(None)
            self._fdm.set_debug_level(0)
            loaded = self._fdm.load_model("F450") and self._fdm.load_ic("initGrnd", True)
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(devnull)
            os.close(saved[0])
            os.close(saved[1])
        if not loaded:
            raise DynamicsError("jsbsim_f450", "cannot load the F450 model or its initGrnd conditions")
        self._fdm["ic/psi-true-deg"] = 0.0
        self._dt = 1.0 / rate_hz
        self._fdm.set_dt(self._dt)
        self._fdm.run_ic()
        self._fdm["propulsion/set-running"] = -1
        self._fdm["fcs/ScasEngage"] = 0
        self._fdm.run()
        self._fdm["simulation/do_simple_trim"] = 2  # ground trim
        self._lat0 = float(self._fdm["position/lat-geod-deg"])
        self._lon0 = float(self._fdm["position/long-gc-deg"])
        self._h0_m = float(self._fdm["position/h-sl-meters"])
        self._agl0_m = float(self._fdm["position/h-agl-ft"]) * FT_M
        home = np.zeros(3) if home_position_ned_m is None else np.asarray(home_position_ned_m, dtype=np.float64)
        # Local NED with the ground at down = home[2]; the resting centre of mass sits agl0 above it.
        self._offset = home - np.array([0.0, 0.0, self._agl0_m])
        self._last_vel = np.zeros(3)
        self._acc = np.zeros(3)
        self._airframe = Airframe(
            rotor_positions_frd_m=((ARM_M, ARM_M), (-ARM_M, -ARM_M), (ARM_M, -ARM_M), (-ARM_M, ARM_M)),
            rotor_yaw_sign=(1.0, 1.0, -1.0, -1.0),
            thrust_model_factor=1.0,
            hover_thrust=0.19,  # measured: hover at about 0.44 command with a quadratic thrust curve
            mass_kg=float(self._fdm["inertia/weight-lbs"]) * 0.45359237,
        )

    @property
    def airframe(self) -> Airframe:
        """Geometry and thrust model for the mixer."""
        return self._airframe

    def state(self) -> VehicleState:
        """The true state, in the SITL's local NED."""
        f = self._fdm
        n, e, d = geodetic_to_ned(
            float(f["position/lat-geod-deg"]),
            float(f["position/long-gc-deg"]),
            float(f["position/h-sl-meters"]),
            self._lat0,
            self._lon0,
            self._h0_m,
        )
        position = np.array([n, e, d]) + self._offset
        velocity = (
            np.array(
                [
                    float(f["velocities/v-north-fps"]),
                    float(f["velocities/v-east-fps"]),
                    float(f["velocities/v-down-fps"]),
                ]
            )
            * FT_M
        )
        quaternion = quaternion_from_euler(
            float(f["attitude/phi-rad"]), float(f["attitude/theta-rad"]), float(f["attitude/psi-rad"])
        )
        rates = np.array(
            [float(f["velocities/p-rad_sec"]), float(f["velocities/q-rad_sec"]), float(f["velocities/r-rad_sec"])]
        )
        return VehicleState(position, velocity, quaternion, rates, self._acc.copy(), bool(f["gear/wow"]))

    def set_motor_commands(self, commands: F64Array) -> None:
        """ESC commands (4,), clipped to [0, 1], PX4 order."""
        u = np.clip(np.nan_to_num(np.asarray(commands, dtype=np.float64)), 0.0, 1.0)
        for name, value in zip(MOTORS, u, strict=True):
            self._fdm[f"fcs/cmd{name}_ext_nd"] = float(value)

    def set_wind(self, wind_ned_mps: F64Array) -> None:
        """Wind velocity in world NED."""
        w = np.asarray(wind_ned_mps, dtype=np.float64).reshape(3) / FT_M
        self._fdm["atmosphere/wind-north-fps"] = float(w[0])
        self._fdm["atmosphere/wind-east-fps"] = float(w[1])
        self._fdm["atmosphere/wind-down-fps"] = float(w[2])

    def step(self, dt_s: float) -> None:
        """Advance by ``dt_s`` (in JSBSim steps of the configured rate)."""
        steps = max(1, round(dt_s / self._dt))
        for _ in range(steps):
            self._fdm.run()
        f = self._fdm
        vel = (
            np.array(
                [
                    float(f["velocities/v-north-fps"]),
                    float(f["velocities/v-east-fps"]),
                    float(f["velocities/v-down-fps"]),
                ]
            )
            * FT_M
        )
        self._acc = (vel - self._last_vel) / (steps * self._dt)
        self._last_vel = vel
