"""The ground station's landing commands, decided by the landing logic (:mod:`companion.ground.command_channel` takes
them, :mod:`companion.app.operator_desk` hands them over at a tick): go around, reject the zone, land now, the next
fallback site."""

from __future__ import annotations

import math

from companion.guidance.fallback import BudgetEnd
from companion.guidance.landing import ACTIVE_PHASES, CommandKind, Decision, LandingGuidance, LandingPhase
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent, OperatorCommand, RefusalCause

OPERATOR_EVENTS: dict[OperatorCommand, tuple[DecisionEvent, str]] = {
    OperatorCommand.GO_AROUND: (DecisionEvent.OPERATOR_GO_AROUND, "go-around from the ground station"),
    OperatorCommand.REJECT_ZONE: (DecisionEvent.OPERATOR_REJECT, "zone rejected from the ground station"),
    OperatorCommand.LAND_NOW: (DecisionEvent.OPERATOR_LAND, "land now, from the ground station"),
}
"""What each ground-station command is, as a decision: its event and its words."""


def operator_decision(
    g: LandingGuidance, command: OperatorCommand, state: VehicleState, person_seen: bool, force: bool
) -> Decision | str:
    """A ground station's command to the landing logic ``g`` at ``state``: its decision, or why it is denied (in
    words; a denial changes nothing). ``person_seen``: the newest map sees a person in the footprint at the target;
    ``force``: land even so (the decision says it).

    A go-around, and a rejection in the descent, abort the descent as a refused point does (climb back, a
    re-selection spent, the point refused); a rejection in the approach refuses the zone and chooses again from where
    the vehicle is; land-now commands the landing over the target, the vehicle within ``capture_radius_m`` of it; the
    next fallback site ends the search (or gives up the site flown to) for the nearest fallback site not tried yet, as
    the end of the search's budget does (:func:`next_fallback`)."""
    if command is OperatorCommand.NEXT_FALLBACK:
        return next_fallback(g, state)
    target = g.target
    if g.phase not in (LandingPhase.APPROACH, LandingPhase.DESCENT) or target is None:
        return f"no approach or descent to act on (phase {g.phase.value})"
    if command not in OPERATOR_EVENTS:
        return f"{command.value} is not supported"
    event, said = OPERATOR_EVENTS[command]
    descending = g.phase is LandingPhase.DESCENT
    if command is OperatorCommand.GO_AROUND or (command is OperatorCommand.REJECT_ZONE and descending):
        return g.abort_descent(state, said, RefusalCause.OPERATOR, event)
    if command is OperatorCommand.REJECT_ZONE:  # approaching: refuse the zone, choose another from here
        g.commitment.refuse(target.north_m, target.east_m, state.t_s, said)
        n, e, alt = state.north_m, state.east_m, max(state.altitude_m, g.climb.search_altitude_m)
        return g.steer(state, LandingPhase.SEARCH, None, said, n, e, alt, event, RefusalCause.OPERATOR)
    offset_m = math.hypot(target.north_m - state.north_m, target.east_m - state.east_m)
    if offset_m > g.config.capture_radius_m:
        return f"{offset_m:.1f} m from the target: land-now lands where the vehicle is; wait until over it"
    if person_seen and not force:
        return "a person in the footprint on the newest map (param1 = 1 forces the landing)"
    said += " (forced: a person in the footprint on the newest map)" if person_seen else ""
    g.enter(LandingPhase.LAND, state.t_s)
    return Decision(state.t_s, LandingPhase.LAND, CommandKind.LAND, None, target, said, event)


def next_fallback(g: LandingGuidance, state: VehicleState) -> Decision | str:
    """The ground station's "next fallback site" to ``g`` at ``state``: while searching, approaching or descending,
    the nearest fallback site not tried yet in reach (the climb to the search altitude first, then the site's checks,
    as when the search's budget ends; a site flown to now is given up); denied (in words) without sites or with none
    left to try. The search counts as ended by the ground station: once no site is left, ``guidance.last_resort``."""
    plan = g.fallback
    if g.phase not in ACTIVE_PHASES:
        return f"no search, approach or descent to act on (phase {g.phase.value})"
    if not plan.sites:
        return "no fallback sites in this mission (guidance.fallback)"
    if not plan.untried(state):
        return "no fallback site left to try in reach"
    said = "next fallback site, from the ground station"
    if plan.ended_by is None:
        plan.ended_by = BudgetEnd(said, DecisionEvent.FALLBACK_SITE, g.config.last_resort)
    return g.next_site(state, said, RefusalCause.OPERATOR)
