"""Why a mission held, from its flight log and the SITL's ground truth: every time the map turned a landing point down.

A hold's kind (:func:`sitl.campaign.metrics.hold_cause`) says how the mission ended; this says what led there. Each
time the companion gave up a landing point, its flight log names why: a committed zone was *released* (a person seen
in its footprint for several frames, it shrank, it was lost, its footprint left the fence), or a descent was
*aborted* (a person seen in the footprint, the zone shrank, no fresh map saw it free, someone kept walking in, or the
walker gate's wait ran out). For the refusals that name a person, the ground truth says how far the nearest body
really was from the refused point at that instant, so a hold reads as one of:

- people really were there (a body's edge inside the footprint: ``vehicle_radius_m + margin_m``);
- the map keeps a wider berth than the footprint (the nearest body a little outside it: the occupancy's blob and
  its dilation, by design);
- the map saw people where nobody was (the nearest body far away: false positives).

And whether a perfect map would have landed: every few seconds of the flight, the largest disc inside the landing
area (or the geofence) that no body's edge enters, from the truth. When such a disc as large as the footprint was
there most of the time, the hold is the map's caution, not the scene's crowd.

Times are vehicle-clock seconds (the flight log and the truth share the SITL's clock); positions world NED metres;
distances horizontal, to a body's edge (centre distance minus body radius). :func:`explain_run` reads a mission's
folder (the landing area, else the geofence, from the config its flight log holds); :func:`explain_hold` works on
records already read.
"""

from __future__ import annotations

import bisect
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from companion.flightlog.flight_log import DecisionRecord, FlightLog
from companion.geometry import inside_polygon
from companion.guidance.vocabulary import DecisionEvent, DecisionSource, RefusalCause, ZoneChange
from companion.perception.selection import Target
from sitl.vehicle.truth import TruthHeader, TruthRecord, body_edges_m, clearance_m, people_at, read_truth

FREE_SAMPLE_S = 5.0
"""How often (vehicle seconds) the truth's largest free disc is measured over a flight."""

RELEASE_KINDS = {
    RefusalCause.PERSON_IN_FOOTPRINT: "person in the footprint",
    RefusalCause.ZONE_SHRANK: "zone shrank",
    RefusalCause.ZONE_LOST: "zone lost",
    RefusalCause.LEFT_GEOFENCE: "footprint left the geofence",
}
ABORT_KINDS = {
    RefusalCause.PERSON_AT_GATE: "person in the footprint at the gate, wait limit",
    RefusalCause.WALKER_KEPT_COMING: "walker kept coming",
    RefusalCause.PERSON_IN_FOOTPRINT: "person in the footprint",
    RefusalCause.ZONE_SHRANK: "zone shrank",
    RefusalCause.NO_FREE_MAP: "no fresh free map",
}
PERSON_CAUSES = (RefusalCause.PERSON_IN_FOOTPRINT, RefusalCause.PERSON_AT_GATE)
"""The refusals that name a person in the footprint (the truth says how far the nearest body really was)."""


def release_kind(cause: RefusalCause | None) -> str:
    """A release's kind, as the report counts it: 'person in the footprint', 'zone shrank', 'zone lost',
    'footprint left the geofence' or 'other'."""
    return "other" if cause is None else RELEASE_KINDS.get(cause, "other")


def abort_kind(cause: RefusalCause | None) -> str:
    """An aborted descent's kind, as the report counts it (:data:`ABORT_KINDS`, else 'other')."""
    return "other" if cause is None else ABORT_KINDS.get(cause, "other")


@dataclass(frozen=True)
class Refusal:
    """One landing point given up because the map saw a person in its footprint.

    Attributes
    ----------
    t_s : float
        Vehicle time of the refusal.
    event : str
        ``release`` (a committed zone, before any descent), ``abort`` (a descent) or ``gate`` (one map at the walker
        gate that saw the footprint occupied: the descent waited).
    north_m, east_m : float
        The refused landing point (world NED).
    nearest_edge_m : float
        True distance from the point to the nearest body's edge at ``t_s``.
    """

    t_s: float
    event: str
    north_m: float
    east_m: float
    nearest_edge_m: float


