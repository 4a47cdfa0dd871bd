"""The SITL control channel's vocabulary: one protocol module for the simulator and all of its clients.

The control channel is JSON over UDP beside MAVLink, for what MAVLink does not carry: lockstep ticks and their
acknowledgements, a simulated pilot (mode switch, sticks, RC loss), injected faults, wind, ground truth and shutdown.
A request is ``{"cmd": <Command>, ...fields}`` (with an optional ``"id"`` the reply echoes); a reply or an
unsolicited event is ``{"event": <Event>, ...}``. The SITL (``sitl.vehicle.control_channel``,
``sitl.vehicle.process``), its process wrapper and lockstep client (``sitl.harness.process``,
``sitl.harness.lockstep``) and the companion's lockstep client (``companion.vehicle.lockstep``) all speak it
through this module, which lives in ``companion`` because the companion is one of its clients and must not import
the lab.

Requests are checked here before use: at most :data:`MAX_REQUEST_BYTES` bytes, nesting at most
:data:`MAX_REQUEST_DEPTH` deep, strict JSON (no ``NaN`` or ``Infinity``, no number that overflows to infinity), an
object with a string ``cmd``; each field with :func:`number`, :func:`flag`, :func:`whole_number` and
:func:`lockstep_ack`, which raise :class:`RequestError` naming the field.
"""

from __future__ import annotations

import enum
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from companion.errors import SlzError
from companion.json_value import JsonObject, JsonValue


class Command(str, enum.Enum):
    """Requests the SITL answers."""

    PING = "ping"
    STATE = "state"
    PILOT_MODE = "pilot_mode"
    PILOT_STICKS = "pilot_sticks"
    RC_LOSS = "rc_loss"
    WIND = "wind"
    LOCKSTEP_SUBSCRIBE = "lockstep_subscribe"
    LOCKSTEP_ACK = "lockstep_ack"
    LOCKSTEP_RELEASE = "lockstep_release"
    CAMERA_FAIL = "camera_fail"
    LINK_LOSS = "link_loss"
    PEOPLE = "people"
    PLACE_PERSON = "place_person"
    SHUTDOWN = "shutdown"


class Event(str, enum.Enum):
    """What the SITL sends: replies and the lockstep tick."""

    ACK = "ack"
    ERROR = "error"
    PONG = "pong"
    STATE = "state"
    PEOPLE = "people"
    TICK = "tick"


Message = JsonObject
"""A request, a reply or an event: a JSON object."""


def encode(command: Command, **fields: JsonValue) -> bytes:
    """One request datagram."""
    return json.dumps({"cmd": command.value, **fields}).encode("utf-8")


def decode_event(data: bytes) -> Message | None:
    """A reply or event datagram as a mapping with a string ``event``; None for anything else (to be counted)."""
    try:
        event = json.loads(data)
    except (ValueError, UnicodeDecodeError, RecursionError):
        return None
    return event if isinstance(event, dict) and isinstance(event.get("event"), str) else None


@dataclass(frozen=True)
class Tick:
    """One lockstep tick: its number, the simulated time (s) and the frame sent before it (None: no frame)."""

    seq: int
    t_s: float
    frame_seq: int | None

    @classmethod
    def from_event(cls, event: Mapping[str, object]) -> Tick:
        """Parse a ``tick`` event (raises :class:`RequestError` naming a bad field)."""
        frame_seq = event.get("frame_seq")
        return cls(
            whole_number(event, "seq", 0, 1 << 53),
            number(event, "t_s", 0.0, 1e9),
            None if frame_seq is None else whole_number(event, "frame_seq", 0, 1 << 53),
        )

    def to_event(self) -> Message:
        """The ``tick`` event."""
        return {"event": Event.TICK.value, "seq": self.seq, "t_s": self.t_s, "frame_seq": self.frame_seq}


class SetpointNedYaw(NamedTuple):
    """A position setpoint in the one form both sides of the lockstep use: local NED north, east, down (m) and yaw
    (rad), as SET_POSITION_TARGET_LOCAL_NED carries it. The companion acknowledges a tick with the one it sent; the
    SITL latches the one that arrived and compares the two with :func:`same_setpoint`."""

    north_m: float
    east_m: float
    down_m: float
    yaw_rad: float


