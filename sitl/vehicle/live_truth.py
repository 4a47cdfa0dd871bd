"""The SITL's truth live in Foxglove (``slz sitl --live-view PORT``, ``sitl.live_view_port``): where every person
really is and where the vehicle really is, on the topics and schemas of :mod:`companion.flightlog.foxglove_topics`
(``/truth/people``, ``/tf`` with ``world`` → ``world_ned`` → ``vehicle``), so a person at the desk sees the truth
beside the companion's own live view (``slz fly --live-view``) of its map.

It reads the crowd as it stands (never advancing it: the truth a frame or the truth log would see) at ``rate_hz`` of
simulated time, and only while a client is connected; the SDK's server drops a slow client's oldest messages.
"""

from __future__ import annotations

import json
import logging
from typing import Any

from companion.errors import SlzError
from companion.flightlog.foxglove_topics import SCHEMAS, discs, stamp, world_ned_transform
from sitl.dynamics.base import VehicleState

logger = logging.getLogger(__name__)


class LiveTruthError(SlzError):
    """The truth's live view could not start: the package missing, the port taken."""


class LiveTruth:
    """A Foxglove WebSocket server of the SITL's truth.

    Parameters
    ----------
    port : int
        TCP port.
    host : str
        Address to listen on.
    rate_hz : float
        Samples per simulated second.
    """

    def __init__(self, port: int, host: str = "127.0.0.1", rate_hz: float = 5.0) -> None:
        try:
            import foxglove
        except ImportError:
            raise LiveTruthError("the live view needs foxglove-sdk: pip install 'slz-lander[live]'") from None
        self._context = foxglove.Context()
        try:
            self.server = foxglove.start_server(name="SLZ SITL truth", host=host, port=port, context=self._context)
        except Exception as exc:  # the SDK raises RuntimeError (and others) for a taken port or a bad address
            raise LiveTruthError(f"cannot serve on {host}:{port}: {exc}") from None
        self.port = int(self.server.port)

        def channel(topic: str, schema: str) -> Any:
            data = json.dumps(SCHEMAS[schema]).encode()
            definition = foxglove.Schema(name=schema, encoding="jsonschema", data=data)
            return foxglove.Channel(topic, schema=definition, message_encoding="json", context=self._context)

        self._people = channel("/truth/people", "foxglove.SceneUpdate")
        self._tf = channel("/tf", "foxglove.FrameTransform")
        self.rate_hz = rate_hz
        self._next_s = 0.0
        self.sent = 0
        logger.info("truth live view on ws://%s:%d", host, self.port)

    def due(self, t_s: float) -> bool:
        """Whether a sample is due at simulated ``t_s`` (s)."""
        return t_s >= self._next_s - 1e-9

    def sample(self, t_s: float, people: dict[str, Any] | None, state: VehicleState) -> None:
        """The people (``SimCamera.people()``: positions and radii; None without a camera) and the vehicle now."""
        self._next_s = t_s + 1.0 / self.rate_hz
        ns = max(0, round(t_s * 1e9))
        if self._tf.has_sinks():
            n, e, d = (float(v) for v in state.position_ned_m)
            w, x, y, z = (float(v) for v in state.quaternion_wxyz)
            vehicle = {
                "timestamp": stamp(t_s),
                "parent_frame_id": "world_ned",
                "child_frame_id": "vehicle",
                "translation": {"x": n, "y": e, "z": d},
                "rotation": {"x": x, "y": y, "z": z, "w": w},
            }
            self._tf.log(world_ned_transform(t_s), log_time=ns)
            self._tf.log(vehicle, log_time=ns)
            self.sent += 2
        if people is not None and self._people.has_sinks():
            found = [
                (float(p[0]), float(p[1]), float(r))
                for p, r in zip(people["positions_ne_m"], people["radii_m"], strict=True)
            ]
            self._people.log(discs(t_s, "person", found, (0.9, 0.1, 0.1, 0.8)), log_time=ns)
            self.sent += 1

    def close(self) -> None:
        """Stop serving."""
        self.server.stop()
