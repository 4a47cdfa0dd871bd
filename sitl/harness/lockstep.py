"""The client side of the SITL's lockstep protocol (control channel): subscribe, wait for ticks, acknowledge.

An acknowledgement states how many MAVLink messages the client sent (from its system/component id) before it; the
SITL moves on only when it has received them all, so setpoints cannot be overtaken by the acknowledgement.
"""

from __future__ import annotations

import socket
from typing import Any

from companion.vehicle.sim_control import Command, Event, ack_counting, decode_event, encode
from sitl.config import CONTROL_PORT


class LockstepControl:
    """A UDP socket to one SITL instance's control channel."""

    def __init__(self, instance: int, system_id: int = 245, component_id: int = 190) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        self.address = ("127.0.0.1", CONTROL_PORT + instance)
        self.system_id = system_id
        self.component_id = component_id

    def subscribe(self) -> None:
        """Become the SITL's lockstep client (its next tick comes here)."""
        self._sock.sendto(encode(Command.LOCKSTEP_SUBSCRIBE), self.address)

    def next_tick(self, timeout_s: float = 10.0) -> dict[str, Any]:
        """The next ``{"event": "tick", "seq": k, "t_s": ...}`` (``TimeoutError`` after ``timeout_s``)."""
        self._sock.settimeout(timeout_s)
        while True:
            data, _ = self._sock.recvfrom(65535)
            event = decode_event(data)
            if event is not None and event["event"] == Event.TICK:
                return event

    def ack(self, seq: int, mavlink_sent: int) -> None:
        """Acknowledge tick ``seq`` after sending ``mavlink_sent`` MAVLink messages in all."""
        self._sock.sendto(ack_counting(seq, mavlink_sent, self.system_id, self.component_id), self.address)

    def release(self) -> None:
        """Leave the lockstep: the SITL runs free from here."""
        self._sock.sendto(encode(Command.LOCKSTEP_RELEASE), self.address)

    def close(self) -> None:
        """Close the socket."""
        self._sock.close()