def same_setpoint(arrived: SetpointNedYaw | tuple[float, ...], wanted: SetpointNedYaw | list[float]) -> bool:
    """The setpoint that arrived is the one wanted: positions exactly as float32 (how they travel, so a late re-send
    of the previous setpoint, a millimetre away, is never taken for this one), the yaw within 1e-4 rad (the sender
    converts it from degrees in its own precision)."""
    wanted_ned = np.asarray(wanted[:3], dtype=np.float64).astype(np.float32)
    arrived_ned = np.asarray(arrived[:3], dtype=np.float64).astype(np.float32)
    return bool(np.array_equal(arrived_ned, wanted_ned)) and not abs(arrived[3] - float(wanted[3])) > 1e-4


def ack_expecting(tick: Tick, setpoint: SetpointNedYaw | None, frames: bool = True) -> bytes:
    """``lockstep_ack`` of a client that cannot count its MAVLink messages (MAVSDK re-sends on its own thread): the
    SITL moves on once the position setpoint it names has arrived (or at once, with None). ``frames``: whether the
    client wants a camera frame with the next tick (see :func:`lockstep_ack`)."""
    expect: Message = {}
    if setpoint is not None:
        expect["setpoint"] = [float(v) for v in setpoint]
    return encode(Command.LOCKSTEP_ACK, seq=tick.seq, expect=expect, **_frames_field(frames))


def subscribe_request(request_id: int, frames: bool = True) -> bytes:
    """``lockstep_subscribe``; ``frames`` False: no camera frame with the ticks until an acknowledgement asks for
    them again (a client that does not look at frames before its flight starts)."""
    return encode(Command.LOCKSTEP_SUBSCRIBE, id=request_id, **_frames_field(frames))


def _frames_field(frames: bool) -> dict[str, bool]:
    """The ``frames`` flag as a request carries it: only when False (absent means frames, as older clients send)."""
    return {} if frames else {"frames": False}


def frames_wanted(request: Mapping[str, object]) -> bool:
    """The optional ``frames`` flag of a ``lockstep_subscribe`` or ``lockstep_ack`` (absent: True)."""
    return True if "frames" not in request else flag(request, "frames")


def ack_counting(seq: int, mavlink_sent: int, system_id: int, component_id: int) -> bytes:
    """``lockstep_ack`` of a client that counts its MAVLink messages: the SITL moves on once it has received
    ``mavlink_sent`` from ``system_id``/``component_id``."""
    return encode(Command.LOCKSTEP_ACK, seq=seq, mavlink_sent=mavlink_sent, sysid=system_id, compid=component_id)


MAX_REQUEST_BYTES = 8192
MAX_REQUEST_DEPTH = 8


class RequestError(SlzError, ValueError):
    """A control request's field is missing or out of range (answered as an error event)."""


def _depth(data: bytes) -> int:
    """The deepest nesting of JSON arrays and objects in ``data`` (strings skipped), without parsing it."""
    depth = deepest = 0
    in_string = escaped = False
    for byte in data:
        if in_string:
            if escaped:
                escaped = False
            elif byte == 0x5C:  # backslash
                escaped = True
            elif byte == 0x22:  # quote
                in_string = False
        elif byte == 0x22:
            in_string = True
        elif byte in (0x5B, 0x7B):  # [ {
            depth += 1
            deepest = max(deepest, depth)
        elif byte in (0x5D, 0x7D):
            depth -= 1
    return deepest


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number here")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text[:20]} overflows")
    return value


def parse_request(data: bytes) -> Message:
    """One datagram as a request; raises ValueError (with a short reason) when it is not one."""
    if len(data) > MAX_REQUEST_BYTES:
        raise ValueError(f"request of {len(data)} bytes, more than {MAX_REQUEST_BYTES}")
    if _depth(data) > MAX_REQUEST_DEPTH:
        raise ValueError(f"nested deeper than {MAX_REQUEST_DEPTH}")
    request = json.loads(data.decode("utf-8"), parse_constant=_no_constant, parse_float=_finite_float)
    if not isinstance(request, dict) or not isinstance(request.get("cmd"), str) or len(request["cmd"]) > 64:
        raise ValueError("expected an object with a string 'cmd'")
    return request


