"""The flight live in Foxglove (``live_view`` in the mission config, ``slz fly --live-view PORT``): a server of
Foxglove's WebSocket protocol (the foxglove-sdk package, the ``live`` extra) on the companion, with the topics and
schemas of :mod:`companion.flightlog.foxglove_topics`, the same as ``slz export --mcap`` writes.

It never slows the flight: the flight's loop only queues a job (bounded by ``backlog_messages``; a full queue drops
the job) for the view's own thread, which builds the JSON and the JPEG; nothing is queued while no client is
connected, nor built for a topic no client subscribes to; the camera goes out at ``camera_rate_hz``; each client has
a bounded queue (``backlog_messages``) whose oldest message is dropped when a slow client falls behind (the SDK's
server, on its own threads); and a failure in the view is logged once and switches it off, never raised into the
flight. The decisions, phases, commands and events come from the flight
recorder's records as they are written (:meth:`LiveView.record`), the frames, the map, the zones and the pose from
each processed frame (:meth:`LiveView.frame`).
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import cv2

from companion.app.live_view_config import LiveViewConfig
from companion.errors import SlzError
from companion.flightlog.flight_log import RecordKind, kind_of
from companion.flightlog.foxglove_topics import (
    SCHEMAS,
    TOPICS,
    grid_message,
    image_message,
    messages_of,
    world_ned_transform,
)
from companion.json_value import JsonObject

if TYPE_CHECKING:
    from companion.camera.frames import Frame
    from companion.perception.pipeline import FrameResult

logger = logging.getLogger(__name__)

TRUTH_TOPICS = ("/truth/people",)


class LiveViewError(SlzError):
    """The live view could not start: the package missing, the port taken."""


class LiveView:
    """The Foxglove WebSocket server of one flight.

    Parameters
    ----------
    config : LiveViewConfig
        Where it listens and what it sends.
    name : str
        The server's name as Foxglove shows it.
    """

    def __init__(self, config: LiveViewConfig, name: str = "SLZ Lander") -> None:
        try:
            import foxglove
        except ImportError:
            raise LiveViewError("the live view needs foxglove-sdk: pip install 'slz-lander[live]'") from None
        self.config = config
        self._context = foxglove.Context()
        try:
            self.server = foxglove.start_server(
                name=name,
                host=config.host,
                port=config.port,
                context=self._context,
                message_backlog_size=config.backlog_messages,
            )
        except Exception as exc:  # the SDK raises RuntimeError (and others) for a taken port or a bad address
            raise LiveViewError(f"cannot serve on {config.host}:{config.port}: {exc}") from None
        self.port = int(self.server.port)
        self._channels = {
            topic: foxglove.Channel(
                topic, schema=_schema(foxglove, name_), message_encoding="json", context=self._context
            )
            for topic, name_ in TOPICS.items()
            if topic not in TRUTH_TOPICS  # the truth never reaches the companion
        }
        self._next_image_s = -1e9
        self.failed = False
        self.sent: dict[str, int] = dict.fromkeys(self._channels, 0)
        self.dropped = 0
        """Jobs dropped because the view's own queue was full (the flight never waits for the view)."""
        self._jobs: queue.Queue[Callable[[], None] | None] = queue.Queue(maxsize=config.backlog_messages)
        self._worker = threading.Thread(target=self._work, name="live-view", daemon=True)
        self._worker.start()
        logger.info("live view on ws://%s:%d (Foxglove: open a connection to it)", config.host, self.port)

    def _watched(self) -> bool:
        return any(channel.has_sinks() for channel in self._channels.values())

    def _post(self, job: Callable[[], None]) -> None:
        """Hand ``job`` to the view's thread: the flight's loop only queues (the JSON, the JPEG are built there)."""
        if self.failed or not self._watched():  # no client: nothing queued, nothing built
            return
        try:
            self._jobs.put_nowait(job)
        except queue.Full:
            self.dropped += 1

    def _work(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            self._guard(job)

    def _send(self, topic: str, t_s: float, message: JsonObject | Callable[[], JsonObject]) -> None:
        channel = self._channels[topic]
        if not channel.has_sinks():  # no client wants it: build nothing
            return
        body = message() if callable(message) else message
        channel.log(body, log_time=max(0, round(t_s * 1e9)))
        self.sent[topic] += 1

    def _guard(self, action: Callable[[], None]) -> None:
        if self.failed:
            return
        try:
            action()
        except Exception:  # never into the flight: said once, then the view is off
            self.failed = True
            logger.exception("live view failed; it is off for the rest of the flight")

    def record(self, record: dict[str, Any]) -> None:
        """A flight-log record as it is written: decisions, phases, commands, events."""

        def send() -> None:
            if kind_of(record) is RecordKind.FRAME_RESULT and record.get("t_s") is not None:
                # With every processed frame: a client may join at any time.
                self._send("/tf", float(record["t_s"]), world_ned_transform(float(record["t_s"])))
            for topic, t_s, message in messages_of(record, None):
                self._send(topic, t_s, message)

        self._post(send)

    def frame(self, frame: Frame, result: FrameResult) -> None:
        """A processed frame's head-plane map, and its camera image at ``camera_rate_hz`` (its pose, zones and
        target come with its ``frame_result`` record, :meth:`record`)."""

        def send() -> None:
            t_s = frame.t_capture_s
            self._send("/slz/map", t_s, lambda: grid_message(t_s, result.head_plane))
            rate = self.config.camera_rate_hz
            if rate > 0.0 and t_s >= self._next_image_s and self._channels["/camera/image"].has_sinks():
                self._next_image_s = t_s + 1.0 / rate
                ok, jpeg = cv2.imencode(".jpg", frame.image_bgr, [cv2.IMWRITE_JPEG_QUALITY, self.config.jpeg_quality])
                if ok:
                    self._send("/camera/image", t_s, image_message(t_s, jpeg.tobytes(), "jpeg"))

        self._post(send)

    def close(self) -> None:
        """Stop the view's thread (what is queued is dropped) and serving."""
        while True:
            try:
                self._jobs.get_nowait()
            except queue.Empty:
                break
        self._jobs.put(None)
        self._worker.join(timeout=5.0)
        self._guard(self.server.stop)


def _schema(foxglove: Any, name: str) -> Any:
    import json

    return foxglove.Schema(name=name, encoding="jsonschema", data=json.dumps(SCHEMAS[name]).encode())
