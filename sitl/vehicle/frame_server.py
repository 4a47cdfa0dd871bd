"""The SITL camera's frame stream: a TCP server on loopback that never blocks the simulation.

One client at a time: while it is connected, a second connection is refused (closed at once, counted in
``FrameStats.refused``), so an intruder on the port cannot take the stream over; once the client has gone (its
end closed), the next connection is served (a restarted companion).

Outside lockstep a frame that finds the previous one still unsent is dropped and counted, so a slow or vanished
client cannot stall the SITL; in lockstep the caller flushes with a deadline instead (the client must have the frame
before it can acknowledge the tick).
"""

from __future__ import annotations

import errno
import logging
import socket
import time
from dataclasses import dataclass

logger = logging.getLogger(__name__)


@dataclass
class FrameStats:
    """Counters of the frame stream."""

    sent: int = 0
    dropped: int = 0
    clients: int = 0
    refused: int = 0  # connections turned away while a client was connected
    not_wanted: int = 0  # lockstep frames not drawn: the client asked for none (before its flight starts)


class FrameServer:
    """Listening socket plus the current client, all non-blocking."""

    def __init__(self, bind_address: str, port: int) -> None:
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind((bind_address, port))
        self._listener.listen(1)
        self._listener.setblocking(False)
        self._client: socket.socket | None = None
        self._pending = b""
        self.stats = FrameStats()

    def fileno(self) -> int:
        """For select(): readable when a client is connecting."""
        return self._listener.fileno()

    @property
    def connected(self) -> bool:
        """A client is connected."""
        return self._client is not None

    def poll(self) -> None:
        """Notice a client that left, accept a new one (or refuse it while one is served), push pending bytes."""
        self._check_client()
        while True:
            try:
                client, addr = self._listener.accept()
            except BlockingIOError:  # nobody is connecting
                break
            if self._client is not None:
                self.stats.refused += 1
                logger.warning("frame connection from %s:%d refused: a client is connected", *addr)
                client.close()
                continue
            client.setblocking(False)
            client.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 8 << 20)
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._client = client
            self._pending = b""
            self.stats.clients += 1
            logger.info("frame client connected from %s:%d", *addr)
        self._flush_some()

    def _check_client(self) -> None:
        """Drop the client once its end is closed (it never sends: anything it does send is discarded)."""
        if self._client is None:
            return
        try:
            for _ in range(16):
                data = self._client.recv(65536)
                if not data:  # end of stream: the client closed its end
                    logger.info("frame client gone")
                    self._drop_client()
                    return
        except BlockingIOError:
            return
        except OSError:
            logger.info("frame client gone")
            self._drop_client()

    def disconnect(self) -> None:
        """Close the client's connection (an injected fault); the next client is served."""
        if self._client is not None:
            logger.warning("frame client disconnected (injected)")
        self._drop_client()

    def _drop_client(self) -> None:
        if self._client is not None:
            self._client.close()
        self._client = None
        self._pending = b""

    def _flush_some(self) -> None:
        if self._client is None or not self._pending:
            return
        try:
            sent = self._client.send(self._pending)
            self._pending = self._pending[sent:]
        except BlockingIOError:
            return
        except OSError as exc:
            if exc.errno not in (errno.EPIPE, errno.ECONNRESET, errno.ENOTCONN):
                logger.warning("frame client error: %s", exc)
            logger.info("frame client gone")
            self._drop_client()

    def send(self, message: bytes) -> bool:
        """Queue one frame; False (and counted) if dropped: no client, or the previous frame is still unsent."""
        self.poll()
        if self._client is None or self._pending:
            self.stats.dropped += 1
            return False
        self._pending = message
        self._flush_some()
        self.stats.sent += 1
        return True

    def flush(self, deadline_s: float) -> bool:
        """Push everything queued, waiting at most until ``deadline_s`` (monotonic); True when all was sent."""
        while self._pending and self._client is not None:
            if time.monotonic() > deadline_s:
                return False
            self._flush_some()
            if self._pending and self._client is not None:
                import select

                select.select([], [self._client], [], 0.01)
        return not self._pending

    def close(self) -> None:
        """Close the client and the listener."""
        self._drop_client()
        self._listener.close()
