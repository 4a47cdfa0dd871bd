"""The flight log's schema: one vocabulary for the writer (``FlightApp``, ``slz fly``) and every reader (``slz replay``,
``slz report``, the campaign's metrics, the SITL's mission scoring).

A flight log is ``flight.jsonl``: one JSON object per line, ``{"t_s": <vehicle time or null>, "kind": <RecordKind>,
...fields}``. The header carries :data:`SCHEMA_VERSION`; a log written before the schema had none and reads as
version 1 (the same records: the schema named what was already there). :meth:`FlightLog.read` checks every record
against :data:`REQUIRED_FIELDS` and names the line and the field that is missing, so a reader never meets a
``KeyError`` deep inside a plot.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from companion.errors import SlzError
from companion.flightlog.legacy_decisions import vocabulary_of
from companion.flightlog.recorder import RecorderError, read_log
from companion.guidance.landing import CommandKind, LandingPhase
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import (
    ZONE_CHOICES,
    CommitmentEvent,
    DecisionEvent,
    DecisionSource,
    RefusalCause,
    ZoneChange,
)
from companion.json_value import JsonObject
from companion.perception.selection import Target
from companion.vehicle.link import Setpoint

SCHEMA_VERSION = 3
"""1: logs written before this module (no ``schema_version`` in the header); 2: the header names its version; 3: a
decision carries its ``stimulus`` (:func:`companion.guidance.stimulus.to_json`: its type and inputs) where it had
``inputs``. Every earlier version is still read, and replayed."""


class RecordKind(str, enum.Enum):
    """Every kind of record a flight log holds."""

    HEADER = "header"
    """The full mission config, the model and its hash, the software version, the schema version."""
    START = "start"
    """The mode, vehicle and camera URLs."""
    CLOCK = "clock"
    """Whether the flight runs in lockstep."""
    WAITING_FOR_HANDOVER = "waiting_for_handover"
    WAITING = "waiting"
    """A dry run waits to start deciding (``waiting_for``: what it waits for), once per change of it."""
    HANDOVER = "handover"
    TAKEOFF = "takeoff"
    FRAME = "frame"
    """A saved camera frame: its sequence number and file."""
    FRAME_RESULT = "frame_result"
    """A processed frame: its pose, tracks, target and stage timings."""
    FRAME_ERROR = "frame_error"
    DECISION = "decision"
    """One decision of the landing logic, with its source, the vehicle state and its stimulus (``inputs`` before
    schema 3)."""
    PHASE = "phase"
    """A phase change."""
    COMMAND = "command"
    """A command sent to the vehicle."""
    FAILSAFE = "failsafe"
    POSE = "pose"
    """The vehicle once a second of its clock, whatever the flight does (``north_m``, ``east_m``, ``down_m``,
    ``yaw_deg``, ``mode``, ``armed``, ``in_air``): the whole flight's path, a dry run's wait included."""
    FENCE = "fence"
    """A fence given in latitude and longitude, projected to local NED at the start (``polygon_ne_m``, the origin)."""
    SUPERVISION = "supervision"
    """After a failsafe command: ``event`` (watching, on_ground, pilot_has_it) and ``reason``."""
    ERROR = "error"
    LATENCY = "latency"
    """Frame arrival to command sent, ms."""
    FALLBACK_SITES = "fallback_sites"
    """The fallback sites a flight used, the autopilot's rally points among them (``sites``, ``rally_points``)."""
    GROUND_COMMAND = "ground_command"
    """A ground station's landing command (:mod:`companion.app.operator_desk`): ``command``, ``mav_cmd``, ``sender``,
    ``signed``, ``force``, ``person_seen``, ``result`` (accepted, denied) and ``reason``."""
    WARNING = "warning"
    """The warning device for the people below switched (:mod:`companion.app.warning_device`): ``on``, ``sent``
    (False in a dry run or after the pilot took over), the decision's ``phase`` and ``event``, ``actuator``."""
    END = "end"
    """The flight's outcome."""


REQUIRED_FIELDS: dict[RecordKind, tuple[str, ...]] = {
    RecordKind.HEADER: ("config",),
    RecordKind.START: ("mode",),
    RecordKind.FRAME: ("seq", "path"),
    RecordKind.FRAME_RESULT: ("seq", "T_world_body", "tracks", "target"),
    RecordKind.FRAME_ERROR: ("seq", "error"),
    RecordKind.DECISION: ("decision", "source", "state"),
    RecordKind.PHASE: ("phase",),
    RecordKind.COMMAND: ("command",),
    RecordKind.FAILSAFE: ("reason",),
    RecordKind.SUPERVISION: ("event", "reason"),
    RecordKind.FENCE: ("polygon_ne_m",),
    RecordKind.POSE: ("north_m", "east_m", "down_m"),
    RecordKind.WAITING: ("waiting_for",),
    RecordKind.ERROR: ("error",),
    RecordKind.LATENCY: ("frame_to_command_ms",),
    RecordKind.WARNING: ("on", "sent"),
    RecordKind.END: ("outcome",),
}


_KINDS = {k.value: k for k in RecordKind}


