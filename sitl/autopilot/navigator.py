"""The autopilot's navigator, beside its commander as PX4 has them: the modes that fly somewhere on their own (the
mission, orbit, go-to and return home) and the state each keeps. The commander owns arming, modes, the land detector
and the failsafes; it asks the navigator for the setpoint of a navigation mode, and the navigator asks the commander
(through :class:`NavigatorHost`) where the vehicle is, for the hold point they share, and for mode changes.

Times are simulated seconds; positions local NED, m.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from sitl.autopilot.controller import Setpoint
from sitl.autopilot.modes import FlightMode
from sitl.autopilot.params import ParameterStore
from sitl.autopilot.status import ControlSource, LandedState, MavResult, Severity
from sitl.dynamics.base import F64Array, VehicleState


class NavCommand(enum.IntEnum):
    """The mission items this autopilot flies (MAV_CMD ids)."""

    WAYPOINT = 16
    LOITER_UNLIM = 17
    LOITER_TIME = 19
    RETURN_TO_LAUNCH = 20
    LAND = 21
    TAKEOFF = 22


@dataclass(frozen=True)
class NavItem:
    """One mission item as flown: local NED, NaN where the item leaves a coordinate to the vehicle (the position it
    has when the item starts). The height is either ``down_m`` (an AMSL altitude, fixed in NED) or ``above_home_m``
    (relative to home when the item starts), never both."""

    seq: int
    command: NavCommand
    north_m: float
    east_m: float
    down_m: float = math.nan
    above_home_m: float = math.nan
    hold_s: float = 0.0
    radius_m: float = math.nan  # NaN: NAV_ACC_RAD
    yaw_rad: float = math.nan


@dataclass(frozen=True)
class Orbit:
    """DO_ORBIT: a circle in local NED flown at ``speed_mps`` (positive: clockwise seen from above), facing its
    centre."""

    north_m: float
    east_m: float
    down_m: float
    radius_m: float
    speed_mps: float


class NavigatorHost(Protocol):
    """What the navigator reads and moves of the commander's state (:class:`~sitl.autopilot.commander.Commander`)."""

    params: ParameterStore
    home_ned_m: F64Array
    armed: bool
    mode: FlightMode
    now_s: float
    hold_ned_m: F64Array
    """Where the vehicle holds (and a go-to flies to)."""
    hold_yaw_rad: float
    braking: bool
    """Braking to a stop before holding (a go-to ends it: the hold point is the target)."""
    changed: bool
    """Set when ground stations must hear of a change at once."""

    @property
    def landed_state(self) -> LandedState:
        """The land detector's state (read only)."""
        ...

    def position(self) -> F64Array:
        """The vehicle's position, local NED (m), a copy."""
        ...

    def set_mode(self, mode: FlightMode, source: ControlSource = ControlSource.MAVLINK) -> MavResult:
        """Switch mode, as any request does."""
        ...

    def event(self, text: str, severity: Severity = Severity.INFO) -> None:
        """Tell the ground stations."""
        ...


