"""The start of a flight, tick by tick, with no vehicle: SITL takeoff (refused, accepted, climb, transit), the
field's handover (waiting as long as the pilot flies, never from the ground), a dry run, and the start's time limit.
FlightApp acting on these steps over a fake link is in tests/test_flight_supervision.py; flown, in
tests/test_companion_missions.py."""

from __future__ import annotations

import math

import pytest

from companion.app.mission import StartConfig
from companion.app.start_sequence import (
    START_TIMEOUT_S,
    TAKEOFF_RETRY_S,
    StartAction,
    StartSequence,
    StartStage,
)
from companion.guidance.vehicle_state import VehicleState
from companion.vehicle.link import FlightMode, VehicleStatus

pytestmark = pytest.mark.unit

ALTITUDE_M = 20.0
TICK_S = 0.1


def at(
    t_s: float, north_m: float = 0.0, east_m: float = 0.0, altitude_m: float = 0.0, yaw_deg: float = 0.0
) -> VehicleState:
    return VehicleState(t_s, north_m, east_m, -altitude_m, yaw_deg)


def on_ground() -> VehicleStatus:
    return VehicleStatus(mode=FlightMode.HOLD, armed=False, in_air=False)


def sitl(**start: object) -> StartSequence:
    return StartSequence(
        StartConfig.model_validate({"arm_and_takeoff": True, "takeoff_altitude_m": ALTITUDE_M, **start}), dry_run=False
    )


def test_sitl_asks_for_takeoff_once_a_second_of_vehicle_time_until_the_autopilot_accepts() -> None:
    seq = sitl()
    asked = []
    for k in range(35):  # 3.4 s of ticks, every takeoff refused
        t_s = 10.0 + k * TICK_S
        step = seq.step(at(t_s), on_ground())
        if step.action is StartAction.TAKE_OFF:
            assert step.altitude_m == ALTITUDE_M
            asked.append(t_s)
        else:
            assert step.action is StartAction.WAIT
    assert asked == pytest.approx(
        [10.0, 10.0 + TAKEOFF_RETRY_S, 10.0 + 2 * TAKEOFF_RETRY_S, 10.0 + 3 * TAKEOFF_RETRY_S]
    )
    stages = [seq.stage]
    seq.took_off()
    stages.append(seq.stage)
    assert stages == [StartStage.WAITING, StartStage.CLIMBING]


def test_sitl_climbs_to_within_half_a_metre_then_flies_to_the_start_pose_with_its_heading_held_then_starts() -> None:
    seq = sitl(start_north_m=30.0, start_east_m=-40.0)
    assert seq.step(at(0.0), on_ground()).action is StartAction.TAKE_OFF
    seq.took_off()
    assert seq.step(at(5.0, altitude_m=ALTITUDE_M - 0.6, yaw_deg=12.0), on_ground()).action is StartAction.WAIT
    first = seq.step(at(5.1, altitude_m=ALTITUDE_M - 0.4, yaw_deg=12.0), on_ground())
    assert first.action is StartAction.TRANSIT
    assert (first.north_m, first.east_m, first.altitude_m, first.yaw_deg) == (30.0, -40.0, ALTITUDE_M, 12.0)
    assert seq.stage is StartStage.TRANSIT
    later = seq.step(at(9.0, 10.0, -12.0, ALTITUDE_M, yaw_deg=50.0), on_ground())  # the heading drifted: still 12
    assert later.action is StartAction.TRANSIT
    assert later.yaw_deg == 12.0
    near = seq.step(at(14.0, 30.6, -40.6, ALTITUDE_M), on_ground())  # 0.85 m from the start pose
    assert near.action is StartAction.START
    assert seq.started


def test_without_a_start_pose_the_search_starts_at_the_top_of_the_climb() -> None:
    seq = sitl()
    seq.step(at(0.0), on_ground())
    seq.took_off()
    assert seq.step(at(6.0, altitude_m=ALTITUDE_M - 0.5), on_ground()).action is StartAction.START


