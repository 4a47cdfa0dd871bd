"""The companion's command channel: landing commands from a ground station over MAVLink 2, signed.

A pilot watching the video sends ``COMMAND_LONG`` to the companion's own component (``MAV_COMP_ID_ONBOARD_COMPUTER``,
191, on the vehicle's system id) on a UDP port the companion listens on: from MAVProxy or pymavlink on the ground
directly, or through the autopilot's radio and a router on the companion (mavlink-router, MAVProxy ``--out``).

==========================  =======  ===================================================================
command                     number   what the companion does (:mod:`companion.guidance.landing`)
==========================  =======  ===================================================================
``MAV_CMD_DO_GO_AROUND``    191      climb back and search again (approach or descent)
``MAV_CMD_USER_1``          31010    reject the zone it flies to; choose another
``MAV_CMD_USER_2``          31011    land on the current target now (param1 = 1: even over a person seen)
``MAV_CMD_USER_3``          31012    the next fallback site not tried yet (guidance.fallback)
==========================  =======  ===================================================================

Each is answered with ``COMMAND_ACK``: ``IN_PROGRESS`` when taken (it is decided at the vehicle's next tick), then
``ACCEPTED`` or ``DENIED``, a denial with its reason as ``STATUSTEXT`` (MAVLink 2 chunks sharing an ``id`` when it is
longer than 50 characters, as QGroundControl and MAVSDK put them together). With a signing key every command must
carry a valid MAVLink 2 signature whose timestamp is newer than the last one of its stream (system, component, link id);
unsigned, badly signed or replayed commands are refused (``DENIED`` and the reason, signed) and counted. A datagram
that is not a frame the channel reads is dropped and counted, never a crash.
"""

from __future__ import annotations

import asyncio
import enum
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from companion.config import host_port
from companion.errors import SlzError
from companion.ground.mavlink_frames import (
    COMMAND_ACK,
    COMMAND_LONG,
    HEARTBEAT,
    STATUSTEXT,
    TIMESTAMP_UNITS_PER_S,
    Frame,
    FrameError,
    FrameHeader,
    pack,
    signing_timestamp,
    unpack,
)
from companion.ground.operator_commands import (
    COMMAND_OF_MAV_CMD,
    MAV_COMP_ID_ONBOARD_COMPUTER,
    OperatorCommand,
)
from companion.vehicle.statustext import statustext_chunks

logger = logging.getLogger(__name__)

MAV_SEVERITY_WARNING = 4
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
MAV_STATE_ACTIVE = 4
HEARTBEAT_PERIOD_S = 1.0
MAX_PEERS = 8