@dataclass
class HoldExplanation:
    """What a flight log and its truth say about why a mission did not land.

    Attributes
    ----------
    footprint_radius_m : float
        ``vehicle_radius_m + margin_m``: the disc the map must see free.
    vehicle_radius_m : float
        The vehicle's own radius: a body's edge closer than this to a touchdown is a body in the footprint.
    zones_chosen : int
        Commitments and switches.
    releases : Counter
        Released zones by :func:`release_kind`.
    aborts : Counter
        Aborted descents by :func:`abort_kind`.
    refusals : list of Refusal
        Every release, abort and gate map that named a person, with the truth's nearest body.
    free_radii_m : list of float
        The largest truly free disc's radius in the landing area, every ``FREE_SAMPLE_S`` of the flight.
    """

    footprint_radius_m: float
    vehicle_radius_m: float
    zones_chosen: int = 0
    releases: Counter[str] = field(default_factory=Counter)
    aborts: Counter[str] = field(default_factory=Counter)
    refusals: list[Refusal] = field(default_factory=list)
    free_radii_m: list[float] = field(default_factory=list)

    def free_share(self) -> float | None:
        """The share of the samples in which a disc as large as the footprint was truly free (None: no sample)."""
        if not self.free_radii_m:
            return None
        return float(np.mean(np.array(self.free_radii_m) >= self.footprint_radius_m))

    def person_refusals(self, event: str | None = None) -> list[Refusal]:
        """The refusals of one ``event`` kind (all when None)."""
        return [r for r in self.refusals if event is None or r.event == event]

    def verdict(self) -> str:
        """Where the refusals' nearest bodies were: 'people there' (most had a body in the footprint), 'wide berth'
        (most had the nearest body within 3 m of the footprint's edge, none in it), 'false positives' (most had
        nobody within 3 m of the edge), 'mixed', or 'no person named' (no refusal named a person)."""
        refusals = self.person_refusals("release") + self.person_refusals("abort")
        if not refusals:
            refusals = self.person_refusals()
        if not refusals:
            return "no person named"
        edges = np.array([r.nearest_edge_m for r in refusals])
        inside = float(np.mean(edges < self.footprint_radius_m))
        near = float(np.mean((edges >= self.footprint_radius_m) & (edges < self.footprint_radius_m + 3.0)))
        if inside > 0.5:
            return "people there"
        if near > 0.5:
            return "wide berth"
        if 1.0 - inside - near > 0.5:
            return "false positives"
        return "mixed"

    def summary(self) -> str:
        """One line for a report."""
        parts = [f"{self.zones_chosen} zones chosen"]
        if self.releases:
            parts.append("released: " + ", ".join(f"{n} {k}" for k, n in self.releases.most_common()))
        if self.aborts:
            parts.append("descents aborted: " + ", ".join(f"{n} {k}" for k, n in self.aborts.most_common()))
        for event, name in (("release", "releases"), ("abort", "aborts"), ("gate", "gate maps")):
            edges = np.array([r.nearest_edge_m for r in self.person_refusals(event)])
            if len(edges):
                inside = int((edges < self.footprint_radius_m).sum())
                parts.append(
                    f"nearest body at the {name} for a person: {np.min(edges):.1f}-{np.max(edges):.1f} m "
                    f"(median {np.median(edges):.1f}), {inside} of {len(edges)} inside the "
                    f"{self.footprint_radius_m:g} m footprint"
                )
        share = self.free_share()
        if share is not None:
            parts.append(
                f"truly free disc of the footprint's size in {100 * share:.0f} % of the flight "
                f"(largest free radius median {np.median(self.free_radii_m):.2f} m)"
            )
        return "; ".join(parts) + f" -> {self.verdict()}"

    def to_json(self) -> dict[str, Any]:
        """JSON-able (refusals summarised by event: count, inside the footprint, min / median / max nearest body)."""
        by_event: dict[str, Any] = {}
        for event in ("release", "abort", "gate"):
            edges = np.array([r.nearest_edge_m for r in self.person_refusals(event)])
            if len(edges):
                by_event[event] = {
                    "count": len(edges),
                    "inside_footprint": int((edges < self.footprint_radius_m).sum()),
                    "within_vehicle_radius": int((edges < self.vehicle_radius_m).sum()),
                    "nearest_edge_m": [round(float(v), 2) for v in (edges.min(), np.median(edges), edges.max())],
                }
        return {
            "zones_chosen": self.zones_chosen,
            "releases": dict(self.releases),
            "aborts": dict(self.aborts),
            "person_refusals": by_event,
            "free_share": self.free_share(),
            "free_radius_m": [round(float(q), 2) for q in np.quantile(self.free_radii_m, (0.0, 0.5, 1.0))]
            if self.free_radii_m
            else None,
            "verdict": self.verdict(),
            "summary": self.summary(),
        }


