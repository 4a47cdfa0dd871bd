"""The landing state machine: what the vehicle does after each processed frame.

::

    idle -> search -> approach -> descent -> land -> done
              ^          |          |
              +----------+----------+   (target lost, shrunk or occupied: climb back and re-select)

    any active phase -> hold (perception silent for T1) -> failsafe (silent for T2: the configured action)
    any phase -> yielded (the pilot took over; terminal for the flight)

- **search**: hold position (never below ``search_altitude_m``, climbing to it if lower) until the pipeline
  selects a target; with none for ``search_timeout_s``, fly a bounded expanding-square pattern inside the geofence.
- **approach**: fly horizontally towards the target's centre at constant altitude. The target is committed
  (:mod:`companion.guidance.commitment`): the selection policy chooses once, and the choice stands until the zone
  fails a check (lost, shrunk, out of the fence, a person seen in its footprint) or a rival is better by a stated
  margin for a stated time and reachable in the time left. The paper re-applied the policy at every frame, and over a
  view that moves with the vehicle the biggest zone changed with it: the vehicle chased zones until its time ran out.
- **descent**: once within ``capture_radius_m`` of the centre, the landing point is locked (a point on the ground,
  refined by the target's track while it is seen near it) and the vehicle descends towards ``approach_height_m``
  above ground (the paper: 2 m above the zone). When for ``unsafe_frames_to_abort`` frames in a row a person is seen
  inside the footprint around the landing point, or the tracked zone is narrower than ``min_zone_radius_m``, the
  vehicle climbs back by ``climb_back_m`` and searches again (a zone chosen on the way up is approached climbing); a
  new descent starts only once it is back up there. With ``climb_back_m`` None it climbs over the refused point all
  the way to the altitude the search started from and chooses only there. Zones near the refused point are not
  chosen for a while (``commitment.refused_memory_s``). After ``max_reselections`` aborted descents it holds.
  Below ``blind_altitude_m`` the head plane is too close to the camera to see the whole zone, and below
  ``perception_min_altitude_m`` (4.5 m, the same) the maps are not trusted at all (the whole view then lies within the
  footprint and its margin): the descent continues on the last map that saw the whole footprint free. So it first
  stops at a gate just above that floor and watches for people walking towards the landing point
  (:mod:`companion.guidance.walker_watch`): it goes on once nobody seen would reach the footprint by touchdown and
  the footprint is seen free, and a wait longer than ``walkers.max_wait_s`` refuses the point like an aborted
  descent. At the gate a person seen in the footprint is waited out rather than refused at once: the vehicle hovers
  there, above the heads, and a false positive of the low maps that flickers passes.
- **land**: at or below ``land_altitude_m`` over the target, a landing is commanded only when a map no older than
  ``landing_map_max_age_s`` saw the whole footprint (vehicle radius plus margin) free, and no later frame saw a person
  in it. Otherwise the vehicle climbs back and re-selects.

Every setpoint goes through one safety filter: inside the geofence (clamped), at most ``max_step_m`` away
horizontally, and never more than ``descent_rate_limit_mps * autopilot_z_time_constant_s`` below the vehicle (a
position controller with that time constant then descends no faster than the limit). Times are vehicle-clock
seconds. This module has no I/O: the application turns decisions into MAVLink, or only logs them in a dry run.
"""

from __future__ import annotations

import math
from typing import overload

from companion.guidance.climb_back import ClimbBack
from companion.guidance.commitment import TargetCommitment
from companion.guidance.config import FailsafeAction, GuidanceConfig
from companion.guidance.decision import (
    ACTIVE_PHASES,
    COMMAND_OF_ACTION,
    ENDING_KINDS,
    CommandKind,
    Decision,
    LandingPhase,
)
from companion.guidance.descent import Descent, StepKind
from companion.guidance.fallback import BudgetEnd, BudgetStepKind, FallbackPlan, SearchBudget
from companion.guidance.geofence import Geofence
from companion.guidance.safety_filter import filtered_setpoint
from companion.guidance.search_pattern import ExpandingSquare
from companion.guidance.stimulus import (
    Denied,
    EnergyLow,
    FrameSeen,
    Landed,
    LimitReached,
    OperatorOrder,
    PilotTookOver,
    Silence,
    Started,
    Stimulus,
    StopAsked,
    TimeUp,
)
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import CommitmentEvent, DecisionEvent, OperatorCommand, RefusalCause
from companion.perception.pipeline import FrameResult
from companion.perception.selection import SelectionContext, SelectionPolicy, Target
from companion.vehicle.link import Setpoint

