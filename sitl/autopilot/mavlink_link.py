"""One MAVLink 2 endpoint over UDP, as PX4 SITL runs them: bound locally, sending to a remote port.

Partner choice follows PX4's ``mavlink_receiver.cpp``: the link sends to ``remote`` (loopback by default) until a
peer speaks, then locks onto the first peer heard. A later sender at another address is served (its messages are
handled) but not followed, so a stray or hostile sender cannot steal the link; it is counted in
``LinkStats.stray_frames``. Two exceptions: the configured remote always takes the link back when it speaks (that is
where MAVSDK listens, and it hears every heartbeat even while another peer is the partner), and a partner silent for
:data:`PARTNER_SILENCE_S` of wall time gives way to the next sender (a ground station restarted on another port).

Several ground stations on one link: a sender that is not the partner but sends HEARTBEATs (a ground station or a
MAVLink router does; a stray or a fuzzer usually does not) becomes a listener, up to :data:`MAX_LISTENERS`, and gets
everything the link sends, as long as its heartbeats keep coming (:data:`PARTNER_SILENCE_S`). So a second ground
station sees the full telemetry and every answer, instead of the half it would get if the link followed the latest
sender, and it still cannot take the link from the partner.

Malformed packets (bad CRC, truncated, unknown ids) are dropped and counted, never raised. Each UDP datagram is parsed
on its own: a truncated frame is dropped with its datagram and cannot swallow the next one. One :meth:`receive` reads
at most :data:`MAX_DATAGRAMS_PER_RECEIVE` datagrams, so a flood cannot starve the loop that sends heartbeats.

MAVLink 2 signing: with a 32-byte key, outgoing frames are signed and incoming frames must carry a valid signature
with a fresh timestamp (replays are refused); unsigned and badly signed frames are dropped and counted in
``LinkStats.dropped_unsigned``. Without a key, signatures are ignored, as PX4 does with signing off.
"""

from __future__ import annotations

import errno
import logging
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from companion.errors import SlzError

logger = logging.getLogger(__name__)

MAX_DATAGRAMS_PER_RECEIVE = 256
MAX_DATAGRAM_BYTES = 1200  # a telemetry pass fills datagrams up to this size (PX4's UDP buffer is 1,500 bytes, the MTU)
PARTNER_SILENCE_S = 10.0  # wall seconds without a valid frame from the partner before another sender may take over
MAX_LISTENERS = 4  # ground stations beside the partner that get everything the link sends
MAX_SOURCES_TRACKED = 1024  # distinct (system, component) pairs counted per link; the rest share one counter
OTHER_SOURCE = (-1, -1)
SIGNING_EPOCH_UNIX_S = 1420070400  # 2015-01-01T00:00:00Z, MAVLink's signing timestamp origin


@dataclass
class LinkStats:
    """Counters of one link."""

    received: int = 0
    sent: int = 0
    dropped_malformed: int = 0
    dropped_unknown: int = 0
    dropped_unsigned: int = 0  # unsigned, badly signed or replayed, while signing is on
    stray_frames: int = 0  # valid frames from a sender that is not the link's partner
    per_source: dict[tuple[int, int], int] = field(default_factory=dict)

    def count_source(self, source: tuple[int, int]) -> None:
        """Count one message from ``source``; beyond MAX_SOURCES_TRACKED pairs they share OTHER_SOURCE."""
        if source not in self.per_source and len(self.per_source) >= MAX_SOURCES_TRACKED:
            source = OTHER_SOURCE
        self.per_source[source] = self.per_source.get(source, 0) + 1


def for_autopilot(msg: Any, system_id: int) -> bool:
    """``msg`` is addressed to the autopilot ``system_id`` (component 1) or broadcast (a missing target field, or 0,
    means everyone)."""
    return getattr(msg, "target_system", 0) in (0, system_id) and getattr(msg, "target_component", 0) in (0, 1)


