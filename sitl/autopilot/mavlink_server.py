"""The autopilot's MAVLink server: what the SITL does with each message it receives (commands with their ACKs,
offboard setpoints, parameters, SET_MODE, TIMESYNC), and the counters a test or a lockstep acknowledgement reads.

Every field that came over the wire is checked before use: a command parameter that must be a whole number and is
NaN, infinite or fractional is DENIED (:func:`whole`), a setpoint field the type mask uses must be finite and in
range. The vehicle (:class:`sitl.vehicle.SitlVehicle`) owns the state; this server acts on it.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from sitl.autopilot.commander import FORCE_MAGIC, LandedState, MavResult
from sitl.autopilot.mavlink_link import MavlinkLink
from sitl.autopilot.modes import FlightMode
from sitl.autopilot.params import ParamError, decode_value, encode_value
from sitl.autopilot.telemetry import MESSAGE_IDS, NAMES_BY_ID
from sitl.control_requests import count_capped

if TYPE_CHECKING:
    from sitl.vehicle import SitlVehicle

logger = logging.getLogger(__name__)

# SET_POSITION_TARGET_LOCAL_NED type_mask bits
IGNORE_PX, IGNORE_PY, IGNORE_PZ = 1, 2, 4
IGNORE_VX, IGNORE_VY, IGNORE_VZ = 8, 16, 32
IGNORE_YAW = 1024


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


class MavlinkServer:
    """The MAVLink requests of ``vehicle`` (see the module docstring)."""

    def __init__(self, vehicle: SitlVehicle) -> None:
        self.v = vehicle
        self.setpoints_rejected = 0
        self.commands_by_sender: dict[str, int] = {}
        self.setpoints_by_sender: dict[str, int] = {}
        self.last_setpoint_ned: tuple[float, float, float, float] | None = None  # any sender: n, e, d, yaw (rad)
        self.commands_seen: dict[int, int] = {}  # command id -> how many received
        self._last_reject_text_s = -math.inf

    def _targets_us(self, msg: Any) -> bool:
        target = getattr(msg, "target_system", 0)
        return target in (0, self.v.config.system_id)

    def handle(self, link: MavlinkLink, msg: Any) -> None:
        """One message received on ``link``: commands, setpoints, parameters, modes, timesync."""
        kind = msg.get_type()
        sender = f"{msg.get_srcSystem()}/{msg.get_srcComponent()}"
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            if self._targets_us(msg) and getattr(msg, "target_component", 0) in (0, 1):
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
                mode = FlightMode.from_custom_mode(int(msg.custom_mode))
                if mode is not None:
                    self.v.commander.set_mode(mode)
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            link.send(link.mav.timesync_encode(int(self.v.clock.now_s * 1e9), msg.ts1))

    def _send_ack(self, link: MavlinkLink, msg: Any, result: MavResult) -> None:
        link.send(
            link.mav.command_ack_encode(msg.command, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent())
        )

    def _handle_command(self, link: MavlinkLink, msg: Any, is_int: bool) -> None:
        cmd = self.v.commander
        c = int(msg.command)
        p = [msg.param1, msg.param2, msg.param3, msg.param4]
        p7 = float(msg.z) if is_int else float(msg.param7)
        result = MavResult.UNSUPPORTED
        follow_up: str | None = None
        if c == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            force = whole(p[1], 0, 65535) == FORCE_MAGIC
            arm = whole(p[0], 0, 1)  # neither 0 (disarm) nor 1 (arm): malformed, do neither
            result = MavResult.DENIED if arm is None else cmd.arm(force) if arm == 1 else cmd.disarm(force)
        elif c == mavlink.MAV_CMD_NAV_TAKEOFF:
            above_home = math.nan
            if math.isfinite(p7):
                above_home = p7 - (self.v.config.origin_alt_m - float(cmd.home_ned_m[2]))  # param7 is AMSL
            result = cmd.takeoff(above_home)
        elif c == mavlink.MAV_CMD_NAV_LAND:
            result = cmd.land()
        elif c == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            result = cmd.return_to_launch()
        elif c == mavlink.MAV_CMD_DO_SET_MODE:
            base, main, sub = whole(p[0], 0, 255), whole(p[1], 0, 255), whole(p[2], 0, 255, nan_is=0)
            mode = FlightMode.from_px4(main, sub) if main is not None and sub is not None else None
            if base is None or main is None:
                result = MavResult.DENIED  # not a mode at all
            elif mode is None or not base & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                result = MavResult.UNSUPPORTED
            else:
                result = cmd.set_mode(mode)
        elif c == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            msg_id = whole(p[0], 0, 0xFFFFFF)
            name = NAMES_BY_ID.get(msg_id) if msg_id is not None else None
            if msg_id is None or not math.isfinite(p[1]):
                result = MavResult.DENIED
            elif name is None or name == "AUTOPILOT_VERSION":
                result = MavResult.UNSUPPORTED if msg_id != mavlink.MAVLINK_MSG_ID_HEARTBEAT else MavResult.ACCEPTED
            else:
                self.v.schedules[id(link)].set_interval(name, float(p[1]))
                result = MavResult.ACCEPTED
        elif c in (mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            capabilities = MESSAGE_IDS["AUTOPILOT_VERSION"]
            wanted = whole(p[0], 0, 0xFFFFFF) if c == mavlink.MAV_CMD_REQUEST_MESSAGE else capabilities
            name = NAMES_BY_ID.get(wanted) if wanted is not None else None
            if wanted is None:
                result = MavResult.DENIED
            elif name is not None and self.v.telemetry.can_build(name):
                result, follow_up = MavResult.ACCEPTED, name
        elif c == mavlink.MAV_CMD_DO_SET_HOME:
            if not math.isfinite(p[0]):
                result = MavResult.DENIED
            elif cmd.landed_state is LandedState.ON_GROUND and p[0] > 0.5:
                home = self.v.dynamics.state().position_ned_m.copy()
                home[2] = cmd.home_ned_m[2]
                cmd.home_ned_m = home
                result = MavResult.ACCEPTED
            else:
                result = MavResult.TEMPORARILY_REJECTED if p[0] > 0.5 else MavResult.DENIED
        elif c == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            spec = self.v.params.spec("MPC_XY_VEL_MAX")
            if math.isfinite(p[1]) and spec.minimum <= p[1] <= spec.maximum:
                self.v.params.set("MPC_XY_VEL_MAX", p[1])
                self.v.controller.limits = self.v.limits()
                result = MavResult.ACCEPTED
            else:
                result = MavResult.DENIED
        self._send_ack(link, msg, result)
        if follow_up is not None:
            link.send(
                self.v.telemetry.build(
                    follow_up, link.mav, self.v.clock.now_s, self.v.dynamics.state(), cmd, self.v.battery
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
            self.v.statustext(f"Setpoint rejected: {reason}")

    def _handle_param(self, link: MavlinkLink, msg: Any) -> None:
        names = self.v.params.names()
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            for name in names:
                self._send_param(link, name)
            return
        raw_id = msg.param_id
        name = raw_id.decode("ascii", "ignore") if isinstance(raw_id, bytes) else str(raw_id)
        name = name.rstrip("\x00")
        if kind == "PARAM_REQUEST_READ":
            if msg.param_index >= 0:
                if msg.param_index < len(names):
                    self._send_param(link, names[msg.param_index])
                return
            if name in names:
                self._send_param(link, name)
            return
        # PARAM_SET
        if name not in names:
            self.v.statustext(f"Unknown parameter {name}")
            return
        try:
            spec = self.v.params.spec(name)
            self.v.params.set(name, decode_value(spec, float(msg.param_value), int(msg.param_type)))
            self.v.controller.limits = self.v.limits()
        except ParamError as exc:
            self.v.statustext(str(exc))
        self._send_param(link, name)

    def _send_param(self, link: MavlinkLink, name: str) -> None:
        spec = self.v.params.spec(name)
        link.send(
            link.mav.param_value_encode(
                name.encode("ascii"),
                encode_value(spec, self.v.params[name]),
                int(spec.param_type),
                len(self.v.params.names()),
                self.v.params.index(name),
            )
        )
