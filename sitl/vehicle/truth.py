"""The SITL's ground-truth log, ``truth.jsonl``: its schema, written by the vehicle process
(:mod:`sitl.vehicle.process`) and read, typed, by whoever scores a mission (:mod:`sitl.harness.mission`,
:mod:`sitl.campaign.metrics`, the demo).

One JSON object per line: first the header (``kind: header``: the scene's seed, every person's head-plane position
at the start, body radius and whether they walk, and the schema version), then one record per camera frame or
lockstep tick (``kind: truth``: the vehicle's true position, arming, mode, landed state and ground contact, and the
people's positions when some walk or may step away from the vehicle's warning; whether the warning sounded and how many
people reacted to it, when they did). Positions are local NED (north, east, down), m. A header without
``schema_version`` is version 1 (the same fields).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from companion.errors import SlzError

TRUTH_SCHEMA_VERSION = 2
"""1: logs written before this module (no ``schema_version`` in the header); 2: the header names its version."""

F64Array = npt.NDArray[np.float64]


class TruthError(SlzError):
    """A ground-truth log cannot be read (which file, what is wrong)."""


@dataclass(frozen=True, eq=False)  # numpy fields: compare by their to_json()
class TruthHeader:
    """The scene at the start: people's head-plane positions (N, 2) north/east m, body radii (N,) m, who walks."""

    seed: int | None
    t_s: float
    positions_ne_m: F64Array
    radii_m: F64Array
    moving: tuple[bool, ...]
    version: int = TRUTH_SCHEMA_VERSION

    def to_json(self) -> dict[str, Any]:
        """The header line as written."""
        return {
            "kind": "header",
            "schema_version": self.version,
            "seed": self.seed,
            "t_s": self.t_s,
            "positions_ne_m": self.positions_ne_m.tolist(),
            "radii_m": self.radii_m.tolist(),
            "moving": list(self.moving),
        }

    @classmethod
    def from_json(cls, line: dict[str, Any]) -> TruthHeader:
        return cls(
            None if line.get("seed") is None else int(line["seed"]),
            float(line.get("t_s", 0.0)),
            np.asarray(line["positions_ne_m"], dtype=np.float64).reshape(-1, 2),
            np.asarray(line["radii_m"], dtype=np.float64),
            tuple(bool(m) for m in line["moving"]),
            int(line.get("schema_version", 1)),
        )


@dataclass(frozen=True, eq=False)  # numpy fields: compare by their to_json()
class TruthRecord:
    """The truth at simulated time ``t_s`` (s): the vehicle's position (NED, m) and state; the people's positions
    (N, 2) when some walk (None: where the header has them)."""

    t_s: float
    position_ned_m: tuple[float, float, float]
    armed: bool
    mode: str
    landed_state: str
    on_ground: bool
    people_ne_m: F64Array | None = None
    warning: bool = False
    """The vehicle's warning device (siren, strobe) sounded (written only when it did)."""
    reactions: int = 0
    """People who reacted to a warning so far, in all (written only once someone did)."""

    def to_json(self) -> dict[str, Any]:
        """The record line as written (positions rounded to 0.1 mm)."""
        record: dict[str, Any] = {
            "kind": "truth",
            "t_s": self.t_s,
            "position_ned_m": [round(float(v), 4) for v in self.position_ned_m],
            "armed": self.armed,
            "mode": self.mode,
            "landed_state": self.landed_state,
            "on_ground": self.on_ground,
        }
        if self.warning:
            record["warning"] = True
        if self.reactions:
            record["reactions"] = self.reactions
        if self.people_ne_m is not None:
            rows = np.asarray(self.people_ne_m, dtype=np.float64).tolist()  # Python floats: the same values
            record["positions_ne_m"] = [[round(n, 4), round(e, 4)] for n, e in rows]
        return record

    @classmethod
    def from_json(cls, line: dict[str, Any]) -> TruthRecord:
        n, e, d = (float(v) for v in line["position_ned_m"])
        people = line.get("positions_ne_m")
        return cls(
            float(line["t_s"]),
            (n, e, d),
            bool(line["armed"]),
            str(line["mode"]),
            str(line["landed_state"]),
            bool(line["on_ground"]),
            None if people is None else np.asarray(people, dtype=np.float64).reshape(-1, 2),
            bool(line.get("warning", False)),
            int(line.get("reactions", 0)),
        )


