"""The companion's side of a simulator's lockstep: one tick per camera frame, acknowledged once it is handled.

A simulator in lockstep (the bundled SITL, ``slz sitl --lockstep``) stops its clock at every tick until the client
acknowledges it. Before a tick it has sent the tick's camera frame (``frame_seq``; None when the camera delivers
nothing) and the vehicle's pose stamped at the tick instant. The companion handles the frame, decides, sends its
commands and then acknowledges, saying what the simulator must have received first (the position setpoint it sent
while handling the tick): MAVSDK re-sends setpoints on its own thread, so the companion cannot count its messages,
and an acknowledgement must never overtake them. The result: the same seed gives the same flight at any speed.

On a real vehicle there is no lockstep and nothing here runs; the protocol is JSON over UDP on the simulator's
control port (``udp://127.0.0.1:4560``), spoken through :mod:`companion.vehicle.sim_control`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Callable
from typing import Any
from urllib.parse import urlparse

from companion.errors import SlzError
from companion.vehicle.sim_control import (
    Command,
    Event,
    Message,
    RequestError,
    SetpointNedYaw,
    Tick,
    ack_expecting,
    decode_event,
    encode,
    subscribe_request,
)

logger = logging.getLogger(__name__)


class LockstepError(SlzError):
    """The simulator's lockstep channel failed (what, and which channel)."""

    def __init__(self, url: str, what: str) -> None:
        super().__init__(f"{url}: {what}")
        self.url = url


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, queue: asyncio.Queue[Message]) -> None:
        self.queue = queue
        self.malformed = 0

    def datagram_received(self, data: bytes, addr: tuple[str | Any, int]) -> None:
        event = decode_event(data)
        if event is None:
            self.malformed += 1  # dropped and counted, never raised
            return
        self.queue.put_nowait(event)


class LockstepClient:
    """Subscribe to a simulator's ticks, wait for them, acknowledge them.

    Parameters
    ----------
    url : str
        ``udp://HOST:PORT`` of the simulator's control channel.
    tick_timeout_s : float
        Longest wall-clock wait for a tick or a reply.
    """

    def __init__(self, url: str, tick_timeout_s: float = 30.0) -> None:
        parsed = urlparse(url)
        if parsed.scheme != "udp" or not parsed.hostname or not parsed.port:
            raise LockstepError(url, "expected udp://HOST:PORT")
        self.url = url
        self.address = (parsed.hostname, parsed.port)
        self.tick_timeout_s = tick_timeout_s
        self.period_s = math.nan
        self._queue: asyncio.Queue[Message] = asyncio.Queue()
        self._transport: asyncio.DatagramTransport | None = None
        self._protocol: _Protocol | None = None

    async def open(self, frames: bool = True) -> bool:
        """Subscribe; True when the simulator steps with us, False when it runs free (it said so). ``frames`` False:
        the ticks come without camera frames until an acknowledgement asks for them."""
        loop = asyncio.get_running_loop()
        try:
            transport, protocol = await loop.create_datagram_endpoint(
                lambda: _Protocol(self._queue), local_addr=("127.0.0.1", 0)
            )
        except OSError as exc:
            raise LockstepError(self.url, f"cannot open a socket: {exc}") from None
        self._transport, self._protocol = transport, protocol
        try:  # an open that does not finish (no reply, cancelled) leaves no socket behind
            self._send(subscribe_request(1, frames))
            reply = await self._next(lambda e: e.get("id") == 1, "the reply to lockstep_subscribe")
        except BaseException:
            self.close()
            raise
        if reply.get("event") == Event.ERROR:
            logger.info("%s runs free (%s): no lockstep", self.url, reply.get("error"))
            self.close()
            return False
        period_s = reply.get("tick_period_s")
        self.period_s = float(period_s) if isinstance(period_s, (int, float)) else math.nan
        logger.info("lockstep with %s, tick %.3f s", self.url, self.period_s)
        return True

    def _send(self, request: bytes) -> None:
        if self._transport is None:
            raise LockstepError(self.url, "not open")
        self._transport.sendto(request, self.address)

    async def _next(self, wanted: Callable[[Message], bool], what: str) -> Message:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.tick_timeout_s
        while True:
            remaining = deadline - loop.time()
            if remaining <= 0:
                raise LockstepError(self.url, f"no {what} within {self.tick_timeout_s:g} s")
            try:
                event = await asyncio.wait_for(self._queue.get(), remaining)
            except asyncio.TimeoutError:
                continue
            if wanted(event):
                return event

    async def next_tick(self) -> Tick:
        """The next tick (raises :class:`LockstepError` after ``tick_timeout_s`` of silence)."""
        event = await self._next(lambda e: e.get("event") == Event.TICK, "tick")
        try:
            return Tick.from_event(event)
        except RequestError as exc:
            raise LockstepError(self.url, f"malformed tick: {exc}") from None

    def ack(self, tick: Tick, setpoint: SetpointNedYaw | None = None, frames: bool = True) -> None:
        """Let the simulator pass ``tick`` once it has received ``setpoint``, the position setpoint sent while handling
        the tick (None: nothing to wait for); ``frames``: whether the next tick should come with a camera frame."""
        self._send(ack_expecting(tick, setpoint, frames))

    def release(self) -> None:
        """Leave the lockstep: the simulator runs free from here (its own failsafes act without us)."""
        if self._transport is not None:
            with contextlib.suppress(OSError):
                self._send(encode(Command.LOCKSTEP_RELEASE))

    @property
    def malformed(self) -> int:
        """Datagrams that were not JSON objects (dropped)."""
        return 0 if self._protocol is None else self._protocol.malformed

    def close(self) -> None:
        """Close the socket (idempotent)."""
        if self._transport is not None:
            self._transport.close()
            self._transport = None