def number(request: Mapping[str, object], key: str, low: float, high: float, default: float | None = None) -> float:
    """``request[key]`` as a finite number in [low, high] (``default`` when absent, if given)."""
    value = request.get(key, default)
    if value is None:
        raise RequestError(f"{key}: missing")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RequestError(f"{key}: expected a number, got {type(value).__name__}")
    if not math.isfinite(value) or not low <= value <= high:
        raise RequestError(f"{key}: must lie in [{low:g}, {high:g}]")
    return float(value)


def whole_number(request: Mapping[str, object], key: str, low: int, high: int) -> int:
    """``request[key]`` as an integer in [low, high]."""
    value = request.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise RequestError(f"{key}: expected an integer")
    if not low <= value <= high:
        raise RequestError(f"{key}: must lie in [{low}, {high}]")
    return value


def flag(request: Mapping[str, object], key: str) -> bool:
    """``request[key]`` as a JSON boolean (a string such as ``"false"`` is refused, not taken as true)."""
    value = request.get(key)
    if not isinstance(value, bool):
        raise RequestError(f"{key}: expected true or false")
    return value


@dataclass(frozen=True)
class LockstepAck:
    """A checked ``lockstep_ack`` (:func:`lockstep_ack`): the tick ``seq`` it acknowledges, whether the next tick
    comes with a camera frame, and what MAVLink must have arrived before the SITL moves on: the client's own count
    (``counted``: messages sent, from system and component) or what it expects (a setpoint and command counts; an
    ``expect`` with neither moves on at once)."""

    seq: int
    frames: bool = True
    counted: tuple[int, int, int] | None = None
    """``(mavlink_sent, sysid, compid)``; None: the ack says what it expects instead."""
    expect_setpoint: tuple[float, float, float, float] | None = None
    """[north_m, east_m, down_m, yaw_rad] that must have arrived (None: none)."""
    expect_commands: Mapping[int, int] | None = None
    """COMMAND_LONG/INT counts by MAV_CMD id that must have arrived (None: none)."""


def lockstep_ack(request: Mapping[str, object]) -> LockstepAck:
    """A checked ``lockstep_ack``: ``seq`` and either ``expect`` (a setpoint of four numbers and/or command counts)
    or the client's own count of MAVLink messages (``mavlink_sent`` from ``sysid``/``compid``); ``frames`` (optional,
    default true): whether the next tick comes with a camera frame. A frame skipped that way is not drawn, and its
    sequence number passes as if it had been (a frame's pixels depend on its instant and number only)."""
    seq = whole_number(request, "seq", 0, 1 << 53)
    frames = frames_wanted(request)
    expect = request.get("expect")
    if expect is None:
        sent = whole_number(request, "mavlink_sent", 0, 1 << 53)
        return LockstepAck(
            seq, frames, (sent, whole_number(request, "sysid", 0, 255), whole_number(request, "compid", 0, 255))
        )
    if not isinstance(expect, dict) or not set(expect) <= {"setpoint", "commands"}:
        raise RequestError("expect: expected an object with 'setpoint' and/or 'commands'")
    setpoint, checked_setpoint = expect.get("setpoint"), None
    if setpoint is not None:
        if not isinstance(setpoint, list) or len(setpoint) != 4:
            raise RequestError("expect.setpoint: expected [north_m, east_m, down_m, yaw_rad]")
        values = {f"expect.setpoint[{i}]": v for i, v in enumerate(setpoint)}
        n, e, d, yaw = (number(values, key, -1e7, 1e7) for key in values)
        checked_setpoint = (n, e, d, yaw)
    commands, counts = expect.get("commands"), None
    if commands is not None:
        if not isinstance(commands, dict) or len(commands) > 16:
            raise RequestError("expect.commands: expected an object of at most 16 command counts")
        counts = {}
        for key in commands:
            if not key.isdigit() or int(key) > 65535:
                raise RequestError("expect.commands: keys are MAV_CMD ids")
            counts[int(key)] = whole_number(commands, key, 0, 1 << 31)
    return LockstepAck(seq, frames, None, checked_setpoint, counts)
