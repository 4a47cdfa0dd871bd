"""The harness control channel: JSON datagrams on UDP, for what is not MAVLink.

A simulated pilot (mode switch, sticks, RC loss), wind, ground truth, lockstep ticks and acknowledgements, and a
clean shutdown. Requests are ``{"cmd": ...}``; replies and events are ``{"event": ...}`` sent to the requester.
"""

from __future__ import annotations

import json
import logging
import socket
from typing import Any

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
        """Every request waiting, with its sender."""
        out: list[tuple[dict[str, Any], tuple[str, int]]] = []
        while True:
            try:
                data, addr = self._sock.recvfrom(65535)
            except BlockingIOError:
                return out
            except ConnectionRefusedError:
                continue
            try:
                request = json.loads(data.decode("utf-8"))
                if not isinstance(request, dict) or not isinstance(request.get("cmd"), str):
                    raise ValueError("expected an object with a string 'cmd'")
            except (ValueError, UnicodeDecodeError) as exc:
                self.malformed += 1
                self.send({"event": "error", "error": f"malformed request: {exc}"}, addr)
                continue
            out.append((request, addr))

    def send(self, event: dict[str, Any], addr: tuple[str, int]) -> None:
        """Send one event; a vanished peer is not an error."""
        try:
            self._sock.sendto(json.dumps(event).encode("utf-8"), addr)
        except OSError as exc:
            logger.debug("control: cannot send to %s: %s", addr, exc)

    def close(self) -> None:
        """Close the socket."""
        self._sock.close()