def test_the_field_waits_as_long_as_the_pilot_flies_logs_it_once_and_starts_at_the_handover() -> None:
    seq = StartSequence(StartConfig.model_validate({"handover_modes": ["HOLD", "POSCTL"]}), dry_run=False)
    flying_manually = VehicleStatus(mode=FlightMode.ALTCTL, armed=True, in_air=True)
    steps = [seq.step(at(k * 1.0, altitude_m=15.0), flying_manually) for k in range(int(3 * START_TIMEOUT_S))]
    assert all(s.action is StartAction.WAIT for s in steps)  # no time limit while the pilot flies
    assert [s.waiting_for_modes for s in steps if s.waiting_for_modes] == ["HOLD, POSCTL"]
    on_the_ground_in_hold = VehicleStatus(mode=FlightMode.HOLD, armed=True, in_air=False)
    assert seq.step(at(400.0), on_the_ground_in_hold).action is StartAction.WAIT  # never started from the ground
    handover = seq.step(at(401.0, altitude_m=15.0), VehicleStatus(mode=FlightMode.POSCTL, armed=True, in_air=True))
    assert handover.action is StartAction.START
    assert handover.handed_over is FlightMode.POSCTL


def test_a_field_handover_with_a_start_pose_flies_there_first_and_records_the_handover_once() -> None:
    seq = StartSequence(StartConfig.model_validate({"start_north_m": 50.0, "start_east_m": 0.0}), dry_run=False)
    in_hold = VehicleStatus(mode=FlightMode.HOLD, armed=True, in_air=True)
    first = seq.step(at(1.0, altitude_m=18.0), in_hold)
    assert first.action is StartAction.TRANSIT
    assert first.handed_over is FlightMode.HOLD
    second = seq.step(at(1.1, 1.0, altitude_m=18.0), in_hold)
    assert second.action is StartAction.TRANSIT
    assert second.handed_over is None


def test_a_dry_run_waits_on_the_bench_for_the_air_and_the_head_plane_then_starts_whatever_is_configured() -> None:
    config = StartConfig.model_validate({"arm_and_takeoff": True, "start_north_m": 50.0, "start_east_m": 5.0})
    seq = StartSequence(config, dry_run=True)
    # On the bench, for as long as it takes (no start time limit, no takeoff asked): each new wait said once.
    first = seq.step(at(3.0), on_ground(), head_plane_visible=False)
    assert first.action is StartAction.WAIT
    assert first.waiting_for == "the vehicle armed and in the air"
    later = seq.step(at(3.0 + 10 * START_TIMEOUT_S), on_ground(), head_plane_visible=False)
    assert later.action is StartAction.WAIT
    assert later.waiting_for is None
    flying = VehicleStatus(mode=FlightMode.POSCTL, armed=True, in_air=True)
    low = seq.step(at(4000.0, altitude_m=1.0), flying, head_plane_visible=False)
    assert low.action is StartAction.WAIT
    assert low.waiting_for == "the head plane in view (in the air at 1.0 m)"
    assert seq.step(at(4000.1, altitude_m=1.2), flying, head_plane_visible=False).waiting_for is None
    # Airborne in any of the pilot's modes, the head plane in view: deciding starts at once (no takeoff, no transit).
    assert seq.step(at(4001.0, altitude_m=8.0), flying, head_plane_visible=True).action is StartAction.START
    assert seq.started


def test_a_start_not_done_within_its_limit_fails_and_says_where_it_stopped() -> None:
    seq = sitl(start_north_m=1000.0, start_east_m=0.0)
    seq.step(at(0.0), on_ground())
    seq.took_off()
    step = seq.step(at(10.0, altitude_m=ALTITUDE_M), on_ground())
    assert step.action is StartAction.TRANSIT
    assert seq.step(at(START_TIMEOUT_S, 500.0, altitude_m=ALTITUDE_M), on_ground()).action is StartAction.TRANSIT
    late = seq.step(at(START_TIMEOUT_S + 0.1, 510.0, altitude_m=ALTITUDE_M), on_ground())
    assert late.action is StartAction.TIMED_OUT
    assert late.reason == f"not ready to search {START_TIMEOUT_S:g} s after the start (transit)"
    assert math.isnan(late.north_m)
