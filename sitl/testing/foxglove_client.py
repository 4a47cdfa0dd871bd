"""A client of Foxglove's WebSocket protocol (``foxglove.sdk.v1``, earlier ``foxglove.websocket.v1``), as the app
is one: it reads the server's advertised channels, subscribes to them and counts what arrives per topic. Tests and
the live view's benchmark use it; ``stall`` makes a client that subscribes and then stops reading (a slow laptop on a
bad link).

The protocol: JSON text messages (``serverInfo``, ``advertise`` with each channel's id, topic, encoding and schema),
the client's ``subscribe`` (subscription ids of its choosing), then binary ``messageData`` frames: opcode 1, the
subscription id (uint32), the log time (uint64, ns) and the payload, little endian.
"""

from __future__ import annotations

import contextlib
import json
import struct
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

MESSAGE_DATA = 0x01


@dataclass
class Received:
    """What a client received on one topic."""

    schema_name: str
    encoding: str
    count: int = 0
    first: dict[str, Any] | None = None
    last_log_time_ns: int = 0
    log_times_ns: list[int] = field(default_factory=list)


class FoxgloveClient:
    """Connects to ``url`` (``ws://host:port``), subscribes to every channel advertised and reads on a thread.

    Parameters
    ----------
    url : str
        The server.
    connect_timeout_s : float
        How long to keep trying to connect (the server may still be starting).
    stall : bool
        Subscribe, then never read again.
    """

    def __init__(self, url: str, connect_timeout_s: float = 10.0, stall: bool = False) -> None:
        from websockets.sync.client import connect

        deadline = time.monotonic() + connect_timeout_s
        self._stack = contextlib.ExitStack()
        while True:
            try:
                protocols = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
                opened = connect(url, subprotocols=protocols, open_timeout=2.0, close_timeout=1.0, max_size=None)  # type: ignore[arg-type]
                self.ws = self._stack.enter_context(opened)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        self.stall = stall
        self.channels: dict[int, dict[str, Any]] = {}
        self.by_topic: dict[str, Received] = {}
        self.counts: Counter[str] = Counter()
        self.server_info: dict[str, Any] = {}
        self._subscriptions: dict[int, str] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _subscribe(self, channels: list[dict[str, Any]]) -> None:
        subscriptions = []
        for channel in channels:
            sub_id = len(self._subscriptions) + 1
            self._subscriptions[sub_id] = channel["topic"]
            self.by_topic[channel["topic"]] = Received(channel.get("schemaName", ""), channel.get("encoding", ""))
            subscriptions.append({"id": sub_id, "channelId": channel["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                message = self.ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except Exception:  # closed by the server or by close()
                return
            if isinstance(message, str):
                body = json.loads(message)
                op = body.get("op")
                if op == "serverInfo":
                    self.server_info = body
                elif op == "advertise":
                    with self._lock:
                        for channel in body["channels"]:
                            self.channels[channel["id"]] = channel
                        self._subscribe(body["channels"])
                    if self.stall:
                        return  # subscribed: never read again
                continue
            if message[0] != MESSAGE_DATA:
                continue
            sub_id, log_time_ns = struct.unpack_from("<IQ", message, 1)
            payload = message[13:]
            with self._lock:
                topic = self._subscriptions.get(sub_id)
                if topic is None:
                    continue
                got = self.by_topic[topic]
                got.count += 1
                got.last_log_time_ns = log_time_ns
                got.log_times_ns.append(log_time_ns)
                if got.first is None and got.encoding == "json":
                    got.first = json.loads(payload)
                self.counts[topic] += 1

    def received(self) -> dict[str, Received]:
        """A copy of what arrived so far, per topic."""
        with self._lock:
            return dict(self.by_topic)

    def close(self) -> None:
        """Disconnect."""
        self._stop.set()
        try:
            self._stack.close()
        finally:
            self._thread.join(timeout=5.0)
