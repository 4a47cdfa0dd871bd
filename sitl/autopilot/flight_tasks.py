"""What each flight mode flies, as PX4's flight tasks: the position, velocity and yaw setpoint of OFFBOARD, takeoff,
land, return, mission, orbit, the pilot's sticks in POSCTL, and the brake-then-hold of the holding modes.

Local NED metres and m/s; NaN where a setpoint leaves the axis to the controller.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from sitl.autopilot.controller import Setpoint
from sitl.autopilot.modes import FlightMode
from sitl.autopilot.navigator import Navigator
from sitl.autopilot.params import ParameterStore
from sitl.autopilot.status import ControlSource, MavResult
from sitl.dynamics.base import F64Array, VehicleState


class OffboardStream(Protocol):
    """The latest accepted offboard setpoint (NaN where its type mask ignores the field)."""

    @property
    def position_ned_m(self) -> F64Array: ...

    @property
    def velocity_ned_mps(self) -> F64Array: ...

    @property
    def yaw_rad(self) -> float: ...


class FlightTaskHost(Protocol):
    """What the flight tasks read and move of the commander's state (:class:`~sitl.autopilot.commander.Commander`)."""

    params: ParameterStore
    mode: FlightMode
    home_ned_m: F64Array
    hold_ned_m: F64Array
    hold_yaw_rad: float
    braking: bool
    takeoff_altitude_m: float
    pilot_sticks: F64Array
    rc_lost: bool
    navigator: Navigator

    @property
    def offboard(self) -> OffboardStream | None:
        """The latest offboard setpoint (None: none yet)."""
        ...

    def set_mode(self, mode: FlightMode, source: ControlSource = ControlSource.MAVLINK) -> MavResult:
        """Switch mode, as any request does."""
        ...

    def capture_hold(self) -> None:
        """Hold where the vehicle is, at its heading."""
        ...


def mode_setpoint(c: FlightTaskHost, state: VehicleState) -> Setpoint:
    """The setpoint the mode ``c`` flies asks for at ``state`` (a takeoff that reached its height holds; braking ends
    where the vehicle stopped)."""
    nan3 = np.full(3, math.nan)
    if c.mode is FlightMode.OFFBOARD and c.offboard is not None:
        sp = c.offboard
        return Setpoint(sp.position_ned_m.copy(), sp.velocity_ned_mps.copy(), sp.yaw_rad)
    if c.mode is FlightMode.AUTO_TAKEOFF:
        target = c.hold_ned_m.copy()
        target[2] = c.home_ned_m[2] - c.takeoff_altitude_m
        if state.position_ned_m[2] - target[2] < 0.3:
            c.set_mode(FlightMode.AUTO_LOITER, ControlSource.AUTOPILOT)
            return Setpoint.hold(target, c.hold_yaw_rad)
        climb = np.array([math.nan, math.nan, -c.params["MPC_TKO_SPEED"]])
        pos = np.array([target[0], target[1], math.nan])
        return Setpoint(pos, climb, c.hold_yaw_rad)
    if c.mode is FlightMode.AUTO_LAND:
        pos = np.array([c.hold_ned_m[0], c.hold_ned_m[1], math.nan])
        return Setpoint(pos, np.array([math.nan, math.nan, c.params["MPC_LAND_SPEED"]]), c.hold_yaw_rad)
    if c.mode is FlightMode.AUTO_RTL:
        return c.navigator.rtl_setpoint(state)
    if c.mode is FlightMode.AUTO_MISSION:
        return c.navigator.mission_setpoint(state)
    if c.mode is FlightMode.ORBIT and c.navigator.orbit is not None:
        return c.navigator.orbit_setpoint()
    if c.mode is FlightMode.POSCTL and np.any(c.pilot_sticks != 0) and not c.rc_lost:
        c.capture_hold()
        vel = c.pilot_sticks * np.array(
            [c.params["MPC_XY_VEL_MAX"], c.params["MPC_XY_VEL_MAX"], c.params["MPC_Z_VEL_MAX_DN"]]
        )
        return Setpoint(nan3.copy(), vel, c.hold_yaw_rad)
    if c.braking:  # as PX4: brake to a stop first, then hold where the vehicle stopped
        if math.hypot(state.velocity_ned_mps[0], state.velocity_ned_mps[1]) > 0.3:
            pos = np.array([math.nan, math.nan, c.hold_ned_m[2]])
            return Setpoint(pos, np.array([0.0, 0.0, math.nan]), c.hold_yaw_rad)
        c.braking = False
        c.hold_ned_m[:2] = state.position_ned_m[:2]
    return Setpoint.hold(c.hold_ned_m, c.hold_yaw_rad)
