"""The landing state machine, frame by frame, on hand-made maps and tracks (no processes, no network).

Each test reads like a flight: where the vehicle is, what perception reports, what the logic commands.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from companion.config import ConfigError, validate_config
from companion.geometry import Pose
from companion.guidance.config import FailsafeAction, GuidanceConfig
from companion.guidance.footprint import footprint_view
from companion.guidance.geofence import Geofence, GeofenceConfig
from companion.guidance.landing import CommandKind, Decision, LandingGuidance, LandingPhase
from companion.guidance.stimulus import FrameSeen, Landed, PilotTookOver, Silence, Started, TimeUp
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent
from companion.perception.density import DensityMap
from companion.perception.occupancy import OccupancyImage
from companion.perception.pipeline import FrameResult
from companion.perception.projection import GridSpec, HeadPlaneOccupancy
from companion.perception.selection import BiggestPolicy, Target
from companion.perception.tracking import TrackedZone

pytestmark = pytest.mark.unit

FENCE = Geofence(GeofenceConfig(polygon_ne_m=[(-20, -20), (-20, 20), (20, 20), (20, -20)], max_altitude_m=40))
FOOTPRINT_M = 1.0  # vehicle radius 0.5 + margin 0.5


def _map(
    free: bool = True, person_at: tuple[float, float] | None = None, known_radius_m: float = 30.0
) -> HeadPlaneOccupancy:
    grid = GridSpec(north_min_m=-20.0, east_min_m=-20.0, resolution_m=0.1, rows=400, cols=400)
    nn, ee = np.meshgrid(grid.north_centres_m, grid.east_centres_m, indexing="ij")
    known = np.hypot(nn, ee) <= known_radius_m
    free_cells = np.full(known.shape, free) & known
    if person_at is not None:
        free_cells &= np.hypot(nn - person_at[0], ee - person_at[1]) > 0.8
    return HeadPlaneOccupancy(grid, free_cells, known)


def _track(track_id: int, n: float, e: float, r: float, misses: int = 0) -> TrackedZone:
    return TrackedZone(track_id, n, e, r, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 5, misses)


def _frame(t_s: float, tracks: list[TrackedZone], target: Target | None, head_plane: HeadPlaneOccupancy) -> FrameResult:
    empty = np.zeros((120, 160), np.float32)
    return FrameResult(
        t_s,
        Pose.from_ned_euler(0, 0, -10),
        DensityMap(empty, 640, 480),
        OccupancyImage(np.full((120, 160), 255, np.uint8), 0),
        head_plane,
        [],
        tracks,
        target,
    )


def _guidance(**overrides: object) -> LandingGuidance:
    """Frame-by-frame landing logic; its first choice at once (``commitment.observe_s`` 0) unless a test sets it."""
    commitment = overrides.get("commitment")
    overrides["commitment"] = {"observe_s": 0.0, **(commitment if isinstance(commitment, dict) else {})}
    return LandingGuidance(
        GuidanceConfig.model_validate(overrides), FENCE, FOOTPRINT_M, min_zone_radius_m=1.0, policy=BiggestPolicy()
    )


def _fly(state: VehicleState, setpoint_alt: float, n: float, e: float, t: float) -> VehicleState:
    return VehicleState(t, n, e, -setpoint_alt, 0.0)


def test_the_first_choice_holds_position_for_the_observation_window_and_no_search_pattern_starts() -> None:
    g = _guidance(commitment={"observe_s": 8.0}, search_timeout_s=2.0)  # a window longer than the search timeout
    state = VehicleState(0.0, 0.0, 0.0, -20.0, 0.0)
    g.on(Started(state))
    zone = _track(7, 6.0, 8.0, 2.5)
    t = 0.0
    while t < 7.95:  # from the first frame with a zone at 0.1 s: watching, holding where it is
        t += 0.1
        d = g.on(FrameSeen(state, _frame(t, [zone], Target(6.0, 8.0, 2.5, 7), _map()), seq=0))
        assert d.phase is LandingPhase.SEARCH
        assert d.event is DecisionEvent.HOLD_NO_TARGET, t
        assert "watching zones" in d.reason
        assert d.setpoint is not None
        assert (d.setpoint.north_m, d.setpoint.east_m) == pytest.approx((0.0, 0.0))
    d = g.on(FrameSeen(state, _frame(8.2, [zone], Target(6.0, 8.0, 2.5, 7), _map()), seq=0))
    assert d.phase is LandingPhase.APPROACH
    assert g.commitment.committed_id == 7


def test_a_clean_landing_goes_search_approach_descent_land() -> None:
    g = _guidance()
    state = VehicleState(0.0, 0.0, 0.0, -15.0, 0.0)
    start = g.on(Started(state))
    assert start.phase is LandingPhase.SEARCH
    assert start.setpoint is not None
    assert -start.setpoint.down_m == pytest.approx(20.0)  # climbs to the search altitude
    zone = _track(7, 6.0, 8.0, 2.5)
    target = Target(6.0, 8.0, 2.5, 7)
    phases = []
    t = 0.0
    while g.phase not in (LandingPhase.LAND, LandingPhase.SEARCH) or t == 0.0:
        t += 0.1
        d = g.on(FrameSeen(state, _frame(t, [zone], target, _map()), seq=0))
        phases.append(d.phase)
        if d.kind is CommandKind.LAND:
            break
        assert d.kind is CommandKind.SETPOINT
        assert d.setpoint is not None
        sp = d.setpoint
        # Safety filter: inside the fence, a bounded step, a bounded drop.
        assert FENCE.contains(sp.north_m, sp.east_m, -sp.down_m)
        assert math.hypot(sp.north_m - state.north_m, sp.east_m - state.east_m) <= 4.0 + 1e-9
        assert -sp.down_m >= state.altitude_m - 1.0 - 1e-9
        state = _fly(state, -sp.down_m, sp.north_m, sp.east_m, t)
        assert t < 60.0
    assert phases[0] is LandingPhase.APPROACH
    assert LandingPhase.DESCENT in phases
    assert phases[-1] is LandingPhase.LAND
    assert math.hypot(state.north_m - 6.0, state.east_m - 8.0) <= 0.75
    assert state.altitude_m <= 2.05
    assert g.on(Landed(VehicleState(t + 1, state.north_m, state.east_m, 0.0, 0.0))).phase is LandingPhase.DONE


def _descending_over(g: LandingGuidance, alt: float) -> VehicleState:
    state = VehicleState(0.0, 0.0, 0.0, -alt, 0.0)
    g.on(Started(state))
    d = g.on(FrameSeen(state, _frame(0.1, [_track(3, 0.2, 0.0, 3.0)], Target(0.2, 0.0, 3.0, 3), _map()), seq=0))
    assert d.phase is LandingPhase.DESCENT
    return state


def test_a_person_walking_into_the_footprint_aborts_the_descent() -> None:
    g = _guidance()
    state = _descending_over(g, 14.0)
    need = g.config.unsafe_frames_to_abort
    zone, target, occupied = _track(3, 0.2, 0.0, 3.0), Target(0.2, 0.0, 3.0, 3), _map(person_at=(0.5, 0.3))
    for k in range(need - 1):  # fewer frames in a row than the limit: the model's flicker, not yet a person
        assert (
            g.on(FrameSeen(state, _frame(0.2 + 0.1 * k, [zone], target, occupied), seq=0)).phase is LandingPhase.DESCENT
        )
    d = g.on(FrameSeen(state, _frame(1.0, [zone], target, occupied), seq=0))  # the limit reached: a person
    assert d.phase is LandingPhase.SEARCH
    assert "person" in d.reason
    assert d.setpoint is not None
    assert -d.setpoint.down_m > state.altitude_m  # climbs back
    assert g.reselections == 1


def test_a_flickering_false_positive_does_not_abort() -> None:
    g = _guidance()
    state = _descending_over(g, 14.0)
    zone, target = _track(3, 0.2, 0.0, 3.0), Target(0.2, 0.0, 3.0, 3)
    for k in range(20):  # occupied every other frame: never the limit in a row
        head_plane = _map(person_at=(0.5, 0.3)) if k % 2 else _map()
        assert (
            g.on(FrameSeen(state, _frame(0.2 + 0.1 * k, [zone], target, head_plane), seq=0)).phase
            is LandingPhase.DESCENT
        )
    assert g.reselections == 0


def test_the_footprint_is_checked_at_the_landing_point_not_under_the_vehicle() -> None:
    g = _guidance()
    state = VehicleState(0.0, 0.0, 0.0, -14.0, 0.0)
    g.on(Started(state))
    zone, target = _track(3, 0.6, 0.0, 3.0), Target(0.6, 0.0, 3.0, 3)  # the landing point 0.6 m north
    assert g.on(FrameSeen(state, _frame(0.1, [zone], target, _map()), seq=0)).phase is LandingPhase.DESCENT
    beside_vehicle = _map(person_at=(-1.4, 0.0))  # occupied 0.6 m from the vehicle, 1.2 m from the landing point
    for k in range(2 * g.config.unsafe_frames_to_abort):
        assert (
            g.on(FrameSeen(state, _frame(0.2 + 0.1 * k, [zone], target, beside_vehicle), seq=0)).phase
            is LandingPhase.DESCENT
        )


def test_a_lost_track_keeps_the_landing_point_and_a_shrinking_zone_aborts() -> None:
    g = _guidance()
    state = _descending_over(g, 12.0)
    for k in range(10):  # the zone's track comes and goes with a noisy map: the landing point stays
        d = g.on(FrameSeen(state, _frame(0.2 + 0.1 * k, [], None, _map()), seq=0))
        assert d.phase is LandingPhase.DESCENT
        assert d.setpoint is not None
        assert (d.setpoint.north_m, d.setpoint.east_m) == pytest.approx((0.2, 0.0))
    g2 = _guidance()
    state = _descending_over(g2, 12.0)
    shrunk = _track(3, 0.2, 0.0, 0.6)
    for k in range(g2.config.unsafe_frames_to_abort - 1):
        assert (
            g2.on(FrameSeen(state, _frame(0.2 + 0.1 * k, [shrunk], None, _map()), seq=0)).phase is LandingPhase.DESCENT
        )
    d = g2.on(FrameSeen(state, _frame(1.0, [shrunk], None, _map()), seq=0))
    assert d.phase is LandingPhase.SEARCH
    assert "shrank" in d.reason


@pytest.mark.parametrize("reacquire", [True, False])
def test_a_zone_the_tracker_starts_anew_over_the_landing_point_refines_it(reacquire: bool) -> None:
    # Issue 63's ROI table (moving_10/oldest/0027, replayed): at the gate a walker reshaped the zone, its track was
    # lost and the tracker started another 0.6 m beside the point; the footprint around the stale point overlapped
    # the map's margin around people 2 m away, and the descent waited there 20 s and refused the point.
    def descending(g: LandingGuidance) -> VehicleState:
        state = VehicleState(0.0, 0.0, 0.0, -12.0, 0.0)
        g.on(Started(state))
        d = g.on(FrameSeen(state, _frame(0.1, [_track(3, 0.2, 0.0, 1.2)], Target(0.2, 0.0, 1.2, 3), _map()), seq=0))
        assert d.phase is LandingPhase.DESCENT
        return state

    g = _guidance(commitment={"reacquire_in_descent": reacquire})
    state = descending(g)  # over zone 3 at (0.2, 0.0), 1.2 m free around it
    anew = _track(9, -0.4, 0.0, 1.5)  # the same free ground, a new track: IoU 0.52 with the point's circle ...
    near_person = _map(person_at=(1.6, 0.0))  # ... and occupied to 0.8 m north of the point, inside its footprint
    decisions = [
        g.on(FrameSeen(state, _frame(0.2 + 0.1 * k, [anew], None, near_person), seq=0))
        for k in range(2 * g.config.unsafe_frames_to_abort)
    ]
    if reacquire:
        assert all(d.phase is LandingPhase.DESCENT for d in decisions)
        assert g.descent.locked == Target(-0.4, 0.0, 1.5, 9)
        assert "over zone 9" in decisions[-1].reason
        assert g.reselections == 0
    else:  # before issue 63: the stale point, a person in its footprint, the descent refused
        assert any(d.phase is LandingPhase.SEARCH and "person" in d.reason for d in decisions)
        assert g.reselections == 1
    shrunk = _guidance()  # a zone smaller than a landing needs does not take the point over (IoU 0.56)
    state = descending(shrunk)
    d = shrunk.on(FrameSeen(state, _frame(0.2, [_track(9, 0.0, 0.0, 0.9)], None, _map()), seq=0))
    assert d.phase is LandingPhase.DESCENT
    assert shrunk.descent.locked == Target(0.2, 0.0, 1.2, 3)


def test_a_zone_outside_the_geofence_is_never_approached() -> None:
    g = _guidance()
    state = VehicleState(0.0, 15.0, 0.0, -20.0, 0.0)
    g.on(Started(state))
    outside = Target(25.0, 0.0, 3.0, 7)  # the fence ends at 20 m north
    d = g.on(FrameSeen(state, _frame(0.1, [_track(7, 25.0, 0.0, 3.0)], outside, _map()), seq=0))
    assert d.phase is LandingPhase.SEARCH
    assert d.setpoint is not None
    assert FENCE.contains_ne(d.setpoint.north_m, d.setpoint.east_m)


def test_no_landing_without_a_recent_map_of_a_free_footprint() -> None:
    g = _guidance(walkers={"enabled": False})  # the walker gate would first send it back up to look
    # Descend blind (nothing known around the vehicle), the zone still tracked: at 2 m it must not land.
    state = VehicleState(0.0, 0.0, 0.0, -2.0, 0.0)
    g.on(Started(state))
    blind = _map(known_radius_m=0.0)
    d = g.on(FrameSeen(state, _frame(0.1, [_track(3, 0.0, 0.0, 3.0)], Target(0.0, 0.0, 3.0, 3), blind), seq=0))
    assert d.kind is not CommandKind.LAND
    assert d.phase is LandingPhase.SEARCH
    assert "no map saw the footprint free" in d.reason


def test_silence_holds_then_runs_the_failsafe_action() -> None:
    g = _guidance(failsafe_action=FailsafeAction.RETURN)
    state = VehicleState(0.0, 1.0, 2.0, -18.0, 30.0)
    g.on(Started(state))
    assert g.on(Silence(state, 0.5)) is None
    hold = g.on(Silence(state, 1.2))
    assert hold is not None
    assert hold.phase is LandingPhase.HOLD
    assert hold.setpoint is not None
    assert (hold.setpoint.north_m, hold.setpoint.east_m, hold.setpoint.down_m) == pytest.approx((1.0, 2.0, -18.0))
    action = g.on(Silence(state, 5.5))
    assert action is not None
    assert action.kind is CommandKind.RETURN
    assert not g.commanding
    # Perception back after a hold (before T2) resumes the search.
    g2 = _guidance()
    g2.on(Started(state))
    g2.on(Silence(state, 1.5))
    assert g2.on(FrameSeen(state, _frame(2.0, [], None, _map()), seq=0)).phase is LandingPhase.SEARCH


def test_the_pilot_taking_over_is_final() -> None:
    g = _guidance()
    state = _descending_over(g, 14.0)
    assert g.on(PilotTookOver(VehicleState(1.0, 0.0, 0.0, -14.0, 0.0), "POSCTL")).phase is LandingPhase.YIELDED
    d = g.on(FrameSeen(state, _frame(1.1, [_track(3, 0.2, 0.0, 3.0)], Target(0.2, 0.0, 3.0, 3), _map()), seq=0))
    assert d.kind is CommandKind.NONE
    assert g.on(Silence(state, 30.0)) is None
    assert not g.commanding


def test_no_target_for_a_while_flies_a_search_pattern_inside_the_fence() -> None:
    g = _guidance(search_timeout_s=1.0, search_leg_m=8.0)
    state = VehicleState(0.0, 15.0, 15.0, -20.0, 0.0)
    g.on(Started(state))
    points = []
    for k in range(1, 80):
        state = VehicleState(0.1 * k, 15.0, 15.0, -20.0, 0.0)  # the vehicle clock runs; the vehicle stays put
        d = g.on(FrameSeen(state, _frame(0.1 * k, [], None, _map()), seq=0))
        assert d.setpoint is not None
        points.append((d.setpoint.north_m, d.setpoint.east_m))
        assert FENCE.contains(d.setpoint.north_m, d.setpoint.east_m, -d.setpoint.down_m)
    assert len({(round(n), round(e)) for n, e in points}) >= 3  # it moves


def test_footprint_view_counts_known_and_occupied_cells() -> None:
    view = footprint_view(_map(), 0.0, 0.0, 1.0)
    assert view.known_fraction == pytest.approx(1.0, abs=0.05)
    assert view.clear
    assert footprint_view(_map(person_at=(0.9, 0.0)), 0.0, 0.0, 1.0).occupied_seen
    assert footprint_view(_map(known_radius_m=0.5), 0.0, 0.0, 1.0).known_fraction == pytest.approx(0.25, abs=0.05)


def test_inconsistent_guidance_config_is_named() -> None:
    with pytest.raises(ConfigError, match="failsafe_after_silence_s"):
        validate_config(GuidanceConfig, {"hold_after_silence_s": 5, "failsafe_after_silence_s": 2}, prefix="guidance")
    with pytest.raises(ConfigError, match=r"guidance\.capture_radius_m"):
        validate_config(GuidanceConfig, {"capture_radius_m": -1}, prefix="guidance")


def test_used_up_reselections_hold_and_never_land() -> None:
    g = _guidance(max_reselections=1, failsafe_action=FailsafeAction.LAND, unsafe_frames_to_abort=2)
    state = _descending_over(g, 14.0)
    occupied = _map(person_at=(0.5, 0.3))
    zone, target = _track(3, 0.2, 0.0, 3.0), Target(0.2, 0.0, 3.0, 3)
    g.on(FrameSeen(state, _frame(0.2, [zone], target, occupied), seq=0))
    assert g.on(FrameSeen(state, _frame(0.25, [zone], target, occupied), seq=0)).phase is LandingPhase.SEARCH
    climbed = VehicleState(0.3, state.north_m, state.east_m, -g.config.search_altitude_m, 0.0)  # back up
    # The refused zone is not chosen again; one 5 m away is.
    assert g.on(FrameSeen(climbed, _frame(0.3, [zone], target, _map()), seq=0)).target is None
    other, other_target = _track(4, 0.2, 5.0, 3.0), Target(0.2, 5.0, 3.0, 4)
    over_other = VehicleState(0.35, 0.2, 5.0, climbed.down_m, 0.0)
    assert (
        g.on(FrameSeen(over_other, _frame(0.35, [zone, other], other_target, _map()), seq=0)).phase
        is LandingPhase.DESCENT
    )
    occupied_other = _map(person_at=(0.5, 5.3))
    g.on(FrameSeen(over_other, _frame(0.4, [other], other_target, occupied_other), seq=0))
    last = g.on(FrameSeen(over_other, _frame(0.45, [other], other_target, occupied_other), seq=0))
    assert last.phase is LandingPhase.FAILSAFE
    assert last.kind is CommandKind.HOLD  # not the configured land: the map just refused a landing here


def test_below_the_models_altitude_range_maps_do_not_decide() -> None:
    g = _guidance(perception_min_altitude_m=6.0, walkers={"enabled": False})  # no look at the gate (tested below)
    _descending_over(g, 7.0)  # this frame's map (free footprint) is the landing map
    low = VehicleState(1.0, 0.2, 0.0, -4.0, 0.0)
    d = g.on(FrameSeen(low, _frame(1.0, [], None, _map(person_at=(0.3, 0.0))), seq=0))
    assert d.phase is LandingPhase.DESCENT  # ground texture at 4 m is not trusted to be a person
    at_two = VehicleState(2.0, 0.2, 0.0, -2.0, 0.0)
    assert g.on(FrameSeen(at_two, _frame(2.0, [], None, _map(person_at=(0.3, 0.0))), seq=0)).kind is CommandKind.LAND


def test_the_blind_baseline_lands_on_its_point_whatever_the_map_says() -> None:
    g = _guidance(blind_landing=True)  # the paper's "random landing", for campaigns only
    point = Target(0.3, 0.0, 0.0, None)  # the random policy's committed point: no zone, no track
    occupied = _map(person_at=(0.3, 0.0))
    state = VehicleState(0.0, 0.0, 0.0, -14.0, 0.0)
    g.on(Started(state))
    for k in range(8):
        assert g.on(FrameSeen(state, _frame(0.1 * k, [], point, occupied), seq=0)).phase is LandingPhase.DESCENT
    low = VehicleState(1.0, 0.3, 0.0, -2.0, 0.0)
    assert g.on(FrameSeen(low, _frame(1.0, [], point, occupied), seq=0)).kind is CommandKind.LAND
    assert _guidance().config.blind_landing is False  # never by default


def test_a_mission_that_never_lands_holds_when_its_time_is_used_up() -> None:
    g = _guidance(mission_time_limit_s=60.0)
    assert g.on(TimeUp(VehicleState(0.0, 0.0, 0.0, -20.0, 0.0))) is None  # not started
    g.on(Started(VehicleState(10.0, 0.0, 0.0, -20.0, 0.0)))
    assert g.on(TimeUp(VehicleState(69.9, 0.0, 0.0, -20.0, 0.0))) is None
    d = g.on(TimeUp(VehicleState(70.0, 0.0, 0.0, -20.0, 0.0)))  # vehicle clock, 60 s after the start
    assert d is not None
    assert d.phase is LandingPhase.FAILSAFE
    assert d.kind is CommandKind.HOLD  # never a blind landing
    assert not g.commanding


def _aborted_low_down(g: LandingGuidance) -> VehicleState:
    """A descent at 6 m (above the walker gate, where a person is waited out) aborted for a person in the footprint."""
    state = _descending_over(g, 6.0)
    zone, target, occupied = _track(3, 0.2, 0.0, 3.0), Target(0.2, 0.0, 3.0, 3), _map(person_at=(0.5, 0.3))
    for k in range(g.config.unsafe_frames_to_abort):
        d = g.on(FrameSeen(state, _frame(0.2 + 0.1 * k, [zone], target, occupied), seq=0))
    assert d.phase is LandingPhase.SEARCH
    return state


def test_after_an_abort_low_down_a_new_descent_waits_until_the_vehicle_has_climbed_back() -> None:
    g = _guidance(commitment={"refused_radius_m": 0.0})  # the climb alone, without the refused point's exclusion
    state = _aborted_low_down(g)
    assert g.config.climb_back_m is not None
    climb_to = 6.0 + g.config.climb_back_m
    # Another free zone right under the vehicle: approached (climbing), not descended onto from 4 m.
    other, other_target = _track(4, 0.3, 0.1, 3.0), Target(0.3, 0.1, 3.0, 4)
    t = 1.0
    while state.altitude_m < climb_to - g.config.land_tolerance_m:
        t += 0.1
        d = g.on(FrameSeen(state, _frame(t, [other], other_target, _map()), seq=0))
        assert d.phase is LandingPhase.APPROACH, f"at {state.altitude_m:.1f} m"
        assert d.setpoint is not None
        assert -d.setpoint.down_m > state.altitude_m  # climbing
        state = _fly(state, min(-d.setpoint.down_m, state.altitude_m + 0.5), d.setpoint.north_m, d.setpoint.east_m, t)
        assert t < 10.0
    d = g.on(FrameSeen(state, _frame(t + 0.1, [other], other_target, _map()), seq=0))
    assert d.phase is LandingPhase.DESCENT  # back up: the new zone may be descended onto


def test_with_no_climb_back_height_the_vehicle_climbs_to_the_search_altitude_and_chooses_only_there() -> None:
    # climb_back_m None: back to the altitude the search started from (20 m here), where the policy sees the whole
    # search area. The refused point's exclusion is off: the climb alone is tested.
    climb_to_m = 20.0
    g = _guidance(commitment={"refused_radius_m": 0.0}, climb_back_m=None)
    state = _aborted_low_down(g)
    refused_at = (state.north_m, state.east_m)
    # Another free zone right under the vehicle: not chosen on the way up, where the view is a few metres wide.
    other, other_target = _track(4, 0.3, 0.1, 3.0), Target(0.3, 0.1, 3.0, 4)
    t = 1.0
    while state.altitude_m < climb_to_m - g.config.land_tolerance_m:
        t += 0.1
        d = g.on(FrameSeen(state, _frame(t, [other], other_target, _map()), seq=0))
        assert d.phase is LandingPhase.SEARCH, f"at {state.altitude_m:.1f} m"
        assert d.target is None
        assert g.commitment.committed_id is None
        assert d.setpoint is not None
        assert -d.setpoint.down_m == pytest.approx(climb_to_m)  # climbing, over the refused point
        assert (d.setpoint.north_m, d.setpoint.east_m) == pytest.approx(refused_at)
        state = _fly(state, min(-d.setpoint.down_m, state.altitude_m + 0.5), d.setpoint.north_m, d.setpoint.east_m, t)
        assert t < 10.0
    assert state.altitude_m < climb_to_m + 0.5
    d = g.on(FrameSeen(state, _frame(t + 0.1, [other], other_target, _map()), seq=0))
    assert d.phase is LandingPhase.DESCENT  # back up: chosen, and descended onto (it lies under the vehicle)
    assert d.target is not None
    assert d.target.track_id == 4


def _walker_map(t_s: float) -> HeadPlaneOccupancy:
    """A walker at 1.2 m/s on a line 2 m from the landing point (0.2, 0): from 4.1 m south-west, past it at 3 s."""
    heading = np.array([1.0, 1.0]) / math.sqrt(2.0)
    aside = np.array([1.0, -1.0]) / math.sqrt(2.0) * 2.0
    n, e = np.array([0.2, 0.0]) - heading * 3.6 + aside + heading * 1.2 * t_s
    return _map(person_at=(float(n), float(e)))


def _descend_with(g: LandingGuidance, maps: Callable[[float], HeadPlaneOccupancy], t_limit_s: float) -> list[Decision]:
    """Fly the descent over zone 3 from 14 m (the vehicle reaches each setpoint by the next frame) until it lands,
    aborts or ``t_limit_s`` passes; the decisions."""
    state = _descending_over(g, 14.0)
    zone, target = _track(3, 0.2, 0.0, 3.0), Target(0.2, 0.0, 3.0, 3)
    decisions = []
    t = 0.1
    while t < t_limit_s:
        t += 0.1
        d = g.on(FrameSeen(state, _frame(t, [zone], target, maps(t)), seq=0))
        decisions.append(d)
        if d.kind is not CommandKind.SETPOINT or d.phase is not LandingPhase.DESCENT:
            break
        assert d.setpoint is not None
        state = _fly(state, -d.setpoint.down_m, d.setpoint.north_m, d.setpoint.east_m, t)
    return decisions


def test_a_descent_looks_at_the_gate_above_the_blind_last_metres_then_lands() -> None:
    g = _guidance()
    c = g.config
    gate_m = c.perception_min_altitude_m + c.land_tolerance_m
    decisions = _descend_with(g, lambda t: _map(), t_limit_s=60.0)
    assert decisions[-1].kind is CommandKind.LAND
    at_gate = [d.t_s for d in decisions if d.setpoint is not None and -d.setpoint.down_m == pytest.approx(gate_m)]
    assert at_gate[-1] - at_gate[0] >= c.walkers.window_s - 0.1 - 1e-9  # watched that long, nobody walking
    assert at_gate[-1] - at_gate[0] <= c.walkers.window_s + 0.5
    assert g.descent.walkers.waits == 0


def test_someone_walking_in_at_the_gate_holds_the_descent_there_until_they_have_passed() -> None:
    g = _guidance()
    c = g.config
    gate_m = c.perception_min_altitude_m + c.land_tolerance_m
    walk_from_s = 1.0  # as the vehicle reaches the gate (each frame's setpoint is reached by the next)
    decisions = _descend_with(g, lambda t: _map() if t < walk_from_s else _walker_map(t - walk_from_s), 90.0)
    assert decisions[-1].kind is CommandKind.LAND
    waited = [d for d in decisions if "walking" in d.reason or "closing" in d.reason]
    assert waited, "the walker was not seen coming"
    assert g.descent.walkers.waits == 1
    for d in decisions:  # never below the gate before the walker has gone by
        if d.t_s <= waited[-1].t_s:
            assert d.setpoint is not None
            assert -d.setpoint.down_m >= gate_m - 1e-9
    # The walker's closest pass (2 m from the point, at 3.0 s of its walk) came before the descent went on.
    went_on = next(d.t_s for d in decisions if d.t_s > waited[-1].t_s)
    assert went_on - walk_from_s > 3.0


def test_a_person_who_keeps_walking_in_makes_the_descent_refuse_the_point() -> None:
    g = _guidance(walkers={"max_wait_s": 2.0})

    # Someone walks straight at the point from 4.5 m north at 0.5 m/s, and stops 2.5 m short (outside the
    # footprint): closing in for 4 s, longer than the gate waits.
    def coming(t: float) -> HeadPlaneOccupancy:
        return _map(person_at=(0.2 + max(2.5, 4.5 - 0.5 * max(0.0, t - 1.0)), 0.0))

    decisions = _descend_with(g, coming, 60.0)
    last = decisions[-1]
    assert last.phase is LandingPhase.SEARCH
    assert "kept walking towards the footprint" in last.reason
    assert g.reselections == 1
    assert all(d.kind is not CommandKind.LAND for d in decisions)


def test_a_person_seen_in_the_footprint_at_the_gate_is_waited_out_there_then_the_descent_lands() -> None:
    g = _guidance()
    c = g.config
    gate_m = c.perception_min_altitude_m + c.land_tolerance_m
    # Each setpoint is reached by the next frame: from 14 m the vehicle is at the gate from about 1.0 s. Someone is
    # seen in the footprint there for 1.5 s (longer than unsafe_frames_to_abort frames), then the footprint is free.
    seen_s = (1.2, 2.7)
    decisions = _descend_with(g, lambda t: _map(person_at=(0.5, 0.3)) if seen_s[0] <= t < seen_s[1] else _map(), 60.0)
    assert decisions[-1].kind is CommandKind.LAND
    assert g.reselections == 0  # never refused
    held = [d for d in decisions if "a person seen inside the footprint" in d.reason]
    assert len(held) >= c.unsafe_frames_to_abort  # would have aborted above the gate
    for d in decisions:  # not below the gate while the footprint was seen occupied, nor before a look after it
        if d.t_s < seen_s[1] + c.walkers.clear_frames * 0.1 - 1e-9:
            assert d.setpoint is not None
            assert -d.setpoint.down_m >= gate_m - 1e-9


def test_a_person_who_stays_in_the_footprint_at_the_gate_makes_the_descent_refuse_the_point() -> None:
    g = _guidance(walkers={"max_wait_s": 3.0})
    decisions = _descend_with(g, lambda t: _map(person_at=(0.5, 0.3)) if t >= 1.2 else _map(), 60.0)
    last = decisions[-1]
    assert last.phase is LandingPhase.SEARCH
    assert "person seen inside the footprint at the gate" in last.reason
    assert last.setpoint is not None
    assert -last.setpoint.down_m > g.config.perception_min_altitude_m + g.config.land_tolerance_m  # climbs back
    assert last.t_s - 1.2 == pytest.approx(3.0, abs=0.25)  # after the gate's wait, not at the frames' limit
    assert g.reselections == 1
    assert all(d.kind is not CommandKind.LAND for d in decisions)


def test_a_person_seen_in_the_footprint_after_the_gate_and_above_the_floor_sends_the_descent_back_to_the_gate() -> None:
    g = _guidance(walkers={"max_wait_s": 3.0})
    c = g.config
    gate_m = c.perception_min_altitude_m + c.land_tolerance_m
    state = _descending_over(g, gate_m)
    zone, target = _track(3, 0.2, 0.0, 3.0), Target(0.2, 0.0, 3.0, 3)
    t = 0.1
    while not g.descent.walkers.passed:  # a free footprint at the gate: the look, then the gate is passed
        t += 0.1
        state = VehicleState(t, 0.0, 0.0, -gate_m, 0.0)
        g.on(FrameSeen(state, _frame(t, [zone], target, _map()), seq=0))
        assert t < 5.0
    state = VehicleState(t, 0.2, 0.0, -(c.perception_min_altitude_m + 0.1), 0.0)  # on the way down, above the floor
    occupied = _map(person_at=(0.5, 0.3))
    t += 0.1
    d = g.on(FrameSeen(state, _frame(t, [zone], target, occupied), seq=0))
    assert d.phase is LandingPhase.DESCENT
    assert d.setpoint is not None
    assert -d.setpoint.down_m == pytest.approx(gate_m)  # back up to the gate, not an abort
    assert not g.descent.walkers.passed
    since = t
    while d.phase is LandingPhase.DESCENT:  # still there: the wait is bounded like any wait at the gate
        t += 0.1
        state = VehicleState(t, 0.2, 0.0, -gate_m, 0.0)
        d = g.on(FrameSeen(state, _frame(t, [zone], target, occupied), seq=0))
        assert t - since < 4.0
    assert d.phase is LandingPhase.SEARCH
    assert "person seen inside the footprint at the gate" in d.reason
    assert t - since == pytest.approx(3.0, abs=0.25)
