"""The harness control channel: JSON datagrams on UDP, for what is not MAVLink.

A simulated pilot (mode switch, sticks, RC loss), wind, ground truth, lockstep ticks and acknowledgements, and a
clean shutdown. Requests are ``{"cmd": ...}``; replies and events are ``{"event": ...}`` sent to the requester.

Every datagram is checked before it is parsed and once more after: at most :data:`MAX_REQUEST_BYTES` bytes, nesting
at most :data:`MAX_REQUEST_DEPTH` deep, strict JSON (no ``NaN`` or ``Infinity``, no number that overflows to
infinity), an object with a string ``cmd``. A bad one is answered with an error event and counted in
:attr:`ControlChannel.malformed`; one :meth:`ControlChannel.receive` reads at most
:data:`MAX_REQUESTS_PER_RECEIVE` datagrams, so a flood cannot starve the simulation loop. The fields of each
command are checked by the vehicle with :func:`number`, :func:`flag` and :func:`whole_number`.
"""

from __future__ import annotations

import json
import logging
import math
import socket
from typing import Any

logger = logging.getLogger(__name__)

MAX_REQUEST_BYTES = 8192
MAX_REQUEST_DEPTH = 8
MAX_REQUESTS_PER_RECEIVE = 256
MAX_REPLY_BYTES = 60_000  # one UDP datagram, with room to spare


class RequestError(ValueError):
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


def parse_request(data: bytes) -> dict[str, Any]:
    """One datagram as a request; raises ValueError (with a short reason) when it is not one."""
    if len(data) > MAX_REQUEST_BYTES:
        raise ValueError(f"request of {len(data)} bytes, more than {MAX_REQUEST_BYTES}")
    if _depth(data) > MAX_REQUEST_DEPTH:
        raise ValueError(f"nested deeper than {MAX_REQUEST_DEPTH}")
    request = json.loads(data.decode("utf-8"), parse_constant=_no_constant, parse_float=_finite_float)
    if not isinstance(request, dict) or not isinstance(request.get("cmd"), str) or len(request["cmd"]) > 64:
        raise ValueError("expected an object with a string 'cmd'")
    return request


def number(request: dict[str, Any], key: str, low: float, high: float, default: float | None = None) -> float:
    """``request[key]`` as a finite number in [low, high] (``default`` when absent, if given)."""
    value = request.get(key, default)
    if value is None:
        raise RequestError(f"{key}: missing")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RequestError(f"{key}: expected a number, got {type(value).__name__}")
    if not math.isfinite(value) or not low <= value <= high:
        raise RequestError(f"{key}: must lie in [{low:g}, {high:g}]")
    return float(value)


def whole_number(request: dict[str, Any], key: str, low: int, high: int) -> int:
    """``request[key]`` as an integer in [low, high]."""
    value = request.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise RequestError(f"{key}: expected an integer")
    if not low <= value <= high:
        raise RequestError(f"{key}: must lie in [{low}, {high}]")
    return value


def flag(request: dict[str, Any], key: str) -> bool:
    """``request[key]`` as a JSON boolean (a string such as ``"false"`` is refused, not taken as true)."""
    value = request.get(key)
    if not isinstance(value, bool):
        raise RequestError(f"{key}: expected true or false")
    return value


def lockstep_ack(request: dict[str, Any]) -> dict[str, Any]:
    """A checked ``lockstep_ack``: ``seq`` and either ``expect`` (a setpoint of four numbers and/or command counts)
    or the client's own count of MAVLink messages (``mavlink_sent`` from ``sysid``/``compid``)."""
    seq = whole_number(request, "seq", 0, 1 << 53)
    expect = request.get("expect")
    if expect is None:
        return {
            "seq": seq,
            "mavlink_sent": whole_number(request, "mavlink_sent", 0, 1 << 53),
            "sysid": whole_number(request, "sysid", 0, 255),
            "compid": whole_number(request, "compid", 0, 255),
        }
    if not isinstance(expect, dict) or not set(expect) <= {"setpoint", "commands"}:
        raise RequestError("expect: expected an object with 'setpoint' and/or 'commands'")
    checked: dict[str, Any] = {}
    setpoint = expect.get("setpoint")
    if setpoint is not None:
        if not isinstance(setpoint, list) or len(setpoint) != 4:
            raise RequestError("expect.setpoint: expected [north_m, east_m, down_m, yaw_rad]")
        values = {f"expect.setpoint[{i}]": v for i, v in enumerate(setpoint)}
        checked["setpoint"] = [number(values, key, -1e7, 1e7) for key in values]
    commands = expect.get("commands")
    if commands is not None:
        if not isinstance(commands, dict) or len(commands) > 16:
            raise RequestError("expect.commands: expected an object of at most 16 command counts")
        counts: dict[int, int] = {}
        for key in commands:
            if not key.isdigit() or int(key) > 65535:
                raise RequestError("expect.commands: keys are MAV_CMD ids")
            counts[int(key)] = whole_number(commands, key, 0, 1 << 31)
        checked["commands"] = counts
    return {"seq": seq, "expect": checked}


class ControlChannel:
    """Bound UDP socket with JSON framing; malformed requests are answered with an error event."""

    def __init__(self, bind_address: str, port: int) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((bind_address, port))
        self._sock.setblocking(False)
        self.malformed = 0

    def fileno(self) -> int:
        """For select()."""
        return self._sock.fileno()

    def receive(self) -> list[tuple[dict[str, Any], tuple[str, int]]]:
        """The requests waiting (at most MAX_REQUESTS_PER_RECEIVE datagrams), each with its sender."""
        out: list[tuple[dict[str, Any], tuple[str, int]]] = []
        for _ in range(MAX_REQUESTS_PER_RECEIVE):
            try:
                data, addr = self._sock.recvfrom(65535)
            except BlockingIOError:
                break
            except ConnectionRefusedError:
                continue
            try:
                request = parse_request(data)
            except (ValueError, UnicodeDecodeError, RecursionError) as exc:
                self.malformed += 1
                self.send({"event": "error", "error": f"malformed request: {str(exc)[:120]}"}, addr)
                continue
            out.append((request, addr))
        return out

    def send(self, event: dict[str, Any], addr: tuple[str, int]) -> None:
        """Send one event; a vanished peer is not an error. A reply too big for a datagram is replaced by an error."""
        data = json.dumps(event).encode("utf-8")
        if len(data) > MAX_REPLY_BYTES:
            logger.warning("control: a %s reply of %d bytes was not sent", event.get("event"), len(data))
            data = json.dumps({"event": "error", "error": f"reply of {len(data)} bytes too large"}).encode("utf-8")
        try:
            self._sock.sendto(data, addr)
        except OSError as exc:
            logger.debug("control: cannot send to %s: %s", addr, exc)

    def close(self) -> None:
        """Close the socket."""
        self._sock.close()