def flight_folder(path: Path) -> Path:
    """The flight folder of ``path``: its folder when it is the log ``flight.jsonl`` itself, itself when it holds one,
    else its ``flight/`` sub-folder when that does (the run folder ``slz demo`` and the campaign's missions print),
    else itself (the reader names what is missing)."""
    path = Path(path)
    if path.name == "flight.jsonl" and path.is_file():
        return path.parent
    if not (path / "flight.jsonl").is_file() and (path / "flight" / "flight.jsonl").is_file():
        return path / "flight"
    return path


def kind_of(record: dict[str, Any]) -> RecordKind | None:
    """A record's kind; None for a kind this reader does not know (a newer writer's). The one place a record's kind
    is read from its JSON."""
    return _KINDS.get(str(record.get("kind")))


def _target(logged: dict[str, Any] | None) -> Target | None:
    """A decision's target as logged (its centre and radius, m, and its zone's track id)."""
    if logged is None:
        return None
    track_id = logged.get("track_id")
    return Target(logged["north_m"], logged["east_m"], logged["radius_m"], None if track_id is None else int(track_id))


def _setpoint(logged: dict[str, Any] | None) -> Setpoint | None:
    """A decision's setpoint as logged (local NED, m; yaw, deg)."""
    return (
        None if logged is None else Setpoint(logged["north_m"], logged["east_m"], logged["down_m"], logged["yaw_deg"])
    )


@dataclass(frozen=True)
class DecisionRecord:
    """A ``decision`` record, typed: the command decided (``kind``: none, setpoint, land, hold, return) at vehicle
    time ``t_s`` in ``phase``, toward ``target`` (a zone: ``north_m``, ``east_m``, ``radius_m``, ``track_id``) with
    ``setpoint`` (local NED, m; yaw, deg), why in words (``reason``, for people) and as data (``event``, ``cause``,
    ``zone_changes``: :mod:`companion.guidance.vocabulary`; None where an old log's words name no event), what
    produced it (``source``: start, frame, silence, time, landed, takeover) and the vehicle ``state`` it was taken in
    (``north_m``, ``east_m``, ``down_m``, ``yaw_deg``)."""

    t_s: float
    kind: CommandKind
    phase: LandingPhase
    target: Target | None
    setpoint: Setpoint | None
    reason: str
    source: DecisionSource
    state: VehicleState | None
    event: DecisionEvent | None = None
    cause: RefusalCause | None = None
    zone_changes: tuple[CommitmentEvent, ...] = ()

    @classmethod
    def from_record(cls, record: dict[str, Any]) -> DecisionRecord:
        """From a checked ``decision`` record (see :data:`REQUIRED_FIELDS`); a decision without a target, setpoint
        or reason has none. A log from before decisions carried their event is read through the one legacy reader
        of their words (:func:`companion.flightlog.legacy_decisions.vocabulary_of`)."""
        decision = record["decision"]
        reason = str(decision.get("reason", ""))
        phase = LandingPhase(decision["phase"])
        if "event" in decision:
            event: DecisionEvent | None = DecisionEvent(decision["event"])
            cause = None if decision.get("cause") is None else RefusalCause(decision["cause"])
            changes = tuple(
                CommitmentEvent(
                    ZoneChange(c["change"]), None if c.get("cause") is None else RefusalCause(c["cause"]), c["text"]
                )
                for c in decision.get("zone_changes") or ()
            )
        else:
            event, cause, changes = vocabulary_of(reason, phase)
        return cls(
            float(record["t_s"]),
            CommandKind(decision["kind"]),
            phase,
            _target(decision.get("target")),
            _setpoint(decision.get("setpoint")),
            reason,
            DecisionSource(record["source"]),
            None if record["state"] is None else VehicleState(**record["state"]),
            event,
            cause,
            changes,
        )

    def chose_zones(self) -> int:
        """How many times this decision reports a landing zone chosen (commitments and switches)."""
        return sum(1 for c in self.zone_changes if c.change in ZONE_CHOICES)


@dataclass(frozen=True)
class FlightHeader:
    """A flight log's first record, typed: the schema version, the mission config the flight ran with (as JSON), the
    density model file and its SHA-256, whether that model carries a real-imagery validation record, and the
    software's version. Written by ``slz fly`` (:meth:`write`) and read in one place (:attr:`FlightLog.header`)."""

    config: dict[str, Any]
    schema_version: int = 1
    model: str | None = None
    model_sha256: str | None = None
    model_validated_real_imagery: bool = False
    version: str | None = None

    @classmethod
    def from_record(cls, record: dict[str, Any]) -> FlightHeader:
        """From a checked ``header`` record; fields an older writer did not write take their defaults."""
        return cls(
            dict(record["config"]),
            int(record.get("schema_version", 1)),
            None if record.get("model") is None else str(record["model"]),
            None if record.get("model_sha256") is None else str(record["model_sha256"]),
            bool(record.get("model_validated_real_imagery", False)),
            None if record.get("version") is None else str(record["version"]),
        )

    def fields(self) -> JsonObject:
        """The record's fields, as the recorder writes them (``recorder.write(RecordKind.HEADER, None, **fields)``)."""
        return {
            "schema_version": self.schema_version,
            "config": self.config,
            "model": self.model,
            "model_sha256": self.model_sha256,
            "model_validated_real_imagery": self.model_validated_real_imagery,
            "version": self.version,
        }

    @property
    def mode(self) -> str | None:
        """The operating mode the flight ran in (fly, dry_run; None in a log from before modes)."""
        mode = self.config.get("mode")
        return None if mode is None else str(mode)


