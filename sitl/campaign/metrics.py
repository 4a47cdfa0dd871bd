"""Per-mission metrics, from the SITL's ground truth and the companion's flight log (definitions in docs/campaigns.md).

Distances are horizontal, metres, to the edge of a person's body (centre distance minus body radius). The *final
descent* runs from the companion's last entry into the descent phase before its landing command (or, without one,
from its last command) to the touchdown, or, without a touchdown, to the companion's last record (vehicle time). Its
*landing descent* runs from the moment the walker gate let the vehicle go (the first decision after the final
descent's last wait at the gate) to the same end; without a wait at the gate it is the whole final descent.

What lies under the touchdown comes from the park the SITL rendered, rebuilt from the mission's seed (the SITL has
no collision: a vehicle that descends into a tree crown lands under it).

A mission's metrics depend on its seed and configs only: every window ends at an instant of the vehicle's clock that
the lockstep fixes, never at the end of the ground truth (the SITL runs on for a wall-clock moment after the companion
lets go, a little longer or shorter with the machine's load).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.config import load_yaml_config
from companion.flightlog.flight_log import DecisionRecord, FlightLog, RecordKind
from companion.guidance.landing import CommandKind, LandingPhase
from companion.guidance.vocabulary import DecisionEvent, DecisionSource, RefusalCause
from companion.perception.selection import Target
from sitl.campaign.landing_kinds import landing_outcome
from sitl.campaign.metric_fields import Summary, result_field
from sitl.config import SitlConfig
from sitl.vehicle.truth import TruthHeader, TruthRecord, body_edges_m, people_at, read_truth, touchdown
from sitl.world.park import Park, ParkObject

METRICS_VERSION = 8
"""Incremented when a definition changes what stored results hold; :func:`stale` says which of them it changes.

1. The first campaigns.
2. A mission without a touchdown ends at the companion's last record, not at the end of the ground truth: the nearest
   person, the path length and the people map of such a mission no longer depend on when the SITL was stopped.
3. Adds what lies under the touchdown (``obstacle_distance_m``, ``obstacle_kind``, ``touched_obstacle``). Nothing
   else changes, so version 2 results are not stale: :func:`with_obstacles` completes them from their seed and
   touchdown point without flying them again.
4. The blind random baseline draws its point around the search area's centre (the geofence's centroid: the paper's
   30 m ROI in the SITL), no longer around the vehicle's position at its first frame, which put some points outside
   the crowd and some outside the geofence (a search until the time limit). Earlier results of the random policy are
   stale; no other result changes.
5. Adds why a mission without a touchdown held (``hold_cause``, from the flight log: :func:`hold_cause`) and how many
   times the landing zone was chosen (``zones_chosen``: commitments and switches, issue 33). Nothing else changes;
   earlier results are not stale (they lack the two fields).
6. ``success`` looks for a body under the vehicle over the *landing descent*, from the walker gate's release to the
   touchdown, no longer over the vehicle's wait at the gate (4.8 m, 3 m above the heads) where the companion hovers
   *because* it sees someone walking towards the landing point and lets them pass. A body that passed under the
   vehicle before the gate let it go is reported in its own field, ``overflown_above_gate``. The landing descent is
   part of the final descent, so a success stays a success: only results that landed and are not a success are stale
   (flown again on resume), but not the random policy's (the blind baseline never waits at the gate); an earlier
   success has ``overflown_above_gate`` False.
7. Adds how a mission ended (``ending``: a zone the map chose, a fallback site, or the last resort;
   :mod:`sitl.campaign.landing_kinds`) and how many fallback sites it flew to (``sites_flown_to``), and the hold
   causes of missions whose fallback sites were all refused or timed out (they had read as the time limit's kinds).
   Nothing else changes; earlier results are not stale (they lack the two fields, and keep their hold causes).
8. Adds where the mission's first landing zone was (``first_zone_north_m``, ``first_zone_east_m``: the centre of the
   zone of its first commitment), so that a report can say how often two policies chose the same zone in the same
   scene (issue 63: ``oldest`` and ``biggest``). Nothing else changes; earlier results are not stale (they lack the
   two fields).