class TruthWriter:
    """Writes a run's ground truth (``truth.jsonl``): its header at the first record, then one record per call, each
    flushed (the file is read while the run goes on, and must hold what happened if the run dies).

    Parameters
    ----------
    path : Path
        The file (its folder is created).
    seed : int
        The scenario's seed, for the header.
    """

    def __init__(self, path: Path, seed: int) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(path, "w", encoding="utf-8")  # noqa: SIM115 - closed in close()
        self.seed = seed
        self._header_written = False

    def write(self, t_s: float, people: dict[str, Any], vehicle: TruthRecord) -> None:
        """The record at ``t_s``: ``vehicle`` (its people left out) and the people the world reports (``people``:
        ``t_s``, ``positions_ne_m``, ``radii_m``, ``moving``, and optionally ``reactive`` and ``reactions``; positions
        recorded only when some walk or would step away from a warning)."""
        positions = np.asarray(people["positions_ne_m"], dtype=np.float64).reshape(-1, 2)
        if not self._header_written:
            self._header_written = True
            moving = tuple(bool(m) for m in people["moving"])
            radii = np.asarray(people["radii_m"], dtype=np.float64)
            header = TruthHeader(self.seed, float(people["t_s"]), positions, radii, moving)
            self._file.write(json.dumps(header.to_json()) + "\n")
        record = TruthRecord(
            t_s,
            vehicle.position_ned_m,
            vehicle.armed,
            vehicle.mode,
            vehicle.landed_state,
            vehicle.on_ground,
            positions if any(people["moving"]) or any(people.get("reactive", ())) else None,
            vehicle.warning,
            int(people.get("reactions", 0)),
        )
        self._file.write(json.dumps(record.to_json()) + "\n")
        self._file.flush()

    def close(self) -> None:
        """Close the file."""
        self._file.close()


def read_truth(path: Path) -> tuple[TruthHeader, list[TruthRecord]]:
    """The ground-truth log at ``path``: its header and records (:class:`TruthError` naming the file and line when it
    has no header or a record lacks a field)."""
    try:
        lines = [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]
    except (OSError, ValueError) as exc:
        raise TruthError(f"{path}: {exc}") from None
    if not lines or lines[0].get("kind") != "header":
        raise TruthError(f"{path}: no ground-truth header")
    number = 1
    try:
        header = TruthHeader.from_json(lines[0])
        records = []
        for number, line in enumerate(lines[1:], start=2):  # noqa: B007 - named in the error below
            if line.get("kind", "truth") == "truth":
                records.append(TruthRecord.from_json(line))
    except (KeyError, TypeError, ValueError) as exc:
        raise TruthError(f"{path}: line {number}: missing or bad field {exc}") from None
    if header.version > TRUTH_SCHEMA_VERSION:
        raise TruthError(f"{path}: schema version {header.version}; this reader knows up to {TRUTH_SCHEMA_VERSION}")
    return header, records


def people_at(header: TruthHeader, record: TruthRecord | None) -> tuple[F64Array, F64Array]:
    """Positions (N, 2) north/east m and body radii (N,) m at ``record`` (the header's without one)."""
    positions = header.positions_ne_m if record is None or record.people_ne_m is None else record.people_ne_m
    return positions, header.radii_m


def body_edges_m(header: TruthHeader, record: TruthRecord | None, north_m: float, east_m: float) -> F64Array:
    """Horizontal distance (m) from a point to every person's body edge at a ground-truth record; ``[inf]`` when
    nobody is there."""
    positions, radii = people_at(header, record)
    if not len(radii):
        return np.array([math.inf])
    return np.asarray(np.hypot(positions[:, 0] - north_m, positions[:, 1] - east_m) - radii)


def clearance_m(positions_ne_m: F64Array, radii_m: F64Array, north_m: npt.ArrayLike, east_m: npt.ArrayLike) -> F64Array:
    """Horizontal distance (m) from each point to the nearest body's edge (inf with nobody), the broadcast shape of
    ``north_m`` and ``east_m``; ``positions_ne_m`` (N, 2) and ``radii_m`` (N,) as :func:`people_at` gives them."""
    north, east = np.asarray(north_m, np.float64), np.asarray(east_m, np.float64)
    clear = np.full(np.broadcast_shapes(north.shape, east.shape), np.inf)
    for (n, e), r in zip(positions_ne_m, radii_m, strict=True):
        np.minimum(clear, np.hypot(north - n, east - e) - r, out=clear)
    return clear


def touchdown(records: list[TruthRecord]) -> TruthRecord | None:
    """The first ground-truth record on the ground after having flown, or None."""
    flown = False
    for record in records:
        if not record.on_ground:
            flown = True
        elif flown:
            return record
    return None