__all__ = [
    "ACTIVE_PHASES",
    "COMMAND_OF_ACTION",
    "ENDING_KINDS",
    "CommandKind",
    "Decision",
    "LandingGuidance",
    "LandingPhase",
]

FRAMES_IGNORED = frozenset(
    {LandingPhase.IDLE, LandingPhase.LAND, LandingPhase.DONE, LandingPhase.FAILSAFE, LandingPhase.YIELDED}
)
"""Phases in which a frame decides nothing."""

CLIMBING_BACK = "climbing back to"
"""How the reason of a frame spent climbing back after an aborted descent begins (for people: what counts reads
the decision's event)."""


class LandingGuidance:
    """The state machine (see the module docstring).

    Parameters
    ----------
    config : GuidanceConfig
        Its parameters.
    geofence : Geofence
        Every setpoint is kept inside it.
    footprint_radius_m : float
        Vehicle radius including propellers plus the safety margin: the disc that must be free to land.
    min_zone_radius_m : float
        Smallest zone a descent may continue over.
    policy : SelectionPolicy
        The mission's selection policy: it chooses the zone to commit to, and scores rivals.
    """

    def __init__(
        self,
        config: GuidanceConfig,
        geofence: Geofence,
        footprint_radius_m: float,
        min_zone_radius_m: float,
        policy: SelectionPolicy,
    ) -> None:
        self.config = config
        self.commitment = TargetCommitment(config.commitment, policy, geofence, footprint_radius_m, min_zone_radius_m)
        self.descent = Descent(config, footprint_radius_m, min_zone_radius_m, self.commitment.inside_fence)
        self.geofence = geofence
        self.footprint_radius_m = footprint_radius_m
        self.min_zone_radius_m = min_zone_radius_m
        self.phase = LandingPhase.IDLE
        self.reselections = 0
        self._phase_since_s = 0.0
        self._last_target_s: float | None = None
        self._hold: Setpoint | None = None
        self.search = ExpandingSquare(config.search_leg_m, config.search_timeout_s, geofence)
        self.climb = ClimbBack(config)
        self.fallback = FallbackPlan(config.fallback)
        self.budget = SearchBudget(config.mission_time_limit_s, config.last_resort, config.energy.action, self.fallback)
        self._resume_phase = LandingPhase.SEARCH
        self._heading_deg: float | None = None
        self.target: Target | None = None
        """The target of the newest setpoint (None: none)."""

    # -- helpers -------------------------------------------------------------------------------------------------
    def enter(self, phase: LandingPhase, t_s: float) -> None:
        """Be in ``phase`` from vehicle time ``t_s`` (the parts built on the machine use these primitives)."""
        if phase is not self.phase:
            self.phase = phase
            self._phase_since_s = t_s

    def safe_setpoint(
        self, state: VehicleState, north_m: float, east_m: float, altitude_m: float, yaw_deg: float | None = None
    ) -> Setpoint:
        """The safety filter every setpoint goes through (:func:`~companion.guidance.safety_filter.filtered_setpoint`:
        step, descent rate, geofence). The heading is held: ``yaw_deg``, else the heading at :meth:`start`, else the
        vehicle's (a setpoint never chases the vehicle's slow yaw drift: consecutive setpoints differ only where the
        logic moved them)."""
        if yaw_deg is None:
            yaw_deg = self._heading_deg if self._heading_deg is not None else state.yaw_deg
        return filtered_setpoint(self.config, self.geofence, state, north_m, east_m, altitude_m, yaw_deg)

    def steer(
        self,
        state: VehicleState,
        phase: LandingPhase,
        target: Target | None,
        reason: str,
        n: float,
        e: float,
        alt: float,
        event: DecisionEvent,
        cause: RefusalCause | None = None,
        zone_changes: tuple[CommitmentEvent, ...] = (),
    ) -> Decision:
        self.enter(phase, state.t_s)
        self.target = target
        setpoint = self.safe_setpoint(state, n, e, alt)
        return Decision(state.t_s, phase, CommandKind.SETPOINT, setpoint, target, reason, event, cause, zone_changes)

    def abort_descent(
        self, state: VehicleState, reason: str, cause: RefusalCause, event: DecisionEvent = DecisionEvent.ABORT
    ) -> Decision:
        if self.fallback.current is not None:  # the map refused the site: the next one, or the last resort
            self.descent.refuse()
            return _next_site(self, state, f"{reason}: site {self.fallback.current.name} refused", cause)
        self.reselections += 1
        locked = self.descent.locked
        if locked is not None:
            self.commitment.refuse(locked.north_m, locked.east_m, state.t_s, reason)
        self.descent.refuse()
        self._last_target_s = state.t_s
        self.search.reset()
        if self.reselections > self.config.max_reselections:
            # Never the configured "land": the map has just refused a landing here. The last resort (hold or
            # return), and the pilot decides.
            used = f"{reason}; {self.reselections - 1} re-selections used up"
            return self.failsafe(state, used, DecisionEvent.RESELECTIONS_USED_UP, self.config.last_resort, cause)
        climb_to, said = self.climb.after_abort(state), f"{reason}: climb back and re-select"
        return self.steer(state, LandingPhase.SEARCH, None, said, state.north_m, state.east_m, climb_to, event, cause)

    def failsafe(
        self,
        state: VehicleState,
        reason: str,
        event: DecisionEvent,
        action: FailsafeAction | None = None,
        cause: RefusalCause | None = None,
    ) -> Decision:
        """Enter the failsafe phase with ``action`` (the configured one when None)."""
        action = action or self.config.failsafe_action
        self.enter(LandingPhase.FAILSAFE, state.t_s)
        kind = COMMAND_OF_ACTION[action]
        return Decision(state.t_s, LandingPhase.FAILSAFE, kind, None, None, f"{reason}: {action.value}", event, cause)

    # -- the entry point ------------------------------------------------------------------------------------------
    @overload
    def on(self, stimulus: Started | FrameSeen | Landed | PilotTookOver | LimitReached | StopAsked) -> Decision: ...

    @overload
    def on(self, stimulus: Silence | TimeUp | EnergyLow) -> Decision | None: ...

    @overload
    def on(self, stimulus: OperatorOrder) -> Decision | Denied: ...

    @overload
    def on(self, stimulus: Stimulus) -> Decision | Denied | None: ...

    def on(self, stimulus: Stimulus) -> Decision | Denied | None:
        """Decide on one stimulus (:mod:`companion.guidance.stimulus`): the decision, None when it changes nothing
        (silence not long enough, time not used up), or :class:`Denied` for an operator's command the logic will not
        carry out."""
        state = stimulus.state
        match stimulus:
            case Started():
                return self._start(state)
            case FrameSeen(result=result):
                return self._frame(result, state)
            case Silence(silent_s=silent_s):
                return self._silence(state, silent_s)
            case Landed():
                return self._landed(state.t_s)
            case TimeUp():
                return _budget(self, state)
            case EnergyLow(reason=reason, reach_m=reach_m):
                return _budget(self, state, reason, reach_m)
            case PilotTookOver(mode=mode):
                return self._pilot_took_over(state.t_s, mode)
            case LimitReached(reason=reason) | StopAsked(reason=reason):
                return self.failsafe(state, reason, DecisionEvent.LIMIT, self.config.last_resort)
            case OperatorOrder(command=command, person_seen=person_seen, force=force):
                decided = _operator_decision(self, command, state, person_seen, force)
                return Denied(decided) if isinstance(decided, str) else decided
        raise TypeError(f"not a stimulus: {stimulus!r}")

    # -- the stimuli -------------------------------------------------------------------------------------------------
    def _start(self, state: VehicleState) -> Decision:
        """Begin the mission from where the vehicle is: search, at least at ``search_altitude_m``."""
        if self.phase is not LandingPhase.IDLE:
            raise RuntimeError(f"started in phase {self.phase.value}")
        self._last_target_s = state.t_s
        self.budget.started_s = state.t_s
        self._heading_deg = state.yaw_deg
        altitude = max(state.altitude_m, self.config.search_altitude_m)
        self.climb.start(altitude)
        n, e, event = state.north_m, state.east_m, DecisionEvent.MISSION_START
        return self.steer(state, LandingPhase.SEARCH, None, "mission start", n, e, altitude, event)

    def _frame(self, result: FrameResult, state: VehicleState) -> Decision:
        """Decide after one processed frame (``state`` at the frame's decision time)."""
        c = self.config
        if self.phase in FRAMES_IGNORED:
            ignored = f"frame ignored in {self.phase.value}"
            return Decision(state.t_s, self.phase, CommandKind.NONE, None, None, ignored, DecisionEvent.FRAME_IGNORED)
        if self.phase is LandingPhase.HOLD:  # perception is back
            self.enter(self._resume_phase, state.t_s)
        if self.phase is LandingPhase.DESCENT:
            return self._descent(result, state)
        climbing = self.climb.below_choosing(state)  # all the way back up, and choose only there
        if climbing is not None:
            self._last_target_s = state.t_s  # no search pattern while climbing back
            north_m, east_m, to_m = climbing
            reason = f"{CLIMBING_BACK} {to_m:.1f} m before choosing again"
            return self.steer(state, LandingPhase.SEARCH, None, reason, north_m, east_m, to_m, DecisionEvent.CLIMB_BACK)
        target, said, changes = self._choose(result, state)
        note = "" if said is None else f"; {said}"
        if target is None:
            since = state.t_s - (self._last_target_s if self._last_target_s is not None else state.t_s)
            alt = self.climb.search_altitude_m
            if since < c.search_timeout_s:
                n, e, said, event = state.north_m, state.east_m, "no target yet: hold", DecisionEvent.HOLD_NO_TARGET
            else:
                n, e = self.search.waypoint(state.t_s, state.north_m, state.east_m, alt)
                said, event = "no target: search pattern", DecisionEvent.SEARCH_PATTERN
            return self.steer(state, LandingPhase.SEARCH, None, said + note, n, e, alt, event, zone_changes=changes)
        self._last_target_s = state.t_s
        self.search.reset()
        self.climb.observe(state)
        offset = math.hypot(target.north_m - state.north_m, target.east_m - state.east_m)
        if (
            offset <= c.capture_radius_m
            and (target.radius_m >= self.min_zone_radius_m or c.blind_landing)
            and self.climb.to_m is None
        ):
            self.descent.lock(target)
            self.enter(LandingPhase.DESCENT, state.t_s)
            return self._descent(result, state)
        return self.steer(
            state,
            LandingPhase.APPROACH,
            target,
            f"approach target {target.track_id} ({offset:.1f} m away, r={target.radius_m:.1f} m)"
            + ("" if self.climb.to_m is None else f", climbing back to {self.climb.to_m:.1f} m first")
            + note,
            target.north_m,
            target.east_m,
            max(state.altitude_m, c.land_altitude_m, self.climb.to_m or 0.0),
            DecisionEvent.APPROACH,
            zone_changes=changes,
        )

    def _choose(
        self, result: FrameResult, state: VehicleState
    ) -> tuple[Target | None, str | None, tuple[CommitmentEvent, ...]]:
        """The committed target after this frame, and what changed in the commitment: in words (for the log) and
        as events."""
        c = self.config
        if self.fallback.current is not None:  # flying to a fallback site: the site is the target
            return self.fallback.current.target, None, ()
        proposed = result.target
        if proposed is not None and proposed.track_id is None:  # the blind baseline's point: drawn once, kept
            inside = self.geofence.contains_ne(proposed.north_m, proposed.east_m)
            return (proposed, None, ()) if inside else (None, "the point lies outside the geofence", ())
        elapsed_s = self.budget.elapsed_s(state.t_s)
        choice = self.commitment.choose(
            result.tracks,
            result.head_plane,
            SelectionContext(result.t_s, state.north_m, state.east_m),
            altitude_m=state.altitude_m,
            trusted=state.altitude_m >= c.perception_min_altitude_m,
            time_left_s=c.mission_time_limit_s - elapsed_s,
            descent_rate_mps=c.descent_rate_limit_mps,
        )
        if choice.watching is not None:  # zones to watch: the search pattern waits for the observation window
            self._last_target_s = state.t_s
        return choice.target, choice.text, choice.events

    def _descent(self, result: FrameResult, state: VehicleState) -> Decision:
        """One frame of the descent (:class:`~companion.guidance.descent.Descent` decides): go on, land, or abort."""
        step = self.descent.step(result, state)
        if step.kind is StepKind.ABORT:
            assert step.cause is not None
            return self.abort_descent(state, step.reason, step.cause)
        locked = self.descent.locked
        assert locked is not None
        if step.kind is StepKind.LAND:
            self.enter(LandingPhase.LAND, state.t_s)
            return Decision(state.t_s, LandingPhase.LAND, CommandKind.LAND, None, locked, step.reason, step.event)
        n, e, alt = locked.north_m, locked.east_m, step.goal_altitude_m
        return self.steer(state, LandingPhase.DESCENT, locked, step.reason, n, e, alt, step.event, step.cause)

    def _silence(self, state: VehicleState, silent_s: float) -> Decision | None:
        """No processed frame for ``silent_s`` (wall or vehicle time, the caller's watchdog): T1 hold, T2 failsafe."""
        c = self.config
        if self.phase in ACTIVE_PHASES and silent_s >= c.hold_after_silence_s:
            self._resume_phase = LandingPhase.SEARCH if self.phase is LandingPhase.DESCENT else self.phase
            if self.phase is LandingPhase.DESCENT:
                self.descent.drop()
            self._hold = self.safe_setpoint(state, state.north_m, state.east_m, state.altitude_m)
            self.enter(LandingPhase.HOLD, state.t_s)
            said, event = f"perception silent {silent_s:.1f} s: hold", DecisionEvent.PERCEPTION_HOLD
            return Decision(state.t_s, LandingPhase.HOLD, CommandKind.SETPOINT, self._hold, None, said, event)
        if self.phase is LandingPhase.HOLD and silent_s >= c.failsafe_after_silence_s:
            return self.failsafe(state, f"perception silent {silent_s:.1f} s", DecisionEvent.PERCEPTION_FAILSAFE)
        return None

    def _landed(self, t_s: float) -> Decision:
        """The autopilot reports the vehicle on the ground."""
        self.enter(LandingPhase.DONE, t_s)
        locked = self.descent.locked
        return Decision(t_s, LandingPhase.DONE, CommandKind.NONE, None, locked, "landed", DecisionEvent.LANDED)

    def _pilot_took_over(self, t_s: float, mode: str) -> Decision:
        """The flight mode left OFFBOARD without us: yield at once, for the rest of the flight."""
        self.enter(LandingPhase.YIELDED, t_s)
        said, event = f"pilot took over (mode {mode})", DecisionEvent.PILOT_TOOK_OVER
        return Decision(t_s, LandingPhase.YIELDED, CommandKind.NONE, None, None, said, event)

    @property
    def commanding(self) -> bool:
        """True while the companion may still send setpoints."""
        return self.phase in (*ACTIVE_PHASES, LandingPhase.HOLD)