"""


def stale(result: dict[str, Any], policy: str | None = None) -> bool:
    """Whether a stored result differs from what the current definitions give (it is flown again on resume).

    Version 1 results of missions that touched down are unchanged by version 2; those without a touchdown are stale.
    Results of the random policy (``policy``, the mission's selection policy, as its plan names it) before version 4
    are stale. Results before version 6 that touched down and are not a success are stale (version 6 may find them
    one), except the random policy's (the blind baseline lands without the walker gate).
    """
    if "error" in result:
        return False
    version = int(result.get("metrics_version", 1))
    landed = bool(result.get("landed", False))
    return (
        (version < 2 and not landed)
        or (version < 4 and policy == "random")
        or (version < 6 and landed and not result.get("success", False) and policy != "random")
    )


@dataclass
class MissionMetrics:
    """One mission's outcome. NaN (None in JSON) where a metric does not apply (no descent, no touchdown)."""

    mission_id: str
    condition: str
    strategy: str
    run: int
    seed: int
    phase: str
    reason: str
    landed: bool = result_field(Summary.RATE, order=1)
    success: bool = result_field(Summary.RATE, order=0)
    warning_1m: bool = result_field(Summary.RATE, order=2)
    warning_1_5m: bool = result_field(Summary.RATE, order=3)
    people_within_1m: int = result_field(Summary.MEAN, order=10)
    people_within_1_5m: int = result_field(Summary.MEAN, order=11)
    touchdown_nearest_m: float = result_field(Summary.MEAN, order=3)
    zone_area_m2: float = result_field(Summary.MEAN, order=0)
    nearest_person_mean_m: float = result_field(Summary.MEAN, order=1)
    nearest_person_min_m: float = result_field(Summary.MEAN, order=2)
    zone_iou: float = result_field(Summary.MEAN, order=4)
    time_to_land_s: float = result_field(Summary.MEAN, order=5)
    path_length_m: float = result_field(Summary.MEAN, order=6)
    reselections: int = result_field(Summary.MEAN, order=7)
    aborts: int = result_field(Summary.MEAN, order=8)
    failsafes: int = result_field(Summary.MEAN, order=9)
    touchdown_north_m: float = result_field()
    touchdown_east_m: float = result_field()
    obstacle_distance_m: float = result_field(since=3)
    """Horizontal distance from the touchdown point to the nearest solid park object's outline seen from above (tree
    crown, car, bench, bin, bush, pole), 0 inside it; NaN without a touchdown."""
    obstacle_kind: str | None = result_field(since=3)
    """That object's kind."""
    touched_obstacle: bool = result_field(Summary.RATE, order=4, since=3)
    """The vehicle's footprint (``vehicle_radius_m``) overlapped that outline at touchdown: a real vehicle would have
    hit it. Not part of ``success``, which is about people (the issue's definition)."""
    people_cells: list[list[int]] | None = result_field(optional=True)
    """People at touchdown (or at the companion's last record) on a 1 m grid over [-20, 20) m: ``[row, col, count]``
    of the occupied cells (row from north -20 m, col from east -20 m), for the report's touchdown-over-density plots;
    None in a result restored from ``results.csv``, which does not hold them."""
    hold_cause: str | None = result_field(since=5)
    """Why a mission without a touchdown ended (:data:`HOLD_CAUSES`); None after a touchdown."""
    zones_chosen: int = result_field(since=5)
    """How many times the companion chose a landing zone: its first commitment, each commitment after a release, and
    each switch to a rival (``reselections`` counts changes of the target's track id, which a zone that the tracker
    lost and found again also makes)."""
    ending: str | None = result_field(since=7)
    """How the mission ended (:class:`~sitl.campaign.landing_kinds.LandingKind`'s value: ``zone``, ``fallback_site``,
    ``hold``, ``return``, ``failsafe_land``, ``other``); None in a result before version 7."""
    sites_flown_to: int = result_field(since=7)
    """How many fallback sites the mission flew to (the one landed at included); 0 before version 7."""
    first_zone_north_m: float = result_field(since=8)
    """North of the centre of the first zone the mission committed to (world NED, m); NaN with none, or before
    version 8."""
    first_zone_east_m: float = result_field(since=8)
    """East of that centre (world NED, m)."""
    overflown_above_gate: bool = result_field(since=6, default=False)
    """A landing (False without a touchdown) where a person's body came within the vehicle's footprint under it
    during the final descent but before the walker gate let it go: the vehicle hovering at the gate, 3 m above the
    heads, while someone walked under it, or descending towards it. Not part of ``success``, which looks at the
    landing descent (:data:`METRICS_VERSION` 6); ``nearest_person_min_m`` still covers the whole final descent."""
    metrics_version: int = result_field(compared=False, default=METRICS_VERSION)
    """The definitions these were computed with (:data:`METRICS_VERSION`)."""

    def to_json(self) -> dict[str, Any]:
        """JSON-able, NaN as None, floats rounded to 6 decimals (results compare exactly across runs)."""
        out: dict[str, Any] = {}
        for key, value in asdict(self).items():
            if isinstance(value, float):
                out[key] = round(value, 6) if math.isfinite(value) else None
            else:
                out[key] = value
        return out


def _final_descent(flight: FlightLog) -> tuple[float | None, float | None, Target | None]:
    """Start times of the final descent and of its landing descent (the first decision after the last wait at the
    walker gate; the final descent's start without one), and the target when the final descent began."""
    start: float | None = None
    release: float | None = None
    waiting = False
    target: Target | None = None
    previous: LandingPhase | None = None
    last_command_t: float | None = None
    for kind, record in flight.tagged(RecordKind.COMMAND, RecordKind.DECISION):
        if kind is RecordKind.COMMAND:
            last_command_t = float(record["t_s"])
            continue
        decision = DecisionRecord.from_record(record)
        if decision.phase is LandingPhase.DESCENT and previous is not LandingPhase.DESCENT:
            start = release = decision.t_s
            target = decision.target
            waiting = False
        previous = decision.phase
        at_gate = decision.phase is LandingPhase.DESCENT and decision.event is DecisionEvent.WAIT_AT_GATE
        if waiting and not at_gate:
            release = decision.t_s
        waiting = at_gate
        if decision.kind is CommandKind.LAND:
            return start, release, target
    return last_command_t, last_command_t, None


HOLD_CAUSES = {
    "person in the footprint": "every descent allowed was aborted, the last one for a person seen in the footprint",
    "no fresh free map": "every descent allowed was aborted, the last one because no recent map saw the footprint free",
    "zone shrank": "every descent allowed was aborted, the last one because the zone shrank below the footprint",
    "walker kept coming": "every descent allowed was aborted, the last one because someone kept walking towards the "
    "footprint while the descent waited at the walker gate",
    "nothing free": "the time limit, with no zone chosen in its last 30 s: nothing free in view",
    "time limit while searching": "the time limit, searching between zones (a zone chosen in the last 30 s)",
    "time limit while approaching": "the time limit on the way to a chosen zone",
    "time limit while descending": "the time limit during a descent",
    "time limit while climbing back": "the time limit while climbing back after an aborted descent, before choosing "
    "again",
    "perception silent": "no processed frame for the failsafe's time",
    "pilot took over": "the flight mode left offboard without the companion",
    "energy budget": "the battery no longer covered the way home and down with its reserve (guidance.energy)",
    "fallback sites refused": "the search's budget ended and the last fallback site flown to was refused by the map "
    "(or given up from the ground station), none left in reach",
    "fallback site timed out": "the search's budget ended and the last fallback site flown to was not landed on "
    "within its time (guidance.fallback.site_time_s), none left in reach",
    "other": "anything else (the log's reason is in the result)",
}
"""The kinds of :func:`hold_cause`, each with what it means."""

NOTHING_FREE_WINDOW_S = 30.0
SITE_ENDS = (DecisionEvent.TIME_LIMIT, DecisionEvent.ENERGY_LOW, DecisionEvent.FALLBACK_SITE)
"""The events of a last resort after fallback sites: the search's end (time limit, energy budget, ground station).
A last resort with a cause ended a site (refused, timed out); without one, the energy budget gave the site up."""


USED_UP_CAUSES = {
    RefusalCause.PERSON_IN_FOOTPRINT: "person in the footprint",
    RefusalCause.PERSON_AT_GATE: "person in the footprint",
    RefusalCause.NO_FREE_MAP: "no fresh free map",
    RefusalCause.ZONE_SHRANK: "zone shrank",
    RefusalCause.WALKER_KEPT_COMING: "walker kept coming",
}
"""The hold cause of used-up re-selections, by the last refusal's cause."""


def hold_cause(decisions: list[DecisionRecord]) -> str:
    """Why a mission without a touchdown ended, from its decisions (flight-log records; the last one ended it).

    A hold is a decision the log explains: the descents allowed (``guidance.max_reselections``) were all aborted, and
    the last abort names why; or the time limit came, and the phase it came in says whether nothing was free to choose
    or the vehicle was on its way.
    """
    final = decisions[-1] if decisions else None
    event = None if final is None else final.event
    after_sites = any(d.event is DecisionEvent.FALLBACK_SITE for d in decisions[:-1])
    if (
        final is not None
        and final.phase is LandingPhase.FAILSAFE
        and event in SITE_ENDS
        and after_sites
        and final.cause
    ):
        return "fallback site timed out" if final.cause is RefusalCause.SITE_TIMED_OUT else "fallback sites refused"
    if event is DecisionEvent.RESELECTIONS_USED_UP:
        assert final is not None
        return USED_UP_CAUSES.get(final.cause, "other") if final.cause is not None else "other"
    if event in (DecisionEvent.PERCEPTION_HOLD, DecisionEvent.PERCEPTION_FAILSAFE):
        return "perception silent"
    if event is DecisionEvent.PILOT_TOOK_OVER:
        return "pilot took over"
    if event is DecisionEvent.ENERGY_LOW:
        return "energy budget"
    if event is not DecisionEvent.TIME_LIMIT:
        return "other"
    flying = [d for d in decisions if d.source is DecisionSource.FRAME]
    if not flying:
        return "nothing free"
    end_s = flying[-1].t_s
    if flying[-1].event is DecisionEvent.CLIMB_BACK:
        return "time limit while climbing back"
    recent = [d for d in flying if d.t_s >= end_s - NOTHING_FREE_WINDOW_S]
    if not any(d.target is not None for d in recent):
        return "nothing free"
    during = {
        LandingPhase.APPROACH: "time limit while approaching",
        LandingPhase.DESCENT: "time limit while descending",
    }
    return during.get(flying[-1].phase, "time limit while searching")


def zones_chosen(decisions: list[DecisionRecord]) -> int:
    """Commitments and switches the decisions report (:mod:`companion.guidance.commitment`)."""
    return sum(d.chose_zones() for d in decisions)


def mission_metrics(
    run_dir: Path, mission_id: str, condition: str, strategy: str, run: int, seed: int
) -> MissionMetrics:
    """The metrics of the mission flown in ``run_dir`` (``truth.jsonl`` and ``flight/flight.jsonl``)."""
    header, truth = read_truth(run_dir / "truth.jsonl")
    flight = FlightLog.read(run_dir / "flight")
    config = flight.config
    vehicle_radius_m = float(config["perception"]["zones"]["vehicle_radius_m"])
    sitl = load_yaml_config(SitlConfig, run_dir / "sitl.yaml", section="sitl")
    end = flight.outcome
    decisions = flight.decisions()
    ending = landing_outcome(decisions)
    started = next((d.t_s for d in decisions if d.source is DecisionSource.START), math.nan)
    down = touchdown(truth)
    # Without a touchdown the mission ends where the companion's log does (a hold, a yield, its time limit): an instant
    # of the lockstep, unlike the end of the ground truth, which depends on how soon the SITL was stopped.
    stamped = [float(r["t_s"]) for r in flight.records if r.get("t_s") is not None]
    t_end = down.t_s if down is not None else (max(stamped) if stamped else math.nan)
    truth = [r for r in truth if r.t_s <= t_end + 1e-9] if down is None else truth

    descent_t, release_t, target = _final_descent(flight)
    window = [r for r in truth if descent_t is not None and descent_t - 1e-9 <= r.t_s <= t_end + 1e-9]
    nearest = np.array([float(body_edges_m(header, r, r.position_ned_m[0], r.position_ned_m[1]).min()) for r in window])
    # The landing descent: from the walker gate's release (the whole final descent without a wait at the gate).
    landing = np.array([release_t is not None and r.t_s >= release_t - 1e-9 for r in window], dtype=bool)
    nan = math.nan
    within_1 = within_15 = 0
    touchdown_nearest = nan
    if down is not None:
        edges = body_edges_m(header, down, down.position_ned_m[0], down.position_ned_m[1])
        touchdown_nearest = float(edges.min())
        within_1, within_15 = int((edges < 1.0).sum()), int((edges < 1.5).sum())
    under = nearest < vehicle_radius_m
    intrusion = bool(under[landing].any())
    success = (
        down is not None
        and not intrusion
        and not (math.isfinite(touchdown_nearest) and touchdown_nearest < vehicle_radius_m)
    )

    area = iou = nan
    if target is not None and descent_t is not None:
        r_zone = float(target.radius_m)
        area = math.pi * r_zone**2
        at = min(truth, key=lambda r: abs(r.t_s - descent_t)) if truth else None
        if at is not None:
            free = max(0.0, float(body_edges_m(header, at, target.north_m, target.east_m).min()))
            big, small = max(r_zone, free), min(r_zone, free)
            iou = (small / big) ** 2 if big > 0 else nan

    path = np.array([r.position_ned_m for r in truth if math.isfinite(started) and started <= r.t_s <= t_end + 1e-9])
    path_length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) if len(path) > 1 else 0.0
    targets = [d.target.track_id for d in decisions if d.target is not None]
    # The first zone committed to (a commitment within the capture radius goes straight to the descent, whose
    # decision does not carry the change: then the first target of all).
    first = next((d.target for d in decisions if d.chose_zones() and d.target is not None), None) or next(
        (d.target for d in decisions if d.target is not None), None
    )
    reselections = sum(1 for a, b in itertools.pairwise(targets) if a != b)
    aborts = sum(1 for d in decisions if d.event is DecisionEvent.ABORT)
    obstacle_m, obstacle_kind = (
        nearest_obstacle(
            park_layout(sitl.seed, sitl.scenario.roi_side_m, sitl.scenario.clear_ne_m), *down.position_ned_m[:2]
        )
        if down is not None
        else (nan, None)
    )
    return MissionMetrics(
        mission_id=mission_id,
        condition=condition,
        strategy=strategy,
        run=run,
        seed=seed,
        phase=str(end.get("phase", "unknown")),
        reason=str(end.get("reason", "")),
        landed=down is not None,
        success=success,
        warning_1m=within_1 > 0,
        warning_1_5m=within_15 > 0,
        people_within_1m=within_1,
        people_within_1_5m=within_15,
        touchdown_nearest_m=touchdown_nearest,
        zone_area_m2=area,
        nearest_person_mean_m=float(nearest.mean()) if len(nearest) else nan,
        nearest_person_min_m=float(nearest.min()) if len(nearest) else nan,
        zone_iou=iou,
        time_to_land_s=t_end - started if down is not None and math.isfinite(started) else nan,
        path_length_m=path_length,
        reselections=reselections,
        aborts=aborts,
        failsafes=len(end.get("failsafes", [])),
        touchdown_north_m=down.position_ned_m[0] if down is not None else nan,
        touchdown_east_m=down.position_ned_m[1] if down is not None else nan,
        obstacle_distance_m=obstacle_m,
        obstacle_kind=obstacle_kind,
        touched_obstacle=obstacle_m < vehicle_radius_m,
        people_cells=_people_cells(header, down if down is not None else (truth[-1] if truth else None)),
        hold_cause=None if down is not None else hold_cause(decisions),
        zones_chosen=zones_chosen(decisions),
        ending=ending.kind.value,
        sites_flown_to=ending.sites_flown_to,
        first_zone_north_m=float(first.north_m) if first is not None else nan,
        first_zone_east_m=float(first.east_m) if first is not None else nan,
        overflown_above_gate=down is not None and bool(under[~landing].any()),
    )


