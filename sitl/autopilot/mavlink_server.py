"""The autopilot's MAVLink server: what the SITL does with each message it receives (commands with their ACKs,
offboard setpoints, parameters, SET_MODE, TIMESYNC), and the counters a test or a lockstep acknowledgement reads.

Every field that came over the wire is checked before use: a command parameter that must be a whole number and is NaN,
infinite or fractional is DENIED (:func:`sitl.autopilot.commands.whole`; the command table is
:mod:`sitl.autopilot.commands`), a setpoint field the type mask uses must be finite and in range. The vehicle owns the
state and this server acts on it, seeing the vehicle through :class:`AutopilotHost` alone
(:class:`sitl.vehicle.process.SitlVehicle` is one), so it never imports the process that runs it.
"""

from __future__ import annotations

import logging
import math
import struct
import time
from collections import deque
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from companion.vehicle.sim_control import SetpointNedYaw
from sitl.autopilot.commands import AutopilotHost, CommandHandlers, CommandRequest
from sitl.autopilot.ftp_server import FtpServer
from sitl.autopilot.mavlink_link import MavlinkLink, for_autopilot
from sitl.autopilot.mission_server import MissionServer
from sitl.autopilot.params import ParamError, decode_value, encode_value
from sitl.autopilot.status import MavResult, Severity
from sitl.autopilot.telemetry import euler
from sitl.px4_params import ParamType

logger = logging.getLogger(__name__)

# SET_POSITION_TARGET_LOCAL_NED type_mask bits
IGNORE_PX, IGNORE_PY, IGNORE_PZ = 1, 2, 4
IGNORE_VX, IGNORE_VY, IGNORE_VZ = 8, 16, 32
IGNORE_YAW = 1024
HASH_CHECK = "_HASH_CHECK"
PARAM_TYPE_UINT32 = 5  # how PX4 sends _HASH_CHECK
STICK_FULL = 1000.0  # MANUAL_CONTROL's full deflection
PARAM_RATE_HZ = 500.0  # a parameter list goes out paced (PX4 spreads it over the link's bandwidth): a ground
PARAM_BURST = 25  # station reading at its own pace must not lose half of it in a full receive buffer
MAX_SENDERS_REPORTED = 32  # per counter in the control channel's `state` reply, which must fit one datagram


def count_capped(counts: dict[str, int], key: str) -> None:
    """Count one for ``key``; past MAX_SENDERS_REPORTED keys, new ones share the key ``"other"``."""
    if key not in counts and len(counts) >= MAX_SENDERS_REPORTED:
        key = "other"
    counts[key] = counts.get(key, 0) + 1


class MavlinkServer:
    """The MAVLink requests of ``vehicle`` (see the module docstring)."""

    def __init__(self, vehicle: AutopilotHost) -> None:
        self.v = vehicle
        self.setpoints_rejected = 0
        self.commands_by_sender: dict[str, int] = {}
        self.setpoints_by_sender: dict[str, int] = {}
        self.last_setpoint_ned: SetpointNedYaw | None = None  # the latest position setpoint, any sender
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
        self.commands = CommandHandlers(vehicle)
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
                values = SetpointNedYaw(float(msg.x), float(msg.y), float(msg.z), float(msg.yaw))
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
                result = self.commands.set_mode(int(msg.base_mode), main, sub)
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
        yaw = euler(self.v.dynamics.state())[2]
        north = forward * math.cos(yaw) - right * math.sin(yaw)
        east = forward * math.sin(yaw) + right * math.cos(yaw)
        self.v.commander.set_pilot_sticks(north, east, -up)

    def _send_ack(self, link: MavlinkLink, msg: Any, result: MavResult) -> None:
        link.send(
            link.mav.command_ack_encode(msg.command, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent())
        )

    def _handle_command(self, link: MavlinkLink, msg: Any, is_int: bool) -> None:
        """A COMMAND_LONG or COMMAND_INT: its handler from the command table (UNSUPPORTED without one), the ACK, the
        message it asked for, and a heartbeat at once when the mode or arming changed."""
        cmd = self.v.commander
        request = CommandRequest(link, msg, is_int)
        result = self.commands.handle(request)
        if self.v.ulog is not None:
            self.v.ulog.command(self.v.clock.now_s, msg, int(result))
        self._send_ack(link, msg, result)
        if request.follow_up is not None:
            link.send(
                self.v.telemetry.build(
                    request.follow_up, link.mav, self.v.clock.now_s, self.v.dynamics.state(), cmd, self.v.battery
                )
            )
        if cmd.changed:
            self.v.heartbeat_now()  # let the client see the new mode/arming at once

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
            self.v.refresh_limits()
            if self.v.ulog is not None:
                self.v.ulog.parameter(name, params.raw(name), spec.param_type is ParamType.INT32)
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