class Navigator:
    """Mission, orbit, go-to and return home for ``commander`` (see the module docstring)."""

    def __init__(self, commander: NavigatorHost) -> None:
        self.c = commander
        self.mission: list[NavItem] = []
        self.mission_current = 0
        self.mission_reached: deque[int] = deque(maxlen=32)  # items reached, for MISSION_ITEM_REACHED
        self.mission_changed = False  # the current item changed: MISSION_CURRENT at once
        self._item_target_ned = np.full(3, math.nan)
        self._item_arrived_s = math.nan
        self._item_landing = False
        self.orbit: Orbit | None = None
        self._orbit_angle_rad = 0.0
        self._orbit_last_s = math.nan
        self.rtl_phase = 0  # 0: climb to RTL_RETURN_ALT, 1: fly home, 2: land there

    @property
    def item_landing(self) -> bool:
        """The current mission item is a landing, descending now."""
        return self._item_landing

    def mode_entered(self, mode: FlightMode) -> None:
        """The commander switched to ``mode``: return home starts from its climb; a mission from its current item."""
        self.rtl_phase = 0
        if mode is FlightMode.AUTO_MISSION:
            self.start_item()

    def disarmed(self) -> None:
        """As PX4: a finished mission starts over at the next arming."""
        if self.mission and self.mission_current >= len(self.mission):
            self.mission_current = 0
            self.mission_changed = True

    # -- return home -------------------------------------------------------------------------------------------------
    def rtl_setpoint(self, state: VehicleState) -> Setpoint:
        return_down = self.c.home_ned_m[2] - self.c.params["RTL_RETURN_ALT"]
        pos = state.position_ned_m
        if self.rtl_phase == 0:  # climb to the return altitude where we are
            target_down = min(return_down, pos[2])
            if abs(pos[2] - target_down) < 0.5:
                self.rtl_phase = 1
            return Setpoint.hold(
                np.array([self.c.hold_ned_m[0], self.c.hold_ned_m[1], target_down]), self.c.hold_yaw_rad
            )
        if self.rtl_phase == 1:  # fly home at that altitude
            target = np.array([self.c.home_ned_m[0], self.c.home_ned_m[1], min(return_down, self.c.hold_ned_m[2])])
            if math.hypot(pos[0] - target[0], pos[1] - target[1]) < 1.0:
                self.rtl_phase = 2
            return Setpoint.hold(target, self.c.hold_yaw_rad)
        land = np.array([self.c.home_ned_m[0], self.c.home_ned_m[1], math.nan])
        return Setpoint(land, np.array([math.nan, math.nan, self.c.params["MPC_LAND_SPEED"]]), self.c.hold_yaw_rad)

    # -- go-to, orbit, missions ------------------------------------------------------------------------------------
    def reposition(self, target_ned_m: F64Array, yaw_rad: float = math.nan) -> MavResult:
        """DO_REPOSITION: fly to ``target_ned_m`` (NaN: keep that coordinate) in HOLD and stay there."""
        if not self.c.armed or self.c.landed_state is LandedState.ON_GROUND:
            self.c.event("Reposition rejected: not flying", Severity.CRITICAL)
            return MavResult.TEMPORARILY_REJECTED
        result = self.c.set_mode(FlightMode.AUTO_LOITER)
        if result is not MavResult.ACCEPTED:
            return result
        target = np.asarray(target_ned_m, dtype=np.float64)
        here = self.c.position()
        self.c.hold_ned_m = np.where(np.isnan(target), here, target)
        if math.isfinite(yaw_rad):
            self.c.hold_yaw_rad = yaw_rad
        self.c.braking = False
        self.c.changed = True
        return MavResult.ACCEPTED

    def start_orbit(self, orbit: Orbit) -> MavResult:
        """DO_ORBIT: circle ``orbit`` (in the air only)."""
        if not self.c.armed or self.c.landed_state is LandedState.ON_GROUND:
            self.c.event("Orbit rejected: not flying", Severity.CRITICAL)
            return MavResult.TEMPORARILY_REJECTED
        here = self.c.position()
        self.orbit = orbit
        self._orbit_angle_rad = math.atan2(here[1] - orbit.east_m, here[0] - orbit.north_m)
        self._orbit_last_s = math.nan
        if self.c.mode is FlightMode.ORBIT:
            return MavResult.ACCEPTED
        return self.c.set_mode(FlightMode.ORBIT)

    def orbit_setpoint(self) -> Setpoint:
        o = self.orbit
        assert o is not None
        if math.isfinite(self._orbit_last_s):
            self._orbit_angle_rad += o.speed_mps / o.radius_m * (self.c.now_s - self._orbit_last_s)
        self._orbit_last_s = self.c.now_s
        a = self._orbit_angle_rad
        position = np.array([o.north_m + o.radius_m * math.cos(a), o.east_m + o.radius_m * math.sin(a), o.down_m])
        velocity = np.array([-o.speed_mps * math.sin(a), o.speed_mps * math.cos(a), 0.0])
        return Setpoint(position, velocity, math.atan2(-math.sin(a), -math.cos(a)))

    def set_mission(self, items: list[NavItem]) -> None:
        """A new mission (an upload or a clear); flying it goes on from the same index, or holds when it is gone."""
        self.mission = list(items)
        self.mission_current = min(self.mission_current, max(len(items) - 1, 0)) if items else 0
        self.mission_changed = True
        if self.c.mode is FlightMode.AUTO_MISSION:
            if not items:
                self.c.set_mode(FlightMode.AUTO_LOITER, ControlSource.AUTOPILOT)
            else:
                self.start_item()

    def set_mission_current(self, seq: int) -> MavResult:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: fly item ``seq`` next."""
        if not 0 <= seq < len(self.mission):
            return MavResult.DENIED
        self.mission_current = seq
        self.mission_changed = True
        if self.c.mode is FlightMode.AUTO_MISSION:
            self.start_item()
        return MavResult.ACCEPTED

    def start_mission(self, first: int) -> MavResult:
        """MISSION_START: AUTO.MISSION from item ``first``."""
        if not 0 <= first < len(self.mission):
            self.c.event("Mission rejected: no such item", Severity.CRITICAL)
            return MavResult.DENIED
        self.mission_current = first
        self.mission_changed = True
        return self.c.set_mode(FlightMode.AUTO_MISSION)

    def start_item(self) -> None:
        """The current item begins: resolve the coordinates it leaves to the vehicle."""
        self._item_arrived_s = math.nan
        self._item_landing = False
        if self.mission_current >= len(self.mission):
            return
        item = self.mission[self.mission_current]
        here = self.c.position()
        down = item.down_m
        if math.isnan(down) and not math.isnan(item.above_home_m):
            down = float(self.c.home_ned_m[2]) - item.above_home_m
        if item.command is NavCommand.LAND:
            down = float(here[2])  # fly there at this height, then descend
        target = np.array([item.north_m, item.east_m, down])
        self._item_target_ned = np.where(np.isnan(target), here, target)
        if math.isfinite(item.yaw_rad):
            self.c.hold_yaw_rad = item.yaw_rad

    def item_reached(self) -> None:
        self.mission_reached.append(self.mission_current)
        self.mission_current += 1
        self.mission_changed = True
        if self.mission_current >= len(self.mission):
            self.mission_current = len(self.mission)
            if self.c.armed and self.c.landed_state is not LandedState.ON_GROUND:
                self.c.event("Mission finished, loitering")
                self.c.set_mode(FlightMode.AUTO_LOITER, ControlSource.AUTOPILOT)
            else:
                self.c.event("Mission finished")  # landed: it starts over from the first item once disarmed
            return
        self.start_item()

    def mission_setpoint(self, state: VehicleState) -> Setpoint:
        if self.mission_current >= len(self.mission):  # finished: stay where it is, on the ground or in the air
            if self.c.landed_state is LandedState.ON_GROUND:
                return Setpoint.hold(self.c.position(), self.c.hold_yaw_rad)
            return Setpoint.hold(self.c.hold_ned_m, self.c.hold_yaw_rad)
        item = self.mission[self.mission_current]
        target = self._item_target_ned
        pos = state.position_ned_m
        if item.command is NavCommand.RETURN_TO_LAUNCH:
            self.item_reached()
            self.c.set_mode(FlightMode.AUTO_RTL, ControlSource.AUTOPILOT)
            return self.rtl_setpoint(state)
        radius = item.radius_m if math.isfinite(item.radius_m) and item.radius_m > 0 else self.c.params["NAV_ACC_RAD"]
        horizontal = math.hypot(pos[0] - target[0], pos[1] - target[1])
        if item.command is NavCommand.LAND:
            if self._item_landing or horizontal < radius:
                self._item_landing = True
                descend = np.array([math.nan, math.nan, self.c.params["MPC_LAND_SPEED"]])
                return Setpoint(np.array([target[0], target[1], math.nan]), descend, self.c.hold_yaw_rad)
            return Setpoint.hold(target, self.c.hold_yaw_rad)
        if item.command is NavCommand.TAKEOFF and pos[2] - target[2] > 0.3:
            climb = np.array([math.nan, math.nan, -self.c.params["MPC_TKO_SPEED"]])
            setpoint = Setpoint(np.array([target[0], target[1], math.nan]), climb, self.c.hold_yaw_rad)
        else:
            setpoint = Setpoint.hold(target, self.c.hold_yaw_rad)
        vertical_ok = abs(pos[2] - target[2]) < self.c.params["NAV_MC_ALT_RAD"]
        arrived = vertical_ok and (item.command is NavCommand.TAKEOFF or horizontal < radius)
        if arrived and math.isnan(self._item_arrived_s):
            self._item_arrived_s = self.c.now_s
        if item.command is NavCommand.LOITER_UNLIM or math.isnan(self._item_arrived_s):
            return setpoint
        if self.c.now_s - self._item_arrived_s >= item.hold_s:
            self.c.hold_ned_m = target.copy()
            self.item_reached()
            if self.c.mode is FlightMode.AUTO_MISSION and self.mission_current < len(self.mission):
                return self.mission_setpoint(state)
            return Setpoint.hold(self.c.hold_ned_m, self.c.hold_yaw_rad)
        return setpoint
