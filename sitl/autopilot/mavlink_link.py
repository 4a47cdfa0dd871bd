"""One MAVLink 2 endpoint over UDP, as PX4 SITL runs them: bound locally, sending to a remote port.

Like PX4, it sends to ``remote`` (loopback by default) until a peer speaks, then answers wherever the peer's packets
come from. Malformed packets (bad CRC, truncated, unknown ids) are dropped and counted, never raised. Each UDP datagram
is parsed on its own: a truncated frame is dropped with its datagram and cannot swallow the next one.
"""

from __future__ import annotations

import errno
import logging
import socket
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

logger = logging.getLogger(__name__)


@dataclass
class LinkStats:
    """Counters of one link."""

    received: int = 0
    sent: int = 0
    dropped_malformed: int = 0
    dropped_unknown: int = 0
    per_source: dict[tuple[int, int], int] = field(default_factory=dict)


class LinkError(Exception):
    """A link could not be opened (e.g. the port is taken)."""

    def __init__(self, name: str, what: str) -> None:
        super().__init__(f"MAVLink link {name}: {what}")
        self.name = name


class MavlinkLink:
    """A UDP MAVLink endpoint.

    Parameters
    ----------
    name : str
        For logs (``"api"``, ``"gcs"``).
    bind_address : str
        Local address to bind (loopback unless told otherwise).
    local_port : int
        Local UDP port.
    remote_port : int
        Where to send before a peer has spoken (on ``bind_address``, or loopback if it binds all interfaces).
    system_id, component_id : int
        This autopilot's MAVLink identity.
    """

    def __init__(
        self, name: str, bind_address: str, local_port: int, remote_port: int, system_id: int, component_id: int = 1
    ) -> None:
        self.name = name
        self.stats = LinkStats()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        try:
            self._sock.bind((bind_address, local_port))
        except OSError as exc:
            self._sock.close()
            raise LinkError(name, f"cannot bind {bind_address}:{local_port}: {exc.strerror}") from None
        self._sock.setblocking(False)
        host = "127.0.0.1" if bind_address in ("", "0.0.0.0") else bind_address
        self.remote: tuple[str, int] = (host, remote_port)
        self.peer_seen = False
        self.cut = False  # a simulated link loss: nothing goes out, everything coming in is discarded
        self._mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._mav.robust_parsing = True

    @property
    def mav(self) -> mavlink.MAVLink:
        """The pymavlink codec (to build messages with ``*_encode``)."""
        return self._mav

    def fileno(self) -> int:
        """For select()."""
        return self._sock.fileno()

    def send(self, msg: Any) -> None:
        """Pack and send one message to the current remote; network errors are logged, not raised."""
        buf = msg.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        if self.cut:
            return
        try:
            self._sock.sendto(buf, self.remote)
            self.stats.sent += 1
        except OSError as exc:
            if exc.errno not in (errno.ECONNREFUSED, errno.EAGAIN, errno.ENOBUFS):
                logger.warning("%s: send failed: %s", self.name, exc)

    def receive(self) -> list[Any]:
        """Every message waiting on the socket, malformed ones dropped and counted."""
        out: list[Any] = []
        while True:
            try:
                data, addr = self._sock.recvfrom(65535)
            except BlockingIOError:
                return out
            except OSError as exc:
                if exc.errno == errno.ECONNREFUSED:
                    continue
                raise
            if self.cut:
                continue
            parser = mavlink.MAVLink(None)
            parser.robust_parsing = True
            try:
                messages = parser.parse_buffer(data) or []
            except Exception:  # pymavlink raises assorted errors on garbage; drop and count
                self.stats.dropped_malformed += 1
                continue
            if parser.buf_len() > 0:  # a partial frame left over: the datagram was cut or padded with junk
                self.stats.dropped_malformed += 1
            good = 0
            for msg in messages:
                kind = msg.get_type()
                if kind == "BAD_DATA":
                    self.stats.dropped_malformed += 1
                elif kind.startswith("UNKNOWN"):
                    self.stats.dropped_unknown += 1
                else:
                    out.append(msg)
                    good += 1
                    src = (msg.get_srcSystem(), msg.get_srcComponent())
                    self.stats.per_source[src] = self.stats.per_source.get(src, 0) + 1
            self.stats.received += good
            if good and (not self.peer_seen or addr != self.remote):
                if not self.peer_seen:
                    logger.info("%s: peer at %s:%d", self.name, addr[0], addr[1])
                self.peer_seen = True
                self.remote = (addr[0], addr[1])

    def close(self) -> None:
        """Close the socket."""
        self._sock.close()
