"""Fallback sites in the landing logic, frame by frame on hand-made maps (no processes, no network): when the search's
budget ends the vehicle flies to the nearest surveyed site in reach, checks it with its map as it checks a zone, and
lands there, or moves on to the next, or ends in the last resort."""

from __future__ import annotations

import math

import pytest

from companion.guidance.landing import CommandKind, Decision, LandingGuidance, LandingPhase
from companion.guidance.stimulus import Denied, EnergyLow, FrameSeen, OperatorOrder, Started, TimeUp
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent, OperatorCommand, RefusalCause
from companion.perception.projection import HeadPlaneOccupancy
from tests.test_landing_logic import _frame, _guidance, _map

pytestmark = pytest.mark.unit

# Two surveyed sites inside the test fence (+-20 m): "lawn" 10 m north, "yard" 15 m east-south.
SITES = [
    {"name": "lawn", "north_m": 10.0, "east_m": 0.0, "radius_m": 3.0},
    {"name": "yard", "north_m": -9.0, "east_m": 12.0, "radius_m": 3.0},
]


def searching(**overrides: object) -> tuple[LandingGuidance, VehicleState]:
    """A mission with the sites and a 60 s time limit, started at t = 0 at 20 m over the origin."""
    settings: dict[str, object] = {"mission_time_limit_s": 60.0, "fallback": {"sites": SITES, "site_time_s": 90.0}}
    g = _guidance(**{**settings, **overrides})
    state = VehicleState(0.0, 0.0, 0.0, -20.0, 0.0)
    g.on(Started(state))
    return g, state


def fly(g: LandingGuidance, state: VehicleState, t_s: float, maps: HeadPlaneOccupancy) -> tuple[Decision, VehicleState]:
    """One frame with no zone seen (the map ``maps``), and the vehicle at the decision's setpoint."""
    d = g.on(FrameSeen(state, _frame(t_s, [], None, maps), seq=0))
    if d.setpoint is None:
        return d, VehicleState(t_s, state.north_m, state.east_m, state.down_m, 0.0)
    sp = d.setpoint
    return d, VehicleState(t_s, sp.north_m, sp.east_m, sp.down_m, 0.0)


def frames(
    g: LandingGuidance, state: VehicleState, t_s: float, maps: HeadPlaneOccupancy, last: set[object]
) -> tuple[list[Decision], VehicleState, float]:
    """Frames at 10 Hz, the vehicle at each setpoint, until a decision's phase or kind is in ``last`` (within 200 s
    of vehicle time); every decision made."""
    made: list[Decision] = []
    end_s = t_s + 200.0
    while t_s < end_s:
        t_s += 0.1
        d, state = fly(g, state, t_s, maps)
        made.append(d)
        if d.phase in last or d.kind in last:
            return made, state, t_s
    raise AssertionError(f"none of {last} within 200 s (last: {made[-1].phase.value}, {made[-1].reason})")


def test_when_the_time_is_used_up_the_nearest_site_is_flown_to_checked_and_landed_on() -> None:
    g, state = searching()
    assert g.on(TimeUp(VehicleState(59.9, 0.0, 0.0, -20.0, 0.0))) is None
    d = g.on(TimeUp(VehicleState(60.0, 0.0, 0.0, -20.0, 0.0)))
    assert d is not None
    assert (d.phase, d.event, d.kind) == (LandingPhase.APPROACH, DecisionEvent.FALLBACK_SITE, CommandKind.SETPOINT)
    assert d.reason == "no landing within 60 s of the start: fallback site lawn, 10 m away"
    assert d.target is not None
    assert (d.target.north_m, d.target.east_m) == (10.0, 0.0)
    made, state, _ = frames(g, state, 60.0, _map(), {CommandKind.LAND})
    assert LandingPhase.DESCENT in [m.phase for m in made]  # checked on the way down, as a zone
    assert made[-1].target is not None
    assert made[-1].target.north_m == 10.0
    assert math.hypot(state.north_m - 10.0, state.east_m) <= g.config.capture_radius_m


