"""The commands the autopilot acts on (COMMAND_LONG and COMMAND_INT), one handler each in a table by MAV_CMD id, and
SET_MODE's mode check, against the vehicle the MAVLink server serves (:class:`AutopilotHost`).

Every parameter that came over the wire is checked before use: one that must be a whole number and is NaN, infinite
or fractional is DENIED (:func:`whole`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from sitl.autopilot.actuators import ActuatorOutputs
from sitl.autopilot.battery import Battery
from sitl.autopilot.commander import FORCE_MAGIC, Commander
from sitl.autopilot.controller import CascadedController
from sitl.autopilot.flight_ulog import FlightULog
from sitl.autopilot.mavlink_link import MavlinkLink
from sitl.autopilot.mission_server import MAX_DISTANCE_M
from sitl.autopilot.modes import FlightMode, MainMode
from sitl.autopilot.navigator import Orbit
from sitl.autopilot.params import ParameterStore
from sitl.autopilot.status import LandedState, MavResult, Severity
from sitl.autopilot.telemetry import MESSAGE_IDS, NAMES_BY_ID, ONE_SHOT, StreamSchedule, TelemetryBuilder
from sitl.config import SitlConfig
from sitl.dynamics.base import Dynamics
from sitl.geodesy import geodetic_to_ned
from sitl.timing.clock import SimClock
from sitl.timing.lockstep_gate import LockstepGate

MAV_CMD_REQUEST_PROTOCOL_VERSION = 519
REPOSITION_CHANGE_MODE = 1  # DO_REPOSITION param2 bit: switch to the go-to mode


def whole(value: float, low: int, high: int, nan_is: int | None = None) -> int | None:
    """A command parameter as a whole number in [low, high], or None when it is not one (NaN gives ``nan_is``).

    MAVLink carries every COMMAND_LONG parameter as a float: a hostile or broken sender may put NaN, infinity or a
    huge value where an id or an enum belongs, and ``int()`` of those raises.
    """
    if math.isnan(value):
        return nan_is
    if not math.isfinite(value) or value != round(value) or not low <= value <= high:
        return None
    return int(value)


@dataclass
class CommandRequest:
    """One COMMAND_LONG or COMMAND_INT as its handler sees it: the link it came on, the message, its first four
    parameters and the seventh (COMMAND_INT's ``z``), and the message the handler wants sent after the ACK."""

    link: MavlinkLink
    msg: Any
    is_int: bool
    follow_up: str | None = None

    @property
    def p(self) -> list[float]:
        return [self.msg.param1, self.msg.param2, self.msg.param3, self.msg.param4]

    @property
    def p7(self) -> float:
        return float(self.msg.z) if self.is_int else float(self.msg.param7)


class AutopilotHost(Protocol):
    """What the MAVLink server reads and acts on: the vehicle's parts, its clock and links, and three services."""

    config: SitlConfig
    clock: SimClock
    params: ParameterStore
    dynamics: Dynamics
    commander: Commander
    controller: CascadedController
    telemetry: TelemetryBuilder
    battery: Battery
    links: list[MavlinkLink]
    schedules: dict[int, StreamSchedule]
    """Each link's telemetry schedule, by the link's ``id()``."""
    lockstep: LockstepGate
    actuators: ActuatorOutputs

    @property
    def ulog(self) -> FlightULog | None:
        """The flight's ULog, when the config asks for one (commands and parameter changes go in)."""
        ...

    def statustext(self, text: str, severity: Severity = Severity.INFO) -> None:
        """A STATUSTEXT on every link."""
        ...

    def heartbeat_now(self) -> None:
        """A heartbeat on every link at once."""
        ...

    def change_speed(self, speed_mps: float | None) -> None:
        """DO_CHANGE_SPEED: fly at most this horizontal speed from now on (None: the parameter's again)."""
        ...

    def refresh_limits(self) -> None:
        """The controller's limits again from the live parameters (after a change)."""
        ...


class CommandHandlers:
    """The command table of ``vehicle``: :meth:`handle` answers one command with its MAV_RESULT (UNSUPPORTED for one
    this autopilot does not act on)."""

    def __init__(self, vehicle: AutopilotHost) -> None:
        self.v = vehicle
        self._commands = self._table()

    def handle(self, request: CommandRequest) -> MavResult:
        """Act on one command; the message it asks for, if any, is left in ``request.follow_up``."""
        handler = self._commands.get(int(request.msg.command))
        return MavResult.UNSUPPORTED if handler is None else handler(request)

    def set_mode(self, base: int | None, main: int | None, sub: int | None) -> MavResult:
        """DO_SET_MODE / SET_MODE: DENIED when it names no mode at all, UNSUPPORTED (with a CRITICAL text, as PX4
        says it) for a PX4 mode this autopilot does not fly."""
        if base is None or main is None or sub is None:
            return MavResult.DENIED
        mode = FlightMode.from_px4(main, sub)
        if mode is None or not base & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            try:
                name = MainMode(main).name
            except ValueError:
                name = f"{main}.{sub}"
            self.v.statustext(f"Switching to mode {name} is not available in this SITL", Severity.CRITICAL)
            return MavResult.UNSUPPORTED
        return self.v.commander.set_mode(mode)

    def _table(self) -> dict[int, Callable[[CommandRequest], MavResult]]:
        """The commands this autopilot acts on, by MAV_CMD id."""
        request_message = self._request_message
        return {
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM: self._arm_disarm,
            mavlink.MAV_CMD_NAV_TAKEOFF: self._takeoff,
            mavlink.MAV_CMD_NAV_LAND: lambda r: self.v.commander.land(),
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda r: self.v.commander.return_to_launch(),
            mavlink.MAV_CMD_DO_SET_MODE: lambda r: self.set_mode(
                whole(r.p[0], 0, 255), whole(r.p[1], 0, 255), whole(r.p[2], 0, 255, nan_is=0)
            ),
            mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: self._set_message_interval,
            mavlink.MAV_CMD_GET_MESSAGE_INTERVAL: self._get_message_interval,
            mavlink.MAV_CMD_REQUEST_MESSAGE: request_message,
            mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: request_message,
            mavlink.MAV_CMD_GET_HOME_POSITION: request_message,
            MAV_CMD_REQUEST_PROTOCOL_VERSION: request_message,
            mavlink.MAV_CMD_DO_SET_HOME: self._set_home,
            mavlink.MAV_CMD_DO_REPOSITION: lambda r: self._reposition(r.msg, r.is_int),
            mavlink.MAV_CMD_DO_ORBIT: lambda r: self._orbit(r.msg, r.is_int),
            mavlink.MAV_CMD_MISSION_START: self._mission_start,
            mavlink.MAV_CMD_DO_SET_MISSION_CURRENT: self._set_mission_current,
            mavlink.MAV_CMD_DO_PAUSE_CONTINUE: self._pause_continue,
            mavlink.MAV_CMD_DO_CHANGE_SPEED: self._change_speed,
            mavlink.MAV_CMD_DO_SET_ACTUATOR: self._set_actuator,
        }

    # -- the commands ------------------------------------------------------------------------------------------------
    def _arm_disarm(self, r: CommandRequest) -> MavResult:
        cmd = self.v.commander
        force = whole(r.p[1], 0, 65535) == FORCE_MAGIC
        arm = whole(r.p[0], 0, 1)  # neither 0 (disarm) nor 1 (arm): malformed, do neither
        return MavResult.DENIED if arm is None else cmd.arm(force) if arm == 1 else cmd.disarm(force)

    def _takeoff(self, r: CommandRequest) -> MavResult:
        cmd = self.v.commander
        above_home = math.nan
        if math.isfinite(r.p7):
            above_home = r.p7 - (self.v.config.origin_alt_m - float(cmd.home_ned_m[2]))  # param7 is AMSL
        return cmd.takeoff(above_home)

    def _set_actuator(self, r: CommandRequest) -> MavResult:
        m = r.msg
        five_six = [float(m.x), float(m.y)] if r.is_int else [m.param5, m.param6]  # COMMAND_INT: x and y
        n, e, _ = (float(v) for v in self.v.dynamics.state().position_ned_m)
        return self.v.actuators.command([*r.p, *five_six], r.p7, self.v.clock.now_s, n, e)

    def _set_message_interval(self, r: CommandRequest) -> MavResult:
        msg_id = whole(r.p[0], 0, 0xFFFFFF)
        name = NAMES_BY_ID.get(msg_id) if msg_id is not None else None
        if msg_id is None or not math.isfinite(r.p[1]):
            return MavResult.DENIED
        if name is None or name in ONE_SHOT:
            return MavResult.UNSUPPORTED if msg_id != mavlink.MAVLINK_MSG_ID_HEARTBEAT else MavResult.ACCEPTED
        self.v.schedules[id(r.link)].set_interval(name, float(r.p[1]))
        return MavResult.ACCEPTED

    def _get_message_interval(self, r: CommandRequest) -> MavResult:
        msg_id = whole(r.p[0], 0, 0xFFFFFF)
        if msg_id is None:
            return MavResult.DENIED
        name = NAMES_BY_ID.get(msg_id)
        interval_us = 0  # not available
        if msg_id == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            interval_us = 1_000_000
        elif name is not None and name not in ONE_SHOT:
            interval_s = self.v.schedules[id(r.link)].intervals_s.get(name, math.inf)
            interval_us = round(interval_s * 1e6) if math.isfinite(interval_s) else -1
        r.link.send(r.link.mav.message_interval_encode(msg_id, interval_us))
        return MavResult.ACCEPTED

    def _request_message(self, r: CommandRequest) -> MavResult:
        """REQUEST_MESSAGE and the older requests of one message each: the message follows the ACK."""
        wanted = {
            mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: MESSAGE_IDS["AUTOPILOT_VERSION"],
            mavlink.MAV_CMD_GET_HOME_POSITION: MESSAGE_IDS["HOME_POSITION"],
            MAV_CMD_REQUEST_PROTOCOL_VERSION: MESSAGE_IDS["PROTOCOL_VERSION"],
        }.get(int(r.msg.command), whole(r.p[0], 0, 0xFFFFFF))
        name = NAMES_BY_ID.get(wanted) if wanted is not None else None
        if wanted is None:
            return MavResult.DENIED
        if name is not None and self.v.telemetry.can_build(name):
            r.follow_up = name
            return MavResult.ACCEPTED
        return MavResult.UNSUPPORTED

    def _set_home(self, r: CommandRequest) -> MavResult:
        cmd = self.v.commander
        if not math.isfinite(r.p[0]):
            return MavResult.DENIED
        if cmd.landed_state is LandedState.ON_GROUND and r.p[0] > 0.5:
            home = self.v.dynamics.state().position_ned_m.copy()
            home[2] = cmd.home_ned_m[2]
            cmd.home_ned_m = home
            return MavResult.ACCEPTED
        return MavResult.TEMPORARILY_REJECTED if r.p[0] > 0.5 else MavResult.DENIED

    def _mission_start(self, r: CommandRequest) -> MavResult:
        first = whole(r.p[0], 0, 65535, nan_is=0)
        return MavResult.DENIED if first is None else self.v.commander.navigator.start_mission(first)

    def _set_mission_current(self, r: CommandRequest) -> MavResult:
        navigator = self.v.commander.navigator
        seq = whole(r.p[0], -1, 65535)
        if seq is None:
            return MavResult.DENIED
        return navigator.set_mission_current(seq if seq >= 0 else navigator.mission_current)

    def _pause_continue(self, r: CommandRequest) -> MavResult:
        cmd = self.v.commander
        pause = whole(r.p[0], 0, 1)
        if pause is None:
            return MavResult.DENIED
        if pause == 0:
            return cmd.set_mode(FlightMode.AUTO_LOITER) if cmd.armed else MavResult.TEMPORARILY_REJECTED
        return cmd.set_mode(FlightMode.AUTO_MISSION)

    def _change_speed(self, r: CommandRequest) -> MavResult:
        """As PX4: the speed flown from now on, within MPC_XY_VEL_MAX; no parameter changes (-1: back to it)."""
        spec = self.v.params.spec("MPC_XY_VEL_MAX")
        if r.p[1] == -1:
            self.v.change_speed(None)
        elif math.isfinite(r.p[1]) and spec.minimum <= r.p[1] <= spec.maximum:
            self.v.change_speed(float(r.p[1]))
        else:
            self.v.refresh_limits()
            return MavResult.DENIED
        return MavResult.ACCEPTED

    def _global_target(self, msg: Any, is_int: bool) -> tuple[float, float, float] | None:
        """The NED point of a command's x/y/z (latitude, longitude, altitude): NaN where the command leaves the
        coordinate as it is (NaN, or 0/0 for the horizontal position); None when it is malformed."""
        if is_int:
            lat = float(msg.x) / 1e7 if msg.x != 0 or msg.y != 0 else math.nan
            lon = float(msg.y) / 1e7 if msg.x != 0 or msg.y != 0 else math.nan
            relative = int(msg.frame) in (
                mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            )
            alt = float(msg.z)
        else:
            lat, lon, alt, relative = float(msg.param5), float(msg.param6), float(msg.param7), False
            if lat == 0 and lon == 0:
                lat = lon = math.nan
        if math.isinf(lat) or math.isinf(lon) or math.isinf(alt) or (math.isnan(lat) != math.isnan(lon)):
            return None
        c = self.v.config
        north = east = down = math.nan
        if not math.isnan(lat):
            if not (-90 <= lat <= 90 and -180 <= lon <= 180):
                return None
            north, east, _ = geodetic_to_ned(lat, lon, 0.0, c.origin_lat_deg, c.origin_lon_deg, 0.0)
            if math.hypot(north, east) > MAX_DISTANCE_M:
                return None
        if not math.isnan(alt):
            down = float(self.v.commander.home_ned_m[2]) - alt if relative else c.origin_alt_m - alt
            if abs(down) > MAX_DISTANCE_M:
                return None
        return north, east, down

    def _reposition(self, msg: Any, is_int: bool) -> MavResult:
        """DO_REPOSITION (QGroundControl's "go to location" and "change altitude"): fly there in HOLD. Without the
        change-mode flag (param2 bit 0) only a vehicle already holding moves, as PX4 does."""
        target = self._global_target(msg, is_int)
        change_mode = whole(msg.param2, 0, 0xFFFFFFFF, nan_is=0)
        if target is None or math.isinf(msg.param4) or change_mode is None:
            return MavResult.DENIED
        if not change_mode & REPOSITION_CHANGE_MODE and self.v.commander.mode is not FlightMode.AUTO_LOITER:
            return MavResult.TEMPORARILY_REJECTED
        yaw = math.radians(float(msg.param4)) if math.isfinite(msg.param4) else math.nan
        return self.v.commander.navigator.reposition(np.array(target), yaw)

    def _orbit(self, msg: Any, is_int: bool) -> MavResult:
        """DO_ORBIT: radius (param1; negative: counter-clockwise), speed (param2), centre and altitude (here when
        NaN or 0/0)."""
        target = self._global_target(msg, is_int)
        radius, speed = float(msg.param1), float(msg.param2)
        if target is None or not math.isfinite(radius) or not 1.0 <= abs(radius) <= 1000.0:
            return MavResult.DENIED
        if math.isnan(speed):
            speed = 1.0
        if not math.isfinite(speed) or abs(speed) > self.v.params["MPC_XY_VEL_MAX"]:
            return MavResult.DENIED
        if radius < 0:
            radius, speed = -radius, -abs(speed)
        here = self.v.dynamics.state().position_ned_m
        north, east, down = (here[i] if math.isnan(v) else v for i, v in enumerate(target))
        return self.v.commander.navigator.start_orbit(Orbit(float(north), float(east), float(down), radius, speed))