# -- the ground station's commands (module-private: the landing logic's own parts, decided through LandingGuidance.on)
OPERATOR_EVENTS: dict[OperatorCommand, tuple[DecisionEvent, str]] = {
    OperatorCommand.GO_AROUND: (DecisionEvent.OPERATOR_GO_AROUND, "go-around from the ground station"),
    OperatorCommand.REJECT_ZONE: (DecisionEvent.OPERATOR_REJECT, "zone rejected from the ground station"),
    OperatorCommand.LAND_NOW: (DecisionEvent.OPERATOR_LAND, "land now, from the ground station"),
}
"""What each ground-station command is, as a decision: its event and its words."""


def _operator_decision(
    g: LandingGuidance, command: OperatorCommand, state: VehicleState, person_seen: bool, force: bool
) -> Decision | str:
    """A ground station's command to the landing logic ``g`` at ``state``: its decision, or why it is denied (in
    words; a denial changes nothing). ``person_seen``: the newest map sees a person in the footprint at the target;
    ``force``: land even so (the decision says it).

    A go-around, and a rejection in the descent, abort the descent as a refused point does (climb back, a
    re-selection spent, the point refused); a rejection in the approach refuses the zone and chooses again from where
    the vehicle is; land-now commands the landing over the target, the vehicle within ``capture_radius_m`` of it; the
    next fallback site ends the search (or gives up the site flown to) for the nearest fallback site not tried yet, as
    the end of the search's budget does (:func:`_next_fallback`)."""
    if command is OperatorCommand.NEXT_FALLBACK:
        return _next_fallback(g, state)
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