def test_a_site_the_map_refuses_is_given_up_for_the_next_and_with_none_left_the_last_resort() -> None:
    g, state = searching()
    g.on(TimeUp(VehicleState(60.0, 0.0, 0.0, -20.0, 0.0)))
    lawn, yard = _map(person_at=(10.2, 0.3)), _map(person_at=(-9.0, 12.2))
    both_taken = HeadPlaneOccupancy(lawn.grid, lawn.free & yard.free, lawn.known)
    made, state, _ = frames(g, state, 60.0, both_taken, {LandingPhase.FAILSAFE})
    moves = [m for m in made if m.event is DecisionEvent.FALLBACK_SITE]
    assert [(m.target.north_m if m.target else None, m.cause) for m in moves] == [
        (-9.0, RefusalCause.PERSON_IN_FOOTPRINT)  # the lawn refused: the yard
    ]
    last = made[-1]
    assert last.kind is CommandKind.HOLD  # the last resort, never a landing the map refused
    assert last.reason.endswith("site yard refused; no fallback site left in reach: hold")
    assert (last.event, last.cause) == (DecisionEvent.TIME_LIMIT, RefusalCause.PERSON_IN_FOOTPRINT)
    assert g.reselections == 0  # a refused site spends no re-selection


def test_a_site_not_landed_on_in_its_time_is_given_up() -> None:
    g, _ = searching(fallback={"sites": SITES[:1], "site_time_s": 5.0})
    g.on(TimeUp(VehicleState(60.0, 0.0, 0.0, -20.0, 0.0)))
    assert g.on(TimeUp(VehicleState(64.9, 0.0, 0.0, -20.0, 0.0))) is None
    d = g.on(TimeUp(VehicleState(65.0, 0.0, 0.0, -20.0, 0.0)))
    assert d is not None
    assert (d.phase, d.kind, d.cause) == (LandingPhase.FAILSAFE, CommandKind.HOLD, RefusalCause.SITE_TIMED_OUT)
    assert d.reason == "not landed at site lawn within 5 s; no fallback site left in reach: hold"


def test_with_the_energy_budget_only_sites_no_farther_than_home_are_in_reach() -> None:
    g, _ = searching(energy={"enabled": True, "capacity_mah": 5000})
    out_of_reach = g.on(EnergyLow(VehicleState(30.0, 0.0, 0.0, -20.0, 0.0), "energy budget used up", reach_m=8.0))
    assert out_of_reach is not None
    assert (out_of_reach.kind, out_of_reach.event) == (CommandKind.RETURN, DecisionEvent.ENERGY_LOW)
    assert out_of_reach.reason == "energy budget used up; no fallback site left in reach: return"
    g, _ = searching(energy={"enabled": True, "capacity_mah": 5000})
    in_reach = g.on(EnergyLow(VehicleState(30.0, 0.0, 0.0, -20.0, 0.0), "energy budget used up", reach_m=12.0))
    assert in_reach is not None
    assert in_reach.event is DecisionEvent.FALLBACK_SITE
    assert in_reach.target is not None
    assert in_reach.target.north_m == 10.0


def test_the_energy_budget_ending_at_a_site_chosen_before_gives_it_up_when_it_lies_farther_than_home() -> None:
    g, _ = searching(energy={"enabled": True, "capacity_mah": 5000})
    chosen = g.on(OperatorOrder(VehicleState(5.0, 0.0, 0.0, -20.0, 0.0), OperatorCommand.NEXT_FALLBACK, False, False))
    assert isinstance(chosen, Decision)
    assert g.fallback.current is not None
    assert g.fallback.current.name == "lawn"
    # Home is 8 m away, the lawn 10 m and the yard 15 m: neither may be flown to any more.
    d = g.on(EnergyLow(VehicleState(6.0, 0.0, 0.0, -20.0, 0.0), "energy budget used up", reach_m=8.0))
    assert d is not None
    assert (d.phase, d.kind, d.event) == (LandingPhase.FAILSAFE, CommandKind.RETURN, DecisionEvent.ENERGY_LOW)
    assert d.reason == "energy budget used up: site lawn out of reach; no fallback site left in reach: return"