GRID_HALF_M = 20.0


def _people_cells(header: TruthHeader, record: TruthRecord | None) -> list[list[int]]:
    positions, _ = people_at(header, record)
    cells: dict[tuple[int, int], int] = {}
    for north, east in positions:
        row, col = math.floor(north + GRID_HALF_M), math.floor(east + GRID_HALF_M)
        if 0 <= row < 2 * GRID_HALF_M and 0 <= col < 2 * GRID_HALF_M:
            cells[(row, col)] = cells.get((row, col), 0) + 1
    return [[row, col, count] for (row, col), count in sorted(cells.items())]


def park_layout(
    seed: int, roi_side_m: float, clear_ne_m: Sequence[tuple[float, float, float]] = ()
) -> list[ParkObject]:
    """The objects of the park a SITL with this seed, ROI and clear ground renders (its layout only: no texture is
    painted)."""
    return Park(seed, roi_side_m=roi_side_m, paint=False, clear_ne_m=clear_ne_m).objects


def nearest_obstacle(objects: list[ParkObject], north_m: float, east_m: float) -> tuple[float, str | None]:
    """Distance (m) from a ground point (NED north, east) to the nearest solid object's outline, and its kind;
    ``(inf, None)`` without one."""
    best, kind = math.inf, None
    for o in objects:
        d = o.footprint_distance_m(north_m, east_m)
        if d < best:
            best, kind = d, o.kind.value
    return best, kind


