"""The autopilot's MAVLink server: what the SITL does with each message it receives (commands with their ACKs,
offboard setpoints, parameters, SET_MODE, TIMESYNC), and the counters a test or a lockstep acknowledgement reads.

Every field that came over the wire is checked before use: a command parameter that must be a whole number and is
NaN, infinite or fractional is DENIED (:func:`whole`), a setpoint field the type mask uses must be finite and in
range. The vehicle owns the state and this server acts on it, seeing the vehicle through :class:`AutopilotHost` alone
(:class:`sitl.vehicle.SitlVehicle` is one), so it never imports the process that runs it.
"""

from __future__ import annotations

import logging
import math
import struct
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from sitl.autopilot.commander import FORCE_MAGIC, Commander
from sitl.autopilot.controller import CascadedController, ControllerLimits
from sitl.autopilot.ftp_server import FtpServer
from sitl.autopilot.mavlink_link import MavlinkLink, for_autopilot
from sitl.autopilot.mission_server import MAX_DISTANCE_M, MissionServer
from sitl.autopilot.modes import FlightMode, MainMode
from sitl.autopilot.navigator import Orbit
from sitl.autopilot.params import ParamError, ParameterStore, decode_value, encode_value
from sitl.autopilot.status import LandedState, MavResult, Severity
from sitl.autopilot.telemetry import MESSAGE_IDS, NAMES_BY_ID, ONE_SHOT, Battery, StreamSchedule, TelemetryBuilder
from sitl.clock import SimClock
from sitl.config import SitlConfig
from sitl.dynamics.base import Dynamics
from sitl.geodesy import geodetic_to_ned
from sitl.lockstep_gate import LockstepGate

logger = logging.getLogger(__name__)

# SET_POSITION_TARGET_LOCAL_NED type_mask bits
IGNORE_PX, IGNORE_PY, IGNORE_PZ = 1, 2, 4
IGNORE_VX, IGNORE_VY, IGNORE_VZ = 8, 16, 32
IGNORE_YAW = 1024
HASH_CHECK = "_HASH_CHECK"
PARAM_TYPE_UINT32 = 5  # how PX4 sends _HASH_CHECK
MAV_CMD_REQUEST_PROTOCOL_VERSION = 519
REPOSITION_CHANGE_MODE = 1  # DO_REPOSITION param2 bit: switch to the go-to mode
STICK_FULL = 1000.0  # MANUAL_CONTROL's full deflection
PARAM_RATE_HZ = 500.0  # a parameter list goes out paced (PX4 spreads it over the link's bandwidth): a ground
PARAM_BURST = 25  # station reading at its own pace must not lose half of it in a full receive buffer
MAX_SENDERS_REPORTED = 32  # per counter in the control channel's `state` reply, which must fit one datagram


def count_capped(counts: dict[str, int], key: str) -> None:
    """Count one for ``key``; past MAX_SENDERS_REPORTED keys, new ones share the key ``"other"``."""
    if key not in counts and len(counts) >= MAX_SENDERS_REPORTED:
        key = "other"
    counts[key] = counts.get(key, 0) + 1


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
    speed_mps: float | None
    """DO_CHANGE_SPEED's horizontal speed while it holds (None: the parameter's)."""

    def statustext(self, text: str, severity: Severity = Severity.INFO) -> None:
        """A STATUSTEXT on every link."""
        ...

    def heartbeat_now(self) -> None:
        """A heartbeat on every link at once."""
        ...

    def limits(self) -> ControllerLimits:
        """The controller's limits from the live parameters and ``speed_mps``."""
        ...