class AckResult(enum.IntEnum):
    """MAV_RESULT."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5


class CommandChannelError(SlzError):
    """The command channel cannot listen (its URL, what failed)."""

    def __init__(self, url: str, what: str) -> None:
        super().__init__(f"ground-station command channel {url}: {what}")
        self.url = url


@dataclass(frozen=True)
class RefusedCommand:
    """A command the channel did not take, for the flight log: its MAV_CMD, who sent it and from where, how it was
    answered (None: not at all, it was addressed to another vehicle) and why."""

    mav_cmd: int
    sender: tuple[int, int]
    address: tuple[str, int]
    result: AckResult | None
    reason: str
    signed: bool


@dataclass(frozen=True)
class GroundCommand:
    """One command taken: what, its MAV_CMD number, forced (param1 = 1 of a land-now), who sent it and from where."""

    command: OperatorCommand
    mav_cmd: int
    force: bool
    sender: tuple[int, int]
    address: tuple[str, int]
    signed: bool


@dataclass
class ChannelCounts:
    """What the channel dropped or refused, by why."""

    malformed: int = 0
    not_for_us: int = 0
    unsigned: int = 0
    bad_signature: int = 0
    replayed: int = 0
    unsupported: int = 0
    taken: int = 0


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, on_datagram: Callable[[bytes, tuple[str, int]], None]) -> None:
        self.on_datagram = on_datagram

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.on_datagram(data, (str(addr[0]), int(addr[1])))


class CommandChannel:
    """The UDP endpoint (see the module docstring).

    Parameters
    ----------
    url : str
        ``udpin://HOST:PORT`` to listen on.
    system_id : int
        The vehicle's system id: commands must target it (and component 191); replies come from it.
    key : bytes or None
        The 32-byte signing key (None: commands are taken unsigned).
    stale_signature_s : float
        A signed stream seen first with a timestamp older than this is refused.
    wall_clock : callable
        Unix seconds, for the signing timestamps alone (MAVLink's signing runs on wall time; no decision does).
    """

    def __init__(
        self,
        url: str,
        system_id: int,
        key: bytes | None = None,
        stale_signature_s: float = 60.0,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        try:
            self.host, self.port = host_port(url, "udpin")
        except ValueError as exc:
            raise CommandChannelError(url, str(exc)) from None
        self.url = url
        self.system_id, self.key, self.stale_signature_s = system_id, key, stale_signature_s
        self.wall_clock = wall_clock
        self.counts = ChannelCounts()
        self._taken: list[GroundCommand] = []
        self._refused: list[RefusedCommand] = []
        self._transport: asyncio.DatagramTransport | None = None
        self._seq = 0
        self._text_id = 0
        self._last_stamp: dict[tuple[int, int, int], int] = {}  # per signed stream: its newest timestamp
        self._own_stamp = 0
        self.peers: list[tuple[str, int]] = []
        """Where frames came from (the newest last, at most ``MAX_PEERS``): the heartbeat goes there."""
        self._heartbeat: asyncio.Task[None] | None = None

    async def open(self) -> None:
        """Listen (a port in use is a :class:`CommandChannelError`)."""
        loop = asyncio.get_running_loop()
        try:
            transport, _ = await loop.create_datagram_endpoint(
                lambda: _Protocol(self._received), local_addr=(self.host, self.port)
            )
        except OSError as exc:
            raise CommandChannelError(self.url, f"cannot listen: {exc}") from None
        self._transport = transport
        self._heartbeat = asyncio.create_task(self._beat(), name="ground-heartbeat")
        logger.info("ground-station commands on %s (%s)", self.url, "signed" if self.key else "unsigned")

    def close(self) -> None:
        """Stop listening (idempotent)."""
        if self._heartbeat is not None:
            self._heartbeat.cancel()
            self._heartbeat = None
        if self._transport is not None:
            self._transport.close()
            self._transport = None

    def pending(self) -> list[GroundCommand]:
        """The commands taken and not yet handed out, oldest first (taken from the channel)."""
        taken, self._taken = self._taken, []
        return taken

    def refused(self) -> list[RefusedCommand]:
        """The commands refused (or addressed to another vehicle) since the last call, oldest first."""
        refused, self._refused = self._refused, []
        return refused

    # -- receiving ---------------------------------------------------------------------------------------------------
    def _received(self, data: bytes, address: tuple[str, int]) -> None:
        try:
            frame = unpack(data, self.key)
        except FrameError as exc:
            self.counts.malformed += 1
            logger.debug("dropped a datagram from %s: %s", address, exc)
            return
        if address in self.peers:
            self.peers.remove(address)
        self.peers = [*self.peers, address][-MAX_PEERS:]
        if frame.msg_id != COMMAND_LONG.msg_id:
            return  # a heartbeat, a reply of another component: nothing to take
        fields = frame.fields
        mav_cmd = int(fields["command"])
        sender, signed = (frame.sys_id, frame.comp_id), frame.signature_ok is not None
        if fields["target_system"] != self.system_id or fields["target_component"] != MAV_COMP_ID_ONBOARD_COMPUTER:
            self.counts.not_for_us += 1
            if fields["target_component"] == MAV_COMP_ID_ONBOARD_COMPUTER:  # meant for a companion: say where it went
                target = int(fields["target_system"])
                reason = f"addressed to system {target}, this vehicle is system {self.system_id}: another vehicle's"
                logger.warning("command %d from %s %s", mav_cmd, address, reason)
                self._refused.append(RefusedCommand(mav_cmd, sender, address, None, reason, signed))
            return
        refusal = self._signature_refusal(frame)
        if refusal is not None:
            logger.warning("command %d from %s refused: %s", mav_cmd, address, refusal)
            self._reply(frame, address, mav_cmd, AckResult.DENIED, f"refused: {refusal}")
            self._refused.append(RefusedCommand(mav_cmd, sender, address, AckResult.DENIED, refusal, signed))
            return
        command = COMMAND_OF_MAV_CMD.get(mav_cmd)
        if command is None:
            self.counts.unsupported += 1
            reason = f"command {mav_cmd} is not supported"
            logger.warning("command %d from %s: %s", mav_cmd, address, reason)
            self._reply(frame, address, mav_cmd, AckResult.UNSUPPORTED, reason)
            self._refused.append(RefusedCommand(mav_cmd, sender, address, AckResult.UNSUPPORTED, reason, signed))
            return
        force = command is OperatorCommand.LAND_NOW and float(fields["param1"]) == 1.0
        taken = GroundCommand(command, mav_cmd, force, sender, address, frame.link_id is not None)
        self.counts.taken += 1
        self._reply(frame, address, mav_cmd, AckResult.IN_PROGRESS)
        self._taken.append(taken)

    def _signature_refusal(self, frame: Frame) -> str | None:
        """Why a command must be refused for its signature (None: it may be taken)."""
        if self.key is None:
            return None
        if frame.signature_ok is None:
            self.counts.unsigned += 1
            return "not signed"
        if not frame.signature_ok:
            self.counts.bad_signature += 1
            return "bad signature"
        if frame.link_id is None or frame.timestamp is None:  # a checked signature has both
            return "bad signature"
        stream = (frame.sys_id, frame.comp_id, frame.link_id)
        last = self._last_stamp.get(stream)
        now = max(self._own_stamp, signing_timestamp(self.wall_clock()))
        stale = frame.timestamp < now - int(self.stale_signature_s * TIMESTAMP_UNITS_PER_S)
        if (last is not None and frame.timestamp <= last) or (last is None and stale):
            self.counts.replayed += 1
            return "replayed or stale signature timestamp"
        self._last_stamp[stream] = frame.timestamp
        self._own_stamp = max(self._own_stamp, frame.timestamp)
        return None

    # -- replying ----------------------------------------------------------------------------------------------------
    def answer(self, command: GroundCommand, result: AckResult, text: str | None = None) -> None:
        """Answer a command taken: ``COMMAND_ACK`` with ``result``, and ``text`` (a denial's reason) as
        ``STATUSTEXT``."""
        self._send_ack(command.address, command.sender, command.mav_cmd, result, text)

    def _reply(self, frame: Frame, address: tuple[str, int], mav_cmd: int, result: AckResult, text: str = "") -> None:
        self._send_ack(address, (frame.sys_id, frame.comp_id), mav_cmd, result, text or None)

    def _send_ack(
        self, address: tuple[str, int], sender: tuple[int, int], mav_cmd: int, result: AckResult, text: str | None
    ) -> None:
        ack: dict[str, int | float | bytes] = {"command": mav_cmd, "result": int(result)}
        ack.update(target_system=sender[0], target_component=sender[1])
        self._send(address, pack(COMMAND_ACK, ack, **self._header()))
        if text:
            self._text_id = self._text_id % 0xFFFF + 1
            for chunk in statustext_chunks(text, MAV_SEVERITY_WARNING, self._text_id):
                status: dict[str, int | float | bytes] = {
                    "severity": chunk.severity,
                    "text": chunk.text.encode("ascii"),
                }
                status.update(id=chunk.id, chunk_seq=chunk.chunk_seq)
                self._send(address, pack(STATUSTEXT, status, **self._header()))

    async def _beat(self) -> None:
        """A ``HEARTBEAT`` once a second to every peer heard from, as every MAVLink component sends (a ground station
        then shows the companion's component; wall time: a transport's period, no decision reads it)."""
        beat: dict[str, int | float | bytes] = {"type": MAV_TYPE_ONBOARD_CONTROLLER, "autopilot": MAV_AUTOPILOT_INVALID}
        beat.update(system_status=MAV_STATE_ACTIVE, mavlink_version=3)
        while True:
            for peer in self.peers:
                self._send(peer, pack(HEARTBEAT, beat, **self._header()))
            await asyncio.sleep(HEARTBEAT_PERIOD_S)

    def _header(self) -> FrameHeader:
        self._seq = (self._seq + 1) & 0xFF
        header: FrameHeader = {"seq": self._seq, "sys_id": self.system_id, "comp_id": MAV_COMP_ID_ONBOARD_COMPUTER}
        if self.key is not None:
            self._own_stamp = max(self._own_stamp + 1, signing_timestamp(self.wall_clock()))
            header["key"], header["link_id"], header["timestamp"] = self.key, 0, self._own_stamp
        return header

    def _send(self, address: tuple[str, int], frame: bytes) -> None:
        if self._transport is not None:
            self._transport.sendto(frame, address)