def with_obstacles(result: dict[str, Any], objects: list[ParkObject], vehicle_radius_m: float) -> dict[str, Any]:
    """A stored result of version 2 completed with what lies under its touchdown (see :data:`METRICS_VERSION`); a
    result that has them, or an error line, is returned as it is."""
    if "error" in result or "obstacle_distance_m" in result:
        return result
    north, east = result.get("touchdown_north_m"), result.get("touchdown_east_m")
    distance, kind = (math.nan, None) if north is None or east is None else nearest_obstacle(objects, north, east)
    return {
        **result,
        "obstacle_distance_m": round(distance, 6) if math.isfinite(distance) else None,
        "obstacle_kind": kind,
        "touched_obstacle": distance < vehicle_radius_m,
    }


def with_gate_overflight(result: dict[str, Any], policy: str | None = None) -> dict[str, Any]:
    """A stored result of an earlier version completed with ``overflown_above_gate`` where that needs no flight (see
    :data:`METRICS_VERSION` 6): False after a success (no body came under the vehicle in its whole final descent),
    without a touchdown, or for the random policy (``policy``, as in :func:`stale`: it lands blind, without the gate,
    so its landing descent is its whole final descent). A stale result (:func:`stale`: a landing of another policy that
    is not a success) is returned as it is, as are results that have the field and error lines."""
    if "error" in result or "overflown_above_gate" in result or stale(result, policy):
        return result
    return {**result, "overflown_above_gate": False}
