"""A mission's ending by kind, from its decisions' events (sitl.campaign.landing_kinds)."""

from __future__ import annotations

import pytest

from companion.flightlog.flight_log import DecisionRecord
from companion.guidance.landing import CommandKind, LandingPhase
from companion.guidance.vocabulary import DecisionEvent, DecisionSource
from companion.perception.selection import Target
from sitl.campaign.landing_kinds import LandingKind, LandingOutcome, landing_outcome

pytestmark = pytest.mark.unit


def decision(
    t_s: float, kind: str, phase: str, event: DecisionEvent, target: tuple[float, float] | None = None
) -> DecisionRecord:
    at = None if target is None else Target(target[0], target[1], 3.0, -1)
    return DecisionRecord(
        t_s, CommandKind(kind), LandingPhase(phase), at, None, "words nobody reads", DecisionSource.FRAME, None, event
    )


START = decision(1.0, "setpoint", "search", DecisionEvent.MISSION_START)
LANDED = decision(60.0, "none", "done", DecisionEvent.LANDED)


def test_each_ending_is_told_by_its_events() -> None:
    zone = [START, decision(30.0, "land", "land", DecisionEvent.LAND, (1.0, 2.0)), LANDED]
    assert landing_outcome(zone) == LandingOutcome(LandingKind.ZONE, None, 0)
    second_site = [
        START,
        decision(20.0, "setpoint", "approach", DecisionEvent.FALLBACK_SITE, (12.0, 12.0)),
        decision(30.0, "setpoint", "approach", DecisionEvent.FALLBACK_SITE, (21.0, -4.0)),
        decision(50.0, "land", "land", DecisionEvent.LAND, (21.0, -4.0)),
        LANDED,
    ]
    assert landing_outcome(second_site) == LandingOutcome(LandingKind.FALLBACK_SITE, (21.0, -4.0), 2)
    held = [START, decision(20.0, "setpoint", "approach", DecisionEvent.FALLBACK_SITE, (12.0, 12.0))]
    held.append(decision(40.0, "hold", "failsafe", DecisionEvent.TIME_LIMIT))
    assert landing_outcome(held) == LandingOutcome(LandingKind.HOLD, None, 1)
    returned = [START, decision(40.0, "return", "failsafe", DecisionEvent.ENERGY_LOW)]
    assert landing_outcome(returned).kind is LandingKind.RETURN
    silent = [START, decision(40.0, "land", "failsafe", DecisionEvent.PERCEPTION_FAILSAFE)]
    assert landing_outcome(silent).kind is LandingKind.FAILSAFE_LAND  # a landing in place, not on a chosen zone
    yielded = [START, decision(40.0, "none", "yielded", DecisionEvent.PILOT_TOOK_OVER)]
    assert landing_outcome(yielded).kind is LandingKind.OTHER
    assert landing_outcome([]).kind is LandingKind.OTHER
