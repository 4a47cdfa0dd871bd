"""The harness control channel's socket: JSON datagrams on UDP, for what is not MAVLink.

The vocabulary (commands, events, the tick, and the checks of every request and field) is
``companion.vehicle.sim_control``, shared with the clients. A datagram that is not a request is answered with an
error event and counted in :attr:`ControlChannel.malformed`; one :meth:`ControlChannel.receive` reads at most
:data:`MAX_REQUESTS_PER_RECEIVE` datagrams, so a flood cannot starve the simulation loop.
"""

from __future__ import annotations

import json
import logging
import socket
from typing import Any

from companion.vehicle.sim_control import parse_request

MAX_REQUESTS_PER_RECEIVE = 256
MAX_REPLY_BYTES = 60_000  # one UDP datagram, with room to spare

logger = logging.getLogger(__name__)


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