def _next_fallback(g: LandingGuidance, state: VehicleState) -> Decision | str:
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
    return _next_site(g, state, said, RefusalCause.OPERATOR)


# -- the search's budget and the fallback sites (module-private, decided through LandingGuidance.on) -----------------
def _budget(
    g: LandingGuidance, state: VehicleState, energy_low: str | None = None, reach_m: float | None = None
) -> Decision | None:
    """The search's budget (:class:`~companion.guidance.fallback.SearchBudget`, with the energy budget's word
    ``energy_low`` and reach ``reach_m``: :mod:`companion.guidance.energy`) as a decision: the nearest fallback site
    in reach, else the last resort; or flying on to the site flown to, said."""
    if g.budget.started_s is None or g.phase not in (*ACTIVE_PHASES, LandingPhase.HOLD):
        return None
    step = g.budget.step(state, energy_low, reach_m)
    if step is None or step.kind is BudgetStepKind.NEXT_SITE:
        return None if step is None else _next_site(g, state, step.reason, step.cause)
    site, event = g.fallback.current, DecisionEvent.ENERGY_LOW
    assert site is not None  # flown on to
    return Decision(state.t_s, g.phase, CommandKind.NONE, None, site.target, step.reason, event)


def _next_site(g: LandingGuidance, state: VehicleState, reason: str, cause: RefusalCause | None) -> Decision:
    """Fly to the nearest fallback site left in reach (:mod:`companion.guidance.fallback`), climbing first to the
    search's altitude; with none left, the last resort the search's end named."""
    end = g.fallback.ended_by
    assert end is not None  # set by the budget's end before any site is chosen
    site = g.fallback.next(state)
    if site is None:
        said = f"{reason}; no fallback site left in reach" if g.fallback.sites else reason
        return g.failsafe(state, said, end.event, end.action, cause)
    g.descent.drop()
    alt = max(state.altitude_m, g.climb.search_altitude_m)
    g.climb.to_m, g.climb.over_ne_m = alt, (state.north_m, state.east_m)
    said = f"{reason}: fallback site {site.name}, {g.fallback.distance_m(state):.0f} m away"
    n, e, event = site.north_m, site.east_m, DecisionEvent.FALLBACK_SITE
    return g.steer(state, LandingPhase.APPROACH, site.target, said, n, e, alt, event, cause)