class LinkError(SlzError):
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
    signing_key : bytes, optional
        32-byte MAVLink 2 signing key; None: no signing.
    """

    def __init__(
        self,
        name: str,
        bind_address: str,
        local_port: int,
        remote_port: int,
        system_id: int,
        component_id: int = 1,
        signing_key: bytes | None = None,
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
        self._configured_remote = self.remote
        self.peer_seen = False
        self._partner_heard_wall = -float("inf")
        self.listeners: dict[tuple[str, int], float] = {}  # address -> wall time of its last heartbeat
        self.cut = False  # a simulated link loss: nothing goes out, everything coming in is discarded
        self._mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._mav.robust_parsing = True
        if signing_key is not None:
            if len(signing_key) != 32:
                self._sock.close()
                raise LinkError(name, f"a signing key has 32 bytes, not {len(signing_key)}")
            signing = self._mav.signing
            signing.secret_key = signing_key
            signing.sign_outgoing = True
            signing.link_id = 0
            signing.timestamp = int((time.time() - SIGNING_EPOCH_UNIX_S) * 100_000)  # 10 us units, as MAVLink's
            signing.allow_unsigned_callback = lambda _mav, _msg_id: False  # counted in reject_count

    @property
    def signed(self) -> bool:
        """Signing is on."""
        return self._mav.signing.secret_key is not None

    @property
    def mav(self) -> mavlink.MAVLink:
        """The pymavlink codec (to build messages with ``*_encode``)."""
        return self._mav

    def fileno(self) -> int:
        """For select()."""
        return self._sock.fileno()

    def send(self, msg: Any) -> None:
        """Pack and send one message to the current partner; network errors are logged, not raised.

        A heartbeat also goes to the configured remote while the partner is elsewhere, so a client listening there
        (MAVSDK's ``udpin``, which speaks only once it has heard the vehicle) can always find it and take the link.
        """
        buf = self._pack(msg)
        if self.cut:
            return
        self._send_buffer(buf, msg.get_msgId() == mavlink.MAVLINK_MSG_ID_HEARTBEAT)

    def send_all(self, msgs: Sequence[Any]) -> None:
        """Pack and send ``msgs`` in order, as few datagrams as fit :data:`MAX_DATAGRAM_BYTES` (PX4 fills one UDP
        packet per pass the same way): the same frames, sequence numbers and order as one :meth:`send` each, in a
        fraction of the system calls. A receiver parses each datagram's frames one after the other, as MAVSDK,
        pymavlink and :meth:`receive` do. Heartbeats go through :meth:`send` (their extra destination)."""
        datagrams: list[tuple[bytes, int]] = []
        pending: list[bytes] = []
        size = 0
        for msg in msgs:
            buf = self._pack(msg)
            if pending and size + len(buf) > MAX_DATAGRAM_BYTES:
                datagrams.append((b"".join(pending), len(pending)))
                pending, size = [], 0
            pending.append(buf)
            size += len(buf)
        if pending:
            datagrams.append((b"".join(pending), len(pending)))
        if self.cut:
            return
        for datagram, frames in datagrams:
            self._send_buffer(datagram, heartbeat=False, frames=frames)

    def _pack(self, msg: Any) -> bytes:
        """``msg`` as this link's next frame (its sequence number taken, sent or not: a cut link numbers on)."""
        buf: bytes = msg.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        return buf

    def forward(self, msg: Any) -> bool:
        """Send a message received on another link as it came (its sender's ids and sequence), as PX4 forwards;
        not on a signed link, whose frames must carry this link's signature. Returns whether it went out."""
        if self.cut or self.signed:
            return False
        self._send_buffer(bytes(msg.get_msgbuf()), heartbeat=False)
        return True

    def _send_buffer(self, buf: bytes, heartbeat: bool, frames: int = 1) -> None:
        """``buf`` (``frames`` MAVLink frames) to the partner and every listener; ``stats.sent`` counts frames."""
        destinations = [self.remote]
        if self.remote != self._configured_remote and heartbeat:
            destinations.append(self._configured_remote)
        if self.listeners:
            now = time.monotonic()
            for addr, heard in list(self.listeners.items()):
                if now - heard > PARTNER_SILENCE_S:
                    del self.listeners[addr]
                elif addr not in destinations:
                    destinations.append(addr)
        for destination in destinations:
            try:
                self._sock.sendto(buf, destination)
                self.stats.sent += frames
            except OSError as exc:
                if exc.errno not in (errno.ECONNREFUSED, errno.EAGAIN, errno.ENOBUFS):
                    logger.warning("%s: send failed: %s", self.name, exc)

    def receive(self) -> list[tuple[Any, bool]]:
        """The messages waiting on the socket (at most MAX_DATAGRAMS_PER_RECEIVE datagrams' worth), malformed ones
        dropped and counted; each with whether it came from the partner or a listener (a peer the link talks to)
        rather than a stray sender."""
        tagged: list[tuple[Any, bool]] = []
        for _ in range(MAX_DATAGRAMS_PER_RECEIVE):
            try:
                data, addr = self._sock.recvfrom(65535)
            except BlockingIOError:
                break
            except OSError as exc:
                if exc.errno == errno.ECONNREFUSED:
                    continue
                raise
            if self.cut:
                continue
            out: list[Any] = []
            good = self._parse(data, out)
            if good:
                heartbeat = any(m.get_msgId() == mavlink.MAVLINK_MSG_ID_HEARTBEAT for m in out)
                peer = self._heard(addr[0], addr[1], good, heartbeat)
                tagged.extend((msg, peer) for msg in out)
        return tagged

    def _parse(self, data: bytes, out: list[Any]) -> int:
        """Parse one datagram into ``out``; returns how many good messages it held."""
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        parser.signing = self._mav.signing  # one signing state: keys, replay timestamps and counts across datagrams
        rejected_before = self._mav.signing.reject_count
        try:
            messages = parser.parse_buffer(data) or []
        except Exception:  # pymavlink raises assorted errors on garbage; drop and count
            self.stats.dropped_malformed += 1
            return 0
        unsigned = self._mav.signing.reject_count - rejected_before
        self.stats.dropped_unsigned += unsigned
        if parser.buf_len() > 0:  # a partial frame left over: the datagram was cut or padded with junk
            self.stats.dropped_malformed += 1
        good = 0
        for msg in messages:
            kind = msg.get_type()
            if kind == "BAD_DATA":
                if unsigned:  # pymavlink reports a refused signature as bad data: counted above
                    unsigned -= 1
                else:
                    self.stats.dropped_malformed += 1
            elif kind.startswith("UNKNOWN"):
                self.stats.dropped_unknown += 1
            else:
                out.append(msg)
                good += 1
                self.stats.count_source((msg.get_srcSystem(), msg.get_srcComponent()))
        self.stats.received += good
        return good

    def _heard(self, host: str, port: int, frames: int, heartbeat: bool) -> bool:
        """Valid frames came from ``host:port``: lock onto it, keep the partner, keep or add a listener, or count a
        stray sender. Returns whether the sender is a peer (partner or listener)."""
        addr = (host, port)
        now = time.monotonic()
        if addr == self.remote:
            self.peer_seen = True
            self._partner_heard_wall = now
            return True
        partner_gone = now - self._partner_heard_wall > PARTNER_SILENCE_S
        if addr == self._configured_remote or not self.peer_seen or partner_gone:
            logger.info("%s: partner at %s:%d", self.name, host, port)
            self.listeners.pop(addr, None)
            if self.peer_seen and self.remote != addr:
                self.listeners[self.remote] = self._partner_heard_wall  # the old partner keeps listening a while
            self.peer_seen = True
            self.remote = addr
            self._partner_heard_wall = now
            return True
        if addr in self.listeners:
            if heartbeat:
                self.listeners[addr] = now
            return True
        if heartbeat and len(self.listeners) < MAX_LISTENERS:
            logger.info("%s: another ground station at %s:%d listens too", self.name, host, port)
            self.listeners[addr] = now
            return True
        self.stats.stray_frames += frames
        return False

    def close(self) -> None:
        """Close the socket."""
        self._sock.close()
