"""How a mission ended, by kind, from its flight log: a landing on a zone the map chose, a landing at a fallback site,
or the last resort (hold, return, land), for campaigns where the search's budget may end (issue 53).

Read from the decisions' events (:mod:`companion.guidance.vocabulary`), never from their words: a landing is at a
fallback site when a ``fallback_site`` decision came before its landing command, and the site is the target of the
last one; the sites given up on the way are the ``fallback_site`` decisions before it.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from pathlib import Path

from companion.flightlog.flight_log import DecisionRecord, FlightLog
from companion.guidance.landing import CommandKind, LandingPhase
from companion.guidance.vocabulary import DecisionEvent


class LandingKind(str, enum.Enum):
    """How a mission ended."""

    ZONE = "zone"
    """Landed on a zone the map chose."""
    FALLBACK_SITE = "fallback_site"
    """Landed at a fallback site, checked by the map on arrival."""
    HOLD = "hold"
    """The last resort: hold (the pilot decides)."""
    RETURN = "return"
    """The last resort: return to launch."""
    FAILSAFE_LAND = "failsafe_land"
    """A failsafe landing in place (perception silent for T2, with land as the failsafe action)."""
    OTHER = "other"
    """None of these (the pilot took over, the run was stopped, no decision)."""


@dataclass(frozen=True)
class LandingOutcome:
    """A mission's ending: its kind, the fallback site landed at (north, east; metres), and how many sites were flown
    to (the one landed at included)."""

    kind: LandingKind
    site_ne_m: tuple[float, float] | None
    sites_flown_to: int


def landing_outcome(decisions: list[DecisionRecord]) -> LandingOutcome:
    """The ending of a flight from its decisions (in order)."""
    to_sites = [d for d in decisions if d.event is DecisionEvent.FALLBACK_SITE]
    landing = next((d for d in reversed(decisions) if d.kind is CommandKind.LAND), None)
    ending = decisions[-1] if decisions else None
    if ending is not None and ending.event is DecisionEvent.LANDED:
        ending = next((d for d in reversed(decisions) if d.event is not DecisionEvent.LANDED), None)
    if landing is not None and landing.phase is LandingPhase.LAND:
        before = [d for d in to_sites if d.t_s <= landing.t_s]
        if before and before[-1].target is not None:
            target = before[-1].target
            site = (float(target.north_m), float(target.east_m))
            return LandingOutcome(LandingKind.FALLBACK_SITE, site, len(before))
        return LandingOutcome(LandingKind.ZONE, None, 0)
    kinds = {
        CommandKind.HOLD: LandingKind.HOLD,
        CommandKind.RETURN: LandingKind.RETURN,
        CommandKind.LAND: LandingKind.FAILSAFE_LAND,
    }
    kind = (
        kinds.get(ending.kind, LandingKind.OTHER)
        if ending is not None and ending.phase is LandingPhase.FAILSAFE
        else None
    )
    return LandingOutcome(kind or LandingKind.OTHER, None, len(to_sites))


def landing_outcome_of_run(flight_dir: Path) -> LandingOutcome:
    """The ending of the flight logged in ``flight_dir`` (its ``flight.jsonl``)."""
    return landing_outcome(FlightLog.read(flight_dir / "flight.jsonl").decisions())