class MavlinkServer:
    """The MAVLink requests of ``vehicle`` (see the module docstring)."""

    def __init__(self, vehicle: AutopilotHost) -> None:
        self.v = vehicle
        self.setpoints_rejected = 0
        self.commands_by_sender: dict[str, int] = {}
        self.setpoints_by_sender: dict[str, int] = {}
        self.last_setpoint_ned: tuple[float, float, float, float] | None = None  # any sender: n, e, d, yaw (rad)
        self.commands_seen: dict[int, int] = {}  # command id -> how many received
        self._last_reject_text_s = -math.inf
        self.missions = MissionServer(
            vehicle.commander.navigator,
            vehicle.commander.set_fence,
            vehicle.config.system_id,
            vehicle.telemetry.origin,
            vehicle.statustext,
        )
        self.ftp = FtpServer()
        self._commands = self._command_table()
        self.forwarded = 0  # messages passed between the links (PX4's MAV_x_FORWARD)
        self._param_lists: dict[int, tuple[MavlinkLink, deque[str]]] = {}  # per link: the list still to send
        self._param_tokens = float(PARAM_BURST)
        self._param_tokens_wall_s = time.monotonic()

    def _targets_us(self, msg: Any) -> bool:
        target = getattr(msg, "target_system", 0)
        return target in (0, self.v.config.system_id)

    def handle(self, link: MavlinkLink, msg: Any, from_peer: bool = True) -> None:
        """One message received on ``link``: commands, setpoints, parameters, modes, missions, files, sticks,
        timesync; a message addressed to another system or component (the companion, a ground station) is passed to
        the other links, as PX4 forwards, when it came from a peer the link talks to (``from_peer``)."""
        kind = msg.get_type()
        if from_peer:
            self._forward(link, msg)
        sender = f"{msg.get_srcSystem()}/{msg.get_srcComponent()}"
        if self.missions.handle(link, msg):
            return
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            if for_autopilot(msg, self.v.config.system_id):
                count_capped(self.commands_by_sender, sender)
                self.commands_seen[int(msg.command)] = self.commands_seen.get(int(msg.command), 0) + 1
                self._handle_command(link, msg, kind == "COMMAND_INT")
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            if self._targets_us(msg):
                count_capped(self.setpoints_by_sender, sender)
                values = (float(msg.x), float(msg.y), float(msg.z), float(msg.yaw))
                gate = self.v.lockstep
                latched = gate.latched_setpoint
                if gate.between_ticks(self.v.clock.now_s) and latched is not None and values != latched:
                    # In lockstep, inputs change only at ticks: a late re-send of an older setpoint (MAVSDK re-sends
                    # on its own thread) must not act at a wall-clock-dependent instant.
                    gate.setpoints_between_ticks += 1
                    return
                self.last_setpoint_ned = values
                self._handle_setpoint(msg)
        elif kind in ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET"):
            if self._targets_us(msg):
                self._handle_param(link, msg)
        elif kind == "SET_MODE":
            if self._targets_us(msg):
                # As PX4: SET_MODE is turned into DO_SET_MODE, and answered as that command.
                main, sub = (int(msg.custom_mode) >> 16) & 0xFF, (int(msg.custom_mode) >> 24) & 0xFF
                result = self._set_mode(int(msg.base_mode), main, sub)
                link.send(
                    link.mav.command_ack_encode(
                        mavlink.MAV_CMD_DO_SET_MODE, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
                    )
                )
                if self.v.commander.changed:
                    self.v.heartbeat_now()
        elif kind == "MANUAL_CONTROL":
            if msg.target in (0, self.v.config.system_id):
                self._manual_control(msg)
        elif kind == "FILE_TRANSFER_PROTOCOL":
            if for_autopilot(msg, self.v.config.system_id):
                reply = self.ftp.handle(msg)
                if reply is not None:
                    peer = (msg.get_srcSystem(), msg.get_srcComponent())
                    link.send(link.mav.file_transfer_protocol_encode(0, *peer, reply))
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            link.send(link.mav.timesync_encode(int(self.v.clock.now_s * 1e9), msg.ts1))

    def _forward(self, link: MavlinkLink, msg: Any) -> None:
        """Pass ``msg`` to the other links unless it is addressed to this autopilot alone (PX4's
        ``forward_message``: broadcasts, messages to another system and to another component of ours go on)."""
        sysid = self.v.config.system_id
        if (msg.get_srcSystem(), msg.get_srcComponent()) == (sysid, 1):
            return
        if getattr(msg, "target_system", 0) == sysid and getattr(msg, "target_component", 0) == 1:
            return
        for other in self.v.links:
            if other is not link and other.forward(msg):
                self.forwarded += 1

    def _set_mode(self, base: int | None, main: int | None, sub: int | None) -> MavResult:
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

    def _manual_control(self, msg: Any) -> None:
        """A ground station's joystick (MANUAL_CONTROL, COM_RC_IN_MODE 1): sticks in POSCTL, body frame turned to
        NED by the heading; x forward, y right, z throttle 0..1000 (500 centred)."""
        values = (float(msg.x), float(msg.y), float(msg.z))
        if not all(math.isfinite(v) for v in values):
            return
        forward, right = (min(max(v / STICK_FULL, -1.0), 1.0) for v in values[:2])
        up = min(max((values[2] - STICK_FULL / 2) / (STICK_FULL / 2), -1.0), 1.0)
        deadband = 0.05
        forward, right, up = (0.0 if abs(v) < deadband else v for v in (forward, right, up))
        yaw = self.v.telemetry.euler(self.v.dynamics.state())[2]
        north = forward * math.cos(yaw) - right * math.sin(yaw)
        east = forward * math.sin(yaw) + right * math.cos(yaw)
        self.v.commander.pilot_sticks = np.array([north, east, -up])

    def _send_ack(self, link: MavlinkLink, msg: Any, result: MavResult) -> None:
        link.send(
            link.mav.command_ack_encode(msg.command, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent())
        )

    def _handle_command(self, link: MavlinkLink, msg: Any, is_int: bool) -> None:
        """A COMMAND_LONG or COMMAND_INT: its handler from the command table (UNSUPPORTED without one), the ACK, the
        message it asked for, and a heartbeat at once when the mode or arming changed."""
        cmd = self.v.commander
        request = CommandRequest(link, msg, is_int)
        handler = self._commands.get(int(msg.command))
        result = MavResult.UNSUPPORTED if handler is None else handler(request)
        self._send_ack(link, msg, result)
        if request.follow_up is not None:
            link.send(
                self.v.telemetry.build(
                    request.follow_up, link.mav, self.v.clock.now_s, self.v.dynamics.state(), cmd, self.v.battery
                )
            )
        if cmd.changed:
            self.v.heartbeat_now()  # let the client see the new mode/arming at once

    def _command_table(self) -> dict[int, Callable[[CommandRequest], MavResult]]:
        """The commands this autopilot acts on, by MAV_CMD id."""
        request_message = self._request_message
        return {
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM: self._arm_disarm,
            mavlink.MAV_CMD_NAV_TAKEOFF: self._takeoff,
            mavlink.MAV_CMD_NAV_LAND: lambda r: self.v.commander.land(),
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda r: self.v.commander.return_to_launch(),
            mavlink.MAV_CMD_DO_SET_MODE: lambda r: self._set_mode(
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
            self.v.speed_mps = None
            result = MavResult.ACCEPTED
        elif math.isfinite(r.p[1]) and spec.minimum <= r.p[1] <= spec.maximum:
            self.v.speed_mps = float(r.p[1])
            result = MavResult.ACCEPTED
        else:
            result = MavResult.DENIED
        self.v.controller.limits = self.v.limits()
        return result

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

    def _handle_setpoint(self, msg: Any) -> None:
        mask = int(msg.type_mask)
        if msg.coordinate_frame != mavlink.MAV_FRAME_LOCAL_NED:
            self._reject_setpoint(f"frame {msg.coordinate_frame} not supported (LOCAL_NED only)")
            return
        nan = math.nan
        pos = np.array(
            [
                nan if mask & IGNORE_PX else msg.x,
                nan if mask & IGNORE_PY else msg.y,
                nan if mask & IGNORE_PZ else msg.z,
            ],
            dtype=np.float64,
        )
        vel = np.array(
            [
                nan if mask & IGNORE_VX else msg.vx,
                nan if mask & IGNORE_VY else msg.vy,
                nan if mask & IGNORE_VZ else msg.vz,
            ],
            dtype=np.float64,
        )
        yaw = nan if mask & IGNORE_YAW else float(msg.yaw)
        # A field the mask says is used must hold a number: NaN there is malformed, as PX4 treats it.
        used_pos = [msg.x, msg.y, msg.z]
        used_vel = [msg.vx, msg.vy, msg.vz]
        for i, bit in enumerate((IGNORE_PX, IGNORE_PY, IGNORE_PZ)):
            if not mask & bit and not math.isfinite(used_pos[i]):
                self._reject_setpoint("non-finite position")
                return
        for i, bit in enumerate((IGNORE_VX, IGNORE_VY, IGNORE_VZ)):
            if not mask & bit and not math.isfinite(used_vel[i]):
                self._reject_setpoint("non-finite velocity")
                return
        if not mask & IGNORE_YAW and not math.isfinite(yaw):
            self._reject_setpoint("non-finite yaw")
            return
        ok, reason = self.v.commander.offboard_setpoint(pos, vel, yaw)
        if not ok:
            self._reject_setpoint(reason)

    def _reject_setpoint(self, reason: str) -> None:
        self.setpoints_rejected += 1
        if self.v.clock.now_s - self._last_reject_text_s >= 1.0:
            self._last_reject_text_s = self.v.clock.now_s
            logger.warning("offboard setpoint rejected: %s", reason)
            self.v.statustext(f"Setpoint rejected: {reason}", Severity.CRITICAL)

    def _handle_param(self, link: MavlinkLink, msg: Any) -> None:
        """PX4's parameter protocol: the list starts with ``_HASH_CHECK`` (a ground station with a matching cache
        stops there), a read by name or index, and PARAM_SET storing what PX4 stores (:meth:`ParameterStore.
        set_from_wire`), echoed on every link so that every parameter view stays current."""
        params = self.v.params
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            self._send_hash_check(link)
            self._param_lists[id(link)] = (link, deque(params.names()))  # a repeated request starts over
            self.pump()
            return
        raw_id = msg.param_id
        name = raw_id.decode("ascii", "ignore") if isinstance(raw_id, bytes) else str(raw_id)
        name = name.rstrip("\x00")
        if kind == "PARAM_REQUEST_READ":
            if msg.param_index >= 0:
                if msg.param_index < len(params):
                    self._send_param(link, params.names()[msg.param_index])
            elif name == HASH_CHECK:
                self._send_hash_check(link)
            elif name in params:
                self._send_param(link, name)
            return
        # PARAM_SET
        if name == HASH_CHECK:
            self._param_lists.pop(id(link), None)  # the ground station's cache is current: the rest is not needed
            return
        if name not in params:
            self.v.statustext(f"Unknown parameter {name}", Severity.CRITICAL)
            return
        try:
            spec = params.spec(name)
            if not params.set_from_wire(name, decode_value(spec, float(msg.param_value), int(msg.param_type))):
                self.v.statustext(
                    f"{name} = {params.raw(name):g} is outside [{spec.minimum:g}, {spec.maximum:g}]: "
                    f"flying with {params[name]:g}",
                    Severity.WARNING,
                )
            self.v.controller.limits = self.v.limits()
        except ParamError as exc:
            self.v.statustext(str(exc), Severity.CRITICAL)
        for each in self.v.links:
            self._send_param(each, name)

    def pump(self) -> None:
        """Send the next parameters of the lists in progress, at most :data:`PARAM_RATE_HZ` per wall second."""
        if not self._param_lists:
            return
        now = time.monotonic()
        self._param_tokens = min(PARAM_BURST, self._param_tokens + (now - self._param_tokens_wall_s) * PARAM_RATE_HZ)
        self._param_tokens_wall_s = now
        for key, (link, names) in list(self._param_lists.items()):
            while names and self._param_tokens >= 1.0:
                self._send_param(link, names.popleft())
                self._param_tokens -= 1.0
            if not names:
                del self._param_lists[key]

    def _send_param(self, link: MavlinkLink, name: str) -> None:
        params = self.v.params
        spec = params.spec(name)
        link.send(
            link.mav.param_value_encode(
                name.encode("ascii"),
                encode_value(spec, params.raw(name)),
                int(spec.param_type),
                len(params),
                params.index(name),
            )
        )

    def _send_hash_check(self, link: MavlinkLink) -> None:
        as_float = struct.unpack("<f", struct.pack("<I", self.v.params.hash_check()))[0]
        count = len(self.v.params)
        link.send(link.mav.param_value_encode(HASH_CHECK.encode(), as_float, PARAM_TYPE_UINT32, count, 0xFFFF))
