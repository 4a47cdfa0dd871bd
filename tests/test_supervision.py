"""The flight's supervision on its own: the watch after a failsafe, a dry run's end, a stop, the wall limit."""

from __future__ import annotations

import pytest

from companion.app.supervision import Supervision
from companion.guidance.landing import CommandKind, Decision, LandingPhase
from companion.guidance.vocabulary import DecisionEvent
from companion.vehicle.link import FlightMode, VehicleStatus

pytestmark = pytest.mark.unit


def _status(mode: FlightMode, in_air: bool = True, armed: bool = True) -> VehicleStatus:
    return VehicleStatus(mode=mode, in_air=in_air, armed=armed)


def test_the_watch_after_a_return_ends_on_the_ground_or_in_the_pilots_mode_not_in_the_returns_own() -> None:
    supervision = Supervision(stay_after_failsafe=True, wall_limit_s=None, wall_clock=lambda: 0.0)
    failsafe = Decision(
        1.0, LandingPhase.FAILSAFE, CommandKind.RETURN, None, None, "limit: return", DecisionEvent.LIMIT
    )
    assert supervision.stays_after(failsafe, sent=True)
    assert not supervision.stays_after(failsafe, sent=False)  # nothing went out: nothing to watch
    supervision.watch(failsafe.kind)
    # The return's own modes, and OFFBOARD still reported (telemetry lagging the command): the watch goes on.
    for mode in (FlightMode.RETURN_TO_LAUNCH, FlightMode.LAND, FlightMode.HOLD, FlightMode.OFFBOARD):
        assert supervision.watch_ends(_status(mode)) is None
    pilot = supervision.watch_ends(_status(FlightMode.POSCTL))
    assert pilot is not None
    assert (pilot.event, pilot.reason) == ("pilot_has_it", "the pilot has it (mode POSCTL)")
    ground = supervision.watch_ends(_status(FlightMode.LAND, in_air=False))
    assert ground is not None
    assert ground.event == "on_ground"


def test_a_hold_is_watched_until_the_pilot_leaves_hold() -> None:
    supervision = Supervision(stay_after_failsafe=True, wall_limit_s=None, wall_clock=lambda: 0.0)
    supervision.watch(CommandKind.HOLD)
    assert supervision.watch_ends(_status(FlightMode.HOLD)) is None
    assert supervision.watch_ends(_status(FlightMode.LAND)) is not None  # not what the hold asked for: the pilot's


def test_a_stop_that_sends_the_last_resort_is_not_watched_after_and_a_second_stop_ends_at_once() -> None:
    supervision = Supervision(stay_after_failsafe=True, wall_limit_s=None, wall_clock=lambda: 0.0)
    assert supervision.ask_stop("SIGTERM")
    assert not supervision.ask_stop("SIGINT")  # asked again: the program ends now
    assert supervision.take_stop(last_resort=True) == "SIGTERM"
    assert supervision.stop_requested is None
    assert supervision.stop_unheard() is None  # taken by a tick: nothing left to end unheard
    failsafe = Decision(1.0, LandingPhase.FAILSAFE, CommandKind.HOLD, None, None, "SIGTERM: hold", DecisionEvent.LIMIT)
    assert not supervision.stays_after(failsafe, sent=True)  # a stopping service cannot stay
    unheard = Supervision(stay_after_failsafe=True, wall_limit_s=None, wall_clock=lambda: 0.0)
    unheard.ask_stop("SIGTERM")
    assert unheard.stop_unheard() == "SIGTERM"


def test_the_wall_limit_comes_once_at_its_wall_time_and_a_dry_run_ends_after_flying_on_the_ground_disarmed() -> None:
    now = [100.0]
    supervision = Supervision(stay_after_failsafe=False, wall_limit_s=30.0, wall_clock=lambda: now[0])
    assert supervision.wall_limit_reached() is None
    now[0] = 130.0
    assert supervision.wall_limit_reached() == "wall limit of 30 s reached (slz fly --timeout)"
    assert supervision.wall_limit_reached() is None
    assert not supervision.flight_over(_status(FlightMode.HOLD, in_air=False, armed=False))  # never flew yet
    supervision.saw(_status(FlightMode.POSCTL))
    assert not supervision.flight_over(_status(FlightMode.LAND, in_air=False, armed=True))
    assert supervision.flight_over(_status(FlightMode.LAND, in_air=False, armed=False))