def test_the_energy_budget_ending_at_a_site_in_reach_flies_on_and_ends_in_its_own_action() -> None:
    g, _ = searching(energy={"enabled": True, "capacity_mah": 5000})
    assert g.on(TimeUp(VehicleState(60.0, 0.0, 0.0, -20.0, 0.0))) is not None  # the time limit: the lawn
    at = VehicleState(61.0, 5.0, 0.0, -20.0, 0.0)  # 5 m from the lawn, home 6 m away
    d = g.on(EnergyLow(at, "energy budget used up", reach_m=6.0))
    assert d is not None
    assert (d.phase, d.kind, d.event) == (LandingPhase.APPROACH, CommandKind.NONE, DecisionEvent.ENERGY_LOW)
    assert d.reason == "energy budget used up: site lawn in reach, flown on"
    assert d.target is not None
    assert d.target.north_m == 10.0
    assert g.on(EnergyLow(VehicleState(61.1, 5.0, 0.0, -20.0, 0.0), "energy budget used up", reach_m=6.0)) is None
    # The lawn is refused: the yard (22 m away) is out of reach, and the energy budget's action ends it.
    made, _, _ = frames(g, at, 61.0, _map(person_at=(10.2, 0.3)), {LandingPhase.FAILSAFE})
    last = made[-1]
    assert (last.kind, last.event) == (CommandKind.RETURN, DecisionEvent.ENERGY_LOW)
    assert last.reason.endswith("site lawn refused; no fallback site left in reach: return")


def test_without_sites_the_end_of_the_budget_is_the_decision_it_always_was() -> None:
    g = _guidance(mission_time_limit_s=60.0)
    g.on(Started(VehicleState(0.0, 0.0, 0.0, -20.0, 0.0)))
    d = g.on(TimeUp(VehicleState(60.0, 0.0, 0.0, -20.0, 0.0)))
    assert d is not None
    assert (d.reason, d.event, d.cause) == ("no landing within 60 s of the start: hold", DecisionEvent.TIME_LIMIT, None)


# -- "next fallback site" from the ground station (an OperatorOrder to the landing logic) ---------------------------
def test_the_ground_stations_next_site_ends_the_search_for_the_nearest_site_then_the_one_after() -> None:
    g, state = searching()
    d = g.on(OperatorOrder(VehicleState(5.0, 0.0, 0.0, -20.0, 0.0), OperatorCommand.NEXT_FALLBACK, False, False))
    assert isinstance(d, Decision)
    assert (d.phase, d.event, d.cause) == (LandingPhase.APPROACH, DecisionEvent.FALLBACK_SITE, RefusalCause.OPERATOR)
    assert d.reason == "next fallback site, from the ground station: fallback site lawn, 10 m away"
    assert d.target is not None
    assert (d.target.north_m, d.target.east_m) == (10.0, 0.0)
    # Asked again on the way: the lawn is given up for the yard.
    d = g.on(OperatorOrder(VehicleState(8.0, 4.0, 0.0, -20.0, 0.0), OperatorCommand.NEXT_FALLBACK, False, False))
    assert isinstance(d, Decision)
    assert d.target is not None
    assert (d.target.north_m, d.target.east_m) == (-9.0, 12.0)
    # None left: denied, nothing changes (the yard is still flown to and checked).
    denied = g.on(OperatorOrder(VehicleState(9.0, 0.0, 4.0, -20.0, 0.0), OperatorCommand.NEXT_FALLBACK, False, False))
    assert denied == Denied("no fallback site left to try in reach")
    assert g.target is not None
    assert g.target.north_m == -9.0
    made, state, _ = frames(g, VehicleState(9.0, 0.0, 4.0, -20.0, 0.0), 9.0, _map(), {CommandKind.LAND})
    assert LandingPhase.DESCENT in [m.phase for m in made]  # checked on the way down
    assert math.hypot(state.north_m + 9.0, state.east_m - 12.0) <= g.config.capture_radius_m


def test_next_site_is_denied_without_sites_or_outside_a_search() -> None:
    g, state = searching(fallback={"sites": []})
    assert g.on(OperatorOrder(state, OperatorCommand.NEXT_FALLBACK, False, False)) == Denied(
        "no fallback sites in this mission (guidance.fallback)"
    )
    g = _guidance(fallback={"sites": SITES})
    idle = g.on(OperatorOrder(VehicleState(0.0, 0.0, 0.0, -20.0, 0.0), OperatorCommand.NEXT_FALLBACK, False, False))
    assert idle == Denied("no search, approach or descent to act on (phase idle)")


def test_a_site_the_ground_station_chose_that_the_map_refuses_ends_in_the_last_resort() -> None:
    g, state = searching(fallback={"sites": SITES[:1], "site_time_s": 90.0})
    d = g.on(OperatorOrder(state, OperatorCommand.NEXT_FALLBACK, False, False))
    assert isinstance(d, Decision)
    made, _, _ = frames(g, state, 0.0, _map(person_at=(10.2, 0.3)), {LandingPhase.FAILSAFE})
    last = made[-1]
    assert last.kind is CommandKind.HOLD
    assert last.reason.endswith("site lawn refused; no fallback site left in reach: hold")
