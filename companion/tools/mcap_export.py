"""A recorded flight as an MCAP file Foxglove opens as it is (``slz export FLIGHT --mcap``): the camera frames saved,
the vehicle's pose as transforms, the zones and the target in the world, the decisions, phases, commands and events;
and, for a SITL run, the truth (where every person really was). The topics and schemas are the live view's
(:mod:`companion.flightlog.foxglove_topics`); log time is the vehicle's boot clock in nanoseconds. The occupancy map is
not in a flight log, so ``/slz/map`` stays empty here (``slz replay`` recomputes it; the live view sends it).
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from pathlib import Path

from companion.errors import SlzError
from companion.flightlog.flight_log import FlightLog
from companion.flightlog.foxglove_topics import SCHEMAS, TOPICS, messages_of, truth_messages, world_ned_transform
from companion.json_value import JsonObject


class ExportError(SlzError):
    """A flight could not be exported: what and where."""


class _Out:
    """The MCAP writer with a channel per topic, counting what it wrote."""

    def __init__(self, path: Path) -> None:
        try:
            from mcap.writer import Writer
        except ImportError:
            raise ExportError("writing MCAP needs the mcap package: pip install 'slz-lander[report]'") from None
        self._stream = path.open("wb")
        self.writer = Writer(self._stream)
        self.writer.start(profile="", library="slz-lander")
        schema_ids = {
            name: self.writer.register_schema(name, "jsonschema", json.dumps(schema).encode())
            for name, schema in SCHEMAS.items()
        }
        self.channels = {
            topic: self.writer.register_channel(topic, "json", schema_ids[schema]) for topic, schema in TOPICS.items()
        }
        self.counts: Counter[str] = Counter()

        self._pending: list[tuple[float, int, str, JsonObject | Callable[[], JsonObject]]] = []

    def add(self, topic: str, t_s: float, message: JsonObject | Callable[[], JsonObject]) -> None:
        """Queue one message (or a function that builds it, for the frames: built when written, one at a time)."""
        self._pending.append((t_s, len(self._pending), topic, message))

    def close(self) -> None:
        """Write the queued messages in log-time order (MCAP readers replay in that order) and finish the file."""
        try:
            for t_s, _, topic, message in sorted(self._pending, key=lambda m: (m[0], m[1])):
                ns = max(0, round(t_s * 1e9))
                body = message() if callable(message) else message
                data = json.dumps(body, separators=(",", ":")).encode()
                self.writer.add_message(self.channels[topic], log_time=ns, data=data, publish_time=ns)
                self.counts[topic] += 1
            self.writer.finish()  # type: ignore[no-untyped-call]
        finally:
            self._stream.close()


def export_mcap(flight_dir: Path, out_path: Path, truth: Path | None = None) -> Counter[str]:
    """Write the flight in ``flight_dir`` (``flight.jsonl``, ``frames/``) as MCAP at ``out_path``; with ``truth``
    (a SITL run's ``truth.jsonl``) the people too. Returns the messages written per topic.

    Raises
    ------
    ExportError
        No readable flight log, or the mcap package is missing.
    """
    try:
        flight = FlightLog.read(flight_dir)
    except SlzError as exc:
        raise ExportError(f"{flight_dir}: {exc}") from None
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out = _Out(out_path)
    try:
        first = next((float(r["t_s"]) for r in flight.records if r.get("t_s") is not None), 0.0)
        out.add("/tf", first, world_ned_transform(first))
        folder = Path(flight.path).parent
        for record in flight.records:
            for topic, t_s, message in messages_of(record, folder):
                out.add(topic, t_s, message)
        if truth is not None:
            try:
                for topic, t_s, message in truth_messages(truth):
                    out.add(topic, t_s, message)
            except (OSError, ValueError, KeyError) as exc:
                raise ExportError(f"{truth}: {exc}") from None
    finally:
        out.close()
    return out.counts