class TruthAt:
    """The ground-truth record nearest a vehicle time (the truth is written at the SITL's rate, the log per frame)."""

    def __init__(self, header: TruthHeader, records: list[TruthRecord]) -> None:
        self.header = header
        self.records = records
        self._times = [r.t_s for r in records]

    def at(self, t_s: float) -> TruthRecord | None:
        """The record nearest ``t_s`` (None without records: the header's scene)."""
        if not self.records:
            return None
        i = bisect.bisect_left(self._times, t_s)
        near = [j for j in (i - 1, i) if 0 <= j < len(self.records)]
        return self.records[min(near, key=lambda j: abs(self._times[j] - t_s))]

    def nearest_edge_m(self, t_s: float, north_m: float, east_m: float) -> float:
        """Distance from a point to the nearest body's edge at ``t_s`` (inf with nobody in the scene)."""
        return float(body_edges_m(self.header, self.at(t_s), north_m, east_m).min())

    def largest_free_radius_m(self, t_s: float, area_ne_m: npt.NDArray[np.float64], step_m: float = 0.25) -> float:
        """The radius (m) of the largest disc inside the polygon ``area_ne_m`` ((K, 2) north/east m) that no body's
        edge enters at ``t_s``, its centre on a ``step_m`` grid (so within ``step_m / sqrt(2)`` of the exact one)."""
        lo, hi = area_ne_m.min(axis=0), area_ne_m.max(axis=0)
        north, east = np.meshgrid(
            np.arange(lo[0] + step_m / 2, hi[0], step_m), np.arange(lo[1] + step_m / 2, hi[1], step_m), indexing="ij"
        )
        inside = inside_polygon(area_ne_m, north, east)
        points = np.stack([north[inside], east[inside]], axis=1)  # (P, 2)
        if not len(points):
            return 0.0
        clear = clearance_m(*people_at(self.header, self.at(t_s)), points[:, 0], points[:, 1])
        a, b = area_ne_m, np.roll(area_ne_m, -1, axis=0)
        for (n0, e0), (n1, e1) in zip(a, b, strict=True):  # the disc stays inside the area: its edges bound it
            d_n, d_e = n1 - n0, e1 - e0
            length2 = d_n * d_n + d_e * d_e
            t = np.clip(((points[:, 0] - n0) * d_n + (points[:, 1] - e0) * d_e) / max(length2, 1e-12), 0.0, 1.0)
            edge = np.hypot(points[:, 0] - (n0 + t * d_n), points[:, 1] - (e0 + t * d_e))
            np.minimum(clear, edge, out=clear)
        return float(max(0.0, clear.max()))


def explain_hold(
    decisions: list[DecisionRecord],
    truth: TruthAt,
    vehicle_radius_m: float,
    margin_m: float,
    area_ne_m: npt.NDArray[np.float64] | None = None,
) -> HoldExplanation:
    """Go through a flight's decisions in order and collect every landing point it gave up, and why.

    Parameters
    ----------
    decisions : list of DecisionRecord
        The flight log's decisions, in order.
    truth : TruthAt
        The mission's ground truth.
    vehicle_radius_m, margin_m : float
        The perception's zone config (the footprint is their sum).
    area_ne_m : ndarray, shape (K, 2), optional
        Where zones may lie (the landing area, else the geofence): the truly free disc is looked for there, every
        ``FREE_SAMPLE_S`` from the first frame's decision to the last (not looked for without it).
    """
    out = HoldExplanation(footprint_radius_m=vehicle_radius_m + margin_m, vehicle_radius_m=vehicle_radius_m)
    target: Target | None = None  # the point the previous decision flew to

    def refuse(t_s: float, event: str) -> None:
        if target is not None:
            n, e = float(target.north_m), float(target.east_m)
            out.refusals.append(Refusal(t_s, event, n, e, truth.nearest_edge_m(t_s, n, e)))

    for d in decisions:
        out.zones_chosen += d.chose_zones()
        for change in d.zone_changes:
            if change.change is ZoneChange.RELEASE:
                out.releases[release_kind(change.cause)] += 1
                if change.cause is RefusalCause.PERSON_IN_FOOTPRINT:
                    refuse(d.t_s, "release")
        if d.event in (DecisionEvent.ABORT, DecisionEvent.RESELECTIONS_USED_UP):
            out.aborts[abort_kind(d.cause)] += 1
            if d.cause in PERSON_CAUSES:
                refuse(d.t_s, "abort")
        elif d.event is DecisionEvent.WAIT_AT_GATE and d.cause is RefusalCause.PERSON_IN_FOOTPRINT:
            refuse(d.t_s, "gate")
        if d.target is not None:
            target = d.target
    flying = [d.t_s for d in decisions if d.source is DecisionSource.FRAME]
    if area_ne_m is not None and flying:
        for t_s in np.arange(flying[0], flying[-1] + 1e-9, FREE_SAMPLE_S):
            out.free_radii_m.append(truth.largest_free_radius_m(float(t_s), area_ne_m))
    return out


def explain_run(run_dir: Path) -> HoldExplanation:
    """:func:`explain_hold` for a mission's folder (``flight/`` and ``truth.jsonl``, as a campaign or a replay writes
    them), with the footprint of the config its flight log holds."""
    flight = FlightLog.read(Path(run_dir) / "flight")
    header, records = read_truth(Path(run_dir) / "truth.jsonl")
    config = flight.config
    zones = config["perception"]["zones"]
    area = zones.get("landing_area_ne_m") or config.get("geofence", {}).get("polygon_ne_m")
    return explain_hold(
        flight.decisions(),
        TruthAt(header, records),
        float(zones["vehicle_radius_m"]),
        float(zones["margin_m"]),
        None if area is None else np.asarray(area, dtype=np.float64),
    )