class FlightLogError(SlzError):
    """A flight log does not follow its schema (which file, which line, which field)."""


@dataclass(frozen=True)
class FlightLog:
    """The records of one flight log, checked, with typed access.

    Attributes
    ----------
    path : Path
        The ``flight.jsonl`` it was read from.
    records : list of dict
        Every record in order (unknown kinds of a newer writer included, unchecked).
    version : int
        The schema version the header states (1 when it states none).
    """

    path: Path
    records: list[dict[str, Any]]
    version: int

    @classmethod
    def read(cls, path: Path) -> FlightLog:
        """Read and check ``path`` (a ``flight.jsonl``, or the flight folder holding it).

        Raises
        ------
        FlightLogError
            Not readable as JSON lines, a newer schema than this reader's, or a record missing a required field.
        """
        path = Path(path)
        if path.is_dir():
            path = flight_folder(path) / "flight.jsonl"
        try:
            records = read_log(path)
        except (OSError, RecorderError) as exc:
            raise FlightLogError(f"{path}: {exc}") from None
        version = 1
        for number, record in enumerate(records, start=1):
            kind = kind_of(record)
            if kind is None:
                continue
            missing = [f for f in REQUIRED_FIELDS.get(kind, ()) if f not in record]
            if missing:
                raise FlightLogError(f"{path}: record {number} ({kind.value}) lacks {', '.join(missing)}")
            if kind is RecordKind.HEADER:
                version = int(record.get("schema_version", 1))
        if version > SCHEMA_VERSION:
            raise FlightLogError(f"{path}: schema version {version}; this reader knows up to {SCHEMA_VERSION}")
        return cls(path, records, version)

    def of(self, kind: RecordKind) -> list[dict[str, Any]]:
        """Every record of ``kind``, in order."""
        return [r for r in self.records if kind_of(r) is kind]

    def first(self, kind: RecordKind) -> dict[str, Any] | None:
        """The first record of ``kind``, or None."""
        return next((r for r in self.records if kind_of(r) is kind), None)

    def last(self, kind: RecordKind) -> dict[str, Any] | None:
        """The last record of ``kind``, or None."""
        return next((r for r in reversed(self.records) if kind_of(r) is kind), None)

    def count(self, kind: RecordKind) -> int:
        """How many records of ``kind``."""
        return sum(1 for r in self.records if kind_of(r) is kind)

    def tagged(self, *kinds: RecordKind) -> Iterator[tuple[RecordKind, dict[str, Any]]]:
        """The records of ``kinds`` (every known kind when none is named) with their kind, in log order: for readers
        that follow several kinds through the flight."""
        wanted = set(kinds) if kinds else set(RecordKind)
        for record in self.records:
            kind = kind_of(record)
            if kind is not None and kind in wanted:
                yield kind, record

    def decisions(self) -> list[DecisionRecord]:
        """Every decision, typed, in order.

        Raises
        ------
        FlightLogError
            A decision names a command, phase, source or event this reader does not know (the line's time says which).
        """
        typed = []
        for record in self.of(RecordKind.DECISION):
            try:
                typed.append(DecisionRecord.from_record(record))
            except ValueError as exc:
                raise FlightLogError(f"{self.path}: the decision at t = {record.get('t_s')} s: {exc}") from None
        return typed

    @property
    def header(self) -> FlightHeader | None:
        """The header, typed (None in a log without one: a flight that never started)."""
        record = self.first(RecordKind.HEADER)
        return None if record is None else FlightHeader.from_record(record)

    def require_header(self) -> FlightHeader:
        """The header, typed (raises :class:`FlightLogError` naming the log when there is none)."""
        header = self.header
        if header is None:
            raise FlightLogError(f"{self.path}: no header record (the config the flight ran with)")
        return header

    @property
    def config(self) -> dict[str, Any]:
        """The header's full mission config (raises :class:`FlightLogError` when there is no header)."""
        return self.require_header().config

    @property
    def outcome(self) -> dict[str, Any]:
        """The end record's outcome ({} when the flight did not end cleanly)."""
        end = self.last(RecordKind.END)
        return {} if end is None else dict(end["outcome"])

    def phases(self) -> list[tuple[float, str]]:
        """(vehicle time, phase) of every phase change with a time."""
        return [(float(r["t_s"]), str(r["phase"])) for r in self.of(RecordKind.PHASE) if r["t_s"] is not None]

    def frame_paths(self) -> dict[int, Path]:
        """Saved frames by sequence number."""
        folder = self.path.parent
        return {int(r["seq"]): folder / str(r["path"]) for r in self.of(RecordKind.FRAME)}
