"""The autopilot's pre-arm checks (PX4's health and arming checks, as far as this SITL simulates them): why arming
would be denied now, in the words a ground station shows."""

from __future__ import annotations

from typing import Protocol

from sitl.autopilot.battery import BatteryLevel
from sitl.autopilot.modes import FlightMode
from sitl.autopilot.navigator import Navigator
from sitl.autopilot.status import LandedState


class ArmingHost(Protocol):
    """What the checks read of the commander (:class:`~sitl.autopilot.commander.Commander`)."""

    mode: FlightMode
    rc_lost: bool
    navigator: Navigator
    battery_level: BatteryLevel

    @property
    def landed_state(self) -> LandedState:
        """The land detector's state."""
        ...

    def outside_fence(self) -> bool:
        """Outside the fence or the distance limits."""
        ...

    def offboard_stream_ok(self) -> bool:
        """Offboard setpoints arrive."""
        ...


def prearm_problem(c: ArmingHost) -> str | None:
    """Why arming would be denied now, or None when the pre-arm checks pass."""
    if c.landed_state is not LandedState.ON_GROUND:
        return "not landed"
    if c.mode in (FlightMode.AUTO_LAND, FlightMode.AUTO_RTL, FlightMode.ORBIT):
        return f"mode {c.mode.px4_name} is not armable"
    if c.mode is FlightMode.AUTO_MISSION and not c.navigator.mission:
        return "no mission"
    if c.outside_fence():
        return "vehicle outside the geofence"
    if c.mode is FlightMode.OFFBOARD and not c.offboard_stream_ok():
        return "no offboard setpoints"
    if c.rc_lost and c.mode is FlightMode.POSCTL:
        return "no RC"
    if c.battery_level >= BatteryLevel.CRITICAL:
        return f"battery {c.battery_level.name.lower()}"
    return None
