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

import enum
import math
from dataclasses import dataclass

from pydantic import Field, model_validator

from companion.config import StrictModel
from companion.guidance.commitment import CommitmentConfig, TargetCommitment
from companion.guidance.footprint import footprint_view
from companion.guidance.geofence import Geofence
from companion.guidance.walker_watch import WalkerWatch, WalkerWatchConfig
from companion.perception.pipeline import FrameResult
from companion.perception.selection import SelectionContext, SelectionPolicy, Target
from companion.vehicle.link import Setpoint

CLIMBING_BACK = "climbing back to"
"""How the reason of a frame spent climbing back after an aborted descent begins (campaign hold causes read it)."""

WAITING_AT_GATE = "wait at"
"""How the reason of a frame spent at the walker gate begins: hovering there, watching or waiting out a person in the
footprint (campaign metrics read it: the landing descent starts when the gate lets the vehicle go)."""

GATE_SLACK_M = 0.5
"""The walker gate's maps are those taken within this of its altitude (the vehicle settles onto it from above)."""


class FailsafeAction(str, enum.Enum):
    """What the companion asks of the autopilot when perception stays silent for T2."""

    HOLD = "hold"
    """Autopilot hold (loiter) where it is."""
    LAND = "land"
    """Land in place (the autopilot's own landing)."""
    RETURN = "return"
    """Return to launch."""


class GuidanceConfig(StrictModel):
    """Landing logic parameters (metres, seconds, vehicle clock)."""

    search_altitude_m: float = Field(default=20.0, gt=2.0, le=120.0, description="Minimum altitude while searching.")
    search_timeout_s: float = Field(default=6.0, gt=0.0, le=600.0, description="No target this long: search pattern.")
    search_leg_m: float = Field(default=5.0, gt=0.0, le=100.0, description="First leg of the expanding square.")
    approach_height_m: float = Field(default=2.0, gt=0.0, le=20.0, description="Descent goal above ground (paper).")
    land_altitude_m: float = Field(default=2.0, gt=0.0, le=20.0, description="At or below: command the landing.")
    land_tolerance_m: float = Field(
        default=0.3, ge=0.0, le=5.0, description="Slack above land_altitude_m (position control converges slowly)."
    )
    capture_radius_m: float = Field(default=0.75, gt=0.0, le=10.0, description="Horizontal error to start descending.")
    max_step_m: float = Field(
        default=4.0, gt=0.0, le=50.0, description="Farthest horizontal setpoint from the vehicle."
    )
    descent_rate_limit_mps: float = Field(default=1.0, gt=0.0, le=5.0)
    autopilot_z_time_constant_s: float = Field(
        default=1.0, gt=0.0, le=10.0, description="1 / the autopilot's vertical position gain (PX4 MPC_Z_P = 1/s)."
    )
    climb_back_m: float | None = Field(
        default=4.0,
        ge=0.0,
        le=120.0,
        description="Climb after an aborted descent before choosing again (metres, at most back to the altitude the "
        "search started from). None: all the way back there, where the policy sees the whole search area (issue "
        "33: it rescued holds but lost landings that a choice from low down had made; not the default).",
    )
    blind_altitude_m: float = Field(
        default=4.5, gt=0.0, le=50.0, description="Below this the camera cannot see a whole zone on the head plane."
    )
    perception_min_altitude_m: float = Field(
        default=4.5,
        ge=0.0,
        le=50.0,
        description="Below this, maps do not decide: the descent continues on the last map from above it, and a "
        "person who walks into the footprint later is not seen. The model read magnified grass as people below "
        "about 10 m until frames were shrunk to its training scale (perception.model.min_gsd_m_per_px), and the "
        "floor was 12 m; now it is blind_altitude_m: lower, the whole view lies within the footprint and its "
        "margin, so a shadow at the frame's edge aborted descents (models/density/MODEL_CARD.md).",
    )
    landing_map_max_age_s: float = Field(
        default=12.0,
        gt=0.0,
        le=60.0,
        description="The landing needs a map this recent that saw the footprint free (the descent from "
        "perception_min_altitude_m to land_altitude_m must fit in it).",
    )
    footprint_known_fraction: float = Field(default=0.95, gt=0.0, le=1.0)
    unsafe_frames_to_abort: int = Field(
        default=4,
        ge=1,
        le=100,
        description="Consecutive frames with a person seen inside the footprint (or the zone shrunk below the "
        "minimum) to abort the descent. A person stays in the map from frame to frame; the model's false positives "
        "flicker (runs of 1-2 frames measured in SITL descents).",
    )
    max_reselections: int = Field(
        default=12,
        ge=0,
        le=100,
        description="Aborted descents before the failsafe (hold). The mission's time limit is the budget that "
        "bounds the attempts; this only stops a vehicle that keeps being refused from trying for ever.",
    )
    hold_after_silence_s: float = Field(default=1.0, gt=0.0, le=60.0, description="T1: perception silent -> hold.")
    failsafe_after_silence_s: float = Field(default=5.0, gt=0.0, le=600.0, description="T2: -> failsafe action.")
    failsafe_action: FailsafeAction = Field(
        default=FailsafeAction.HOLD,
        description="T2's action. Hold by default: a landing in place lands on whatever is below, where the map "
        "may just have refused to land (deploy/README.md, 'If the companion dies over a crowd'); return is the next "
        "best. Land only where nobody can be below (the SITL's campaigns fly the paper's land).",
    )
    mission_time_limit_s: float = Field(
        default=600.0,
        gt=0.0,
        le=7200.0,
        description="Vehicle time from the start of the search to a landing decision; used up: last_resort (the "
        "pilot or the operator decides). On the vehicle clock, so a lockstep mission ends the same way on any machine.",
    )
    last_resort: FailsafeAction = Field(
        default=FailsafeAction.HOLD,
        description="What the companion asks of the autopilot when a limit ends the mission before a landing (the "
        "mission_time_limit_s, the wall limit of `slz fly --timeout`, max_reselections): hold or return, never land "
        "(a landing the map has not chosen lands on whatever is below).",
    )
    commitment: CommitmentConfig = Field(
        default_factory=CommitmentConfig, description="How firmly a chosen zone is kept (issue 33)."
    )
    walkers: WalkerWatchConfig = Field(
        default_factory=WalkerWatchConfig,
        description="A descent waits above the blind last metres while someone walks towards its landing point.",
    )
    blind_landing: bool = Field(
        default=False,
        description="Evaluation baseline only (the paper's 'random landing', with the random selection policy): "
        "descend and land on the target without checking the map. Never on a vehicle near people.",
    )

    @model_validator(mode="after")
    def _order(self) -> GuidanceConfig:
        if self.failsafe_after_silence_s <= self.hold_after_silence_s:
            raise ValueError("failsafe_after_silence_s (T2) must exceed hold_after_silence_s (T1)")
        if self.land_altitude_m < self.approach_height_m:
            raise ValueError("land_altitude_m must be at least approach_height_m, or the descent never reaches it")
        if self.last_resort is FailsafeAction.LAND:
            raise ValueError(
                "last_resort: must be hold or return (got land): a landing the map has not chosen lands on whatever "
                "is below"
            )
        return self


class LandingPhase(str, enum.Enum):
    """States of the landing logic."""

    IDLE = "idle"
    SEARCH = "search"
    APPROACH = "approach"
    DESCENT = "descent"
    LAND = "land"
    DONE = "done"
    HOLD = "hold"
    FAILSAFE = "failsafe"
    YIELDED = "yielded"


ACTIVE_PHASES = frozenset({LandingPhase.SEARCH, LandingPhase.APPROACH, LandingPhase.DESCENT})


class CommandKind(str, enum.Enum):
    """What a decision asks of the vehicle link."""

    NONE = "none"
    SETPOINT = "setpoint"
    LAND = "land"
    HOLD = "hold"
    RETURN = "return"


@dataclass(frozen=True)
class VehicleState:
    """The vehicle at a decision: vehicle-clock time (s), local NED position (m), yaw (deg)."""

    t_s: float
    north_m: float
    east_m: float
    down_m: float
    yaw_deg: float

    @property
    def altitude_m(self) -> float:
        """Height above the local origin (-down)."""
        return -self.down_m


@dataclass(frozen=True)
class Decision:
    """One decision: the phase after it, the command, and why."""

    t_s: float
    phase: LandingPhase
    kind: CommandKind
    setpoint: Setpoint | None
    target: Target | None
    reason: str


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
        self.walkers = WalkerWatch(config.walkers, footprint_radius_m)
        self.geofence = geofence
        self.footprint_radius_m = footprint_radius_m
        self.min_zone_radius_m = min_zone_radius_m
        self.phase = LandingPhase.IDLE
        self.reselections = 0
        self._phase_since_s = 0.0
        self._last_target_s: float | None = None
        self._locked: Target | None = None
        self._unsafe_frames = 0
        self._landing_map_s: float | None = None  # last frame that saw the whole footprint free
        self._hold: Setpoint | None = None
        self._search_origin: tuple[float, float] | None = None
        self._search_started_s = 0.0
        self._search_altitude_m = config.search_altitude_m
        self._start_altitude_m = config.search_altitude_m  # the altitude the search started from
        self._reclimb_m: float | None = None  # after an aborted descent: climbing back to it, no choice below it
        self._reclimb_ne_m: tuple[float, float] | None = None  # where the climb back holds (the refused point)
        self._resume_phase = LandingPhase.SEARCH
        self._heading_deg: float | None = None
        self._started_s: float | None = None

    # -- helpers -------------------------------------------------------------------------------------------------
    def _enter(self, phase: LandingPhase, t_s: float) -> None:
        if phase is not self.phase:
            self.phase = phase
            self._phase_since_s = t_s

    def safe_setpoint(
        self, state: VehicleState, north_m: float, east_m: float, altitude_m: float, yaw_deg: float | None = None
    ) -> Setpoint:
        """The safety filter every setpoint goes through (geofence, step, descent rate).

        The heading is held: ``yaw_deg``, else the heading at :meth:`start`, else the vehicle's (a setpoint never
        chases the vehicle's own slow yaw drift, so consecutive setpoints differ only where the logic moved them).
        """
        c = self.config
        dn, de = north_m - state.north_m, east_m - state.east_m
        dist = math.hypot(dn, de)
        if dist > c.max_step_m:
            north_m, east_m = state.north_m + dn * c.max_step_m / dist, state.east_m + de * c.max_step_m / dist
        lowest = state.altitude_m - c.descent_rate_limit_mps * c.autopilot_z_time_constant_s
        altitude_m = max(altitude_m, lowest)
        north_m, east_m, altitude_m = self.geofence.clamp(north_m, east_m, altitude_m)
        if yaw_deg is None:
            yaw_deg = self._heading_deg if self._heading_deg is not None else state.yaw_deg
        return Setpoint(north_m, east_m, -altitude_m, yaw_deg)

    def _setpoint(
        self,
        state: VehicleState,
        phase: LandingPhase,
        target: Target | None,
        reason: str,
        n: float,
        e: float,
        alt: float,
    ) -> Decision:
        self._enter(phase, state.t_s)
        return Decision(state.t_s, phase, CommandKind.SETPOINT, self.safe_setpoint(state, n, e, alt), target, reason)

    def _abort_descent(self, state: VehicleState, reason: str) -> Decision:
        self.reselections += 1
        if self._locked is not None:
            self.commitment.refuse(self._locked.north_m, self._locked.east_m, state.t_s, reason)
        self._locked = None
        self._landing_map_s = None
        self._last_target_s = state.t_s
        self._search_origin = None
        if self.reselections > self.config.max_reselections:
            # Never the configured "land": the map has just refused a landing here. The last resort (hold or
            # return), and the pilot decides.
            used = f"{reason}; {self.reselections - 1} re-selections used up"
            return self._failsafe(state, used, self.config.last_resort)
        climb_back_m = self.config.climb_back_m
        if climb_back_m is None:
            climb_to = self._start_altitude_m
        else:
            climb_to = min(state.altitude_m + climb_back_m, self.config.search_altitude_m)
        self._search_altitude_m = max(climb_to, state.altitude_m)
        # The next descent starts from there, not from here: low down the camera sees a few metres around the
        # footprint, and a zone next to the one just refused would be captured at once, again and again.
        self._reclimb_m = climb_to if climb_to > state.altitude_m else None
        self._reclimb_ne_m = (state.north_m, state.east_m)
        return self._setpoint(
            state,
            LandingPhase.SEARCH,
            None,
            f"{reason}: climb back and re-select",
            state.north_m,
            state.east_m,
            climb_to,
        )

    def _failsafe(self, state: VehicleState, reason: str, action: FailsafeAction | None = None) -> Decision:
        """Enter the failsafe phase with ``action`` (the configured one when None)."""
        action = action or self.config.failsafe_action
        self._enter(LandingPhase.FAILSAFE, state.t_s)
        kind = {
            FailsafeAction.HOLD: CommandKind.HOLD,
            FailsafeAction.LAND: CommandKind.LAND,
            FailsafeAction.RETURN: CommandKind.RETURN,
        }[action]
        return Decision(state.t_s, LandingPhase.FAILSAFE, kind, None, None, f"{reason}: {action.value}")

    # -- events ----------------------------------------------------------------------------------------------------
    def start(self, state: VehicleState) -> Decision:
        """Begin the mission from where the vehicle is: search, at least at ``search_altitude_m``."""
        if self.phase is not LandingPhase.IDLE:
            raise RuntimeError(f"start() in phase {self.phase.value}")
        self._last_target_s = state.t_s
        self._started_s = state.t_s
        self._heading_deg = state.yaw_deg
        altitude = max(state.altitude_m, self.config.search_altitude_m)
        self._search_altitude_m = altitude
        self._start_altitude_m = altitude
        return self._setpoint(state, LandingPhase.SEARCH, None, "mission start", state.north_m, state.east_m, altitude)

    def on_frame(self, result: FrameResult, state: VehicleState) -> Decision:
        """Decide after one processed frame (``state`` at the frame's decision time)."""
        c = self.config
        if self.phase in (
            LandingPhase.IDLE,
            LandingPhase.LAND,
            LandingPhase.DONE,
            LandingPhase.FAILSAFE,
            LandingPhase.YIELDED,
        ):
            return Decision(state.t_s, self.phase, CommandKind.NONE, None, None, f"frame ignored in {self.phase.value}")
        if self.phase is LandingPhase.HOLD:  # perception is back
            self._enter(self._resume_phase, state.t_s)
        if self.phase is LandingPhase.DESCENT:
            return self._descent(result, state)
        if self._reclimb_m is not None and c.climb_back_m is None:  # all the way back up, and choose only there
            if state.altitude_m < self._reclimb_m - c.land_tolerance_m:
                self._last_target_s = state.t_s  # no search pattern while climbing back
                assert self._reclimb_ne_m is not None  # set with _reclimb_m by every abort
                north_m, east_m = self._reclimb_ne_m
                return self._setpoint(
                    state,
                    LandingPhase.SEARCH,
                    None,
                    f"{CLIMBING_BACK} {self._reclimb_m:.1f} m before choosing again",
                    north_m,
                    east_m,
                    self._reclimb_m,
                )
            self._reclimb_m = None  # climbed back (within the slack position control leaves)
        target, event = self._choose(result, state)
        note = "" if event is None else f"; {event}"
        if target is None:
            since = state.t_s - (self._last_target_s if self._last_target_s is not None else state.t_s)
            if since < c.search_timeout_s:
                return self._setpoint(
                    state,
                    LandingPhase.SEARCH,
                    None,
                    "no target yet: hold" + note,
                    state.north_m,
                    state.east_m,
                    self._search_altitude_m,
                )
            n, e = self._search_waypoint(state)
            return self._setpoint(
                state, LandingPhase.SEARCH, None, "no target: search pattern" + note, n, e, self._search_altitude_m
            )
        self._last_target_s = state.t_s
        self._search_origin = None
        if self._reclimb_m is not None and state.altitude_m >= self._reclimb_m - c.land_tolerance_m:
            self._reclimb_m = None  # climbed back (within the slack position control leaves)
        offset = math.hypot(target.north_m - state.north_m, target.east_m - state.east_m)
        if (
            offset <= c.capture_radius_m
            and (target.radius_m >= self.min_zone_radius_m or c.blind_landing)
            and self._reclimb_m is None
        ):
            self._locked = target
            self._unsafe_frames = 0
            self.walkers.reset()
            self._enter(LandingPhase.DESCENT, state.t_s)
            return self._descent(result, state)
        return self._setpoint(
            state,
            LandingPhase.APPROACH,
            target,
            f"approach target {target.track_id} ({offset:.1f} m away, r={target.radius_m:.1f} m)"
            + ("" if self._reclimb_m is None else f", climbing back to {self._reclimb_m:.1f} m first")
            + note,
            target.north_m,
            target.east_m,
            max(state.altitude_m, c.land_altitude_m, self._reclimb_m or 0.0),
        )

    def _choose(self, result: FrameResult, state: VehicleState) -> tuple[Target | None, str | None]:
        """The committed target after this frame, and what changed in the commitment (for the log)."""
        c = self.config
        proposed = result.target
        if proposed is not None and proposed.track_id is None:  # the blind baseline's point: drawn once, kept
            inside = self.geofence.contains_ne(proposed.north_m, proposed.east_m)
            return (proposed, None) if inside else (None, "the point lies outside the geofence")
        elapsed_s = state.t_s - (self._started_s if self._started_s is not None else state.t_s)
        choice = self.commitment.choose(
            result.tracks,
            result.head_plane,
            SelectionContext(result.t_s, state.north_m, state.east_m),
            altitude_m=state.altitude_m,
            trusted=state.altitude_m >= c.perception_min_altitude_m,
            time_left_s=c.mission_time_limit_s - elapsed_s,
            descent_rate_mps=c.descent_rate_limit_mps,
        )
        return choice.target, choice.event

    def _descent(self, result: FrameResult, state: VehicleState) -> Decision:
        c = self.config
        locked = self._locked
        assert locked is not None
        trusted = state.altitude_m >= c.perception_min_altitude_m
        blind = state.altitude_m < c.blind_altitude_m
        # The landing point is a point on the ground. The locked track refines it while it is seen near it; a
        # missing track (the zones of a noisy map come and go) leaves it where it was.
        track = next((t for t in result.tracks if t.track_id == locked.track_id), None)
        shrunk = False
        seen = (
            track is not None
            and track.misses == 0
            and trusted
            and not blind
            and math.hypot(track.north_m - locked.north_m, track.east_m - locked.east_m) <= c.capture_radius_m
            and self.commitment.inside_fence(track.north_m, track.east_m)  # never refined to beyond the fence
        )
        if seen:
            assert track is not None
            shrunk = track.radius_m < self.min_zone_radius_m
            if not shrunk:
                self._locked = locked = Target(track.north_m, track.east_m, track.radius_m, track.track_id)
        # The footprint is where the vehicle will touch down: around the landing point, not under the vehicle now.
        footprint = footprint_view(result.head_plane, locked.north_m, locked.east_m, self.footprint_radius_m)
        unsafe = trusted and (footprint.occupied_seen or shrunk) and not c.blind_landing
        # At the walker gate the vehicle hovers 3 m above the heads and descends no further until the footprint is
        # seen free: there a person (or a false positive that flickers) in the footprint is waited out, up to the
        # gate's limit, instead of refusing the point at once (the maps at 4.5-5 m are the model's least sure).
        # Between the gate and the floor the same holds after the gate was passed: the descent goes back to the gate
        # and watches again, its wait still counted from when it began (so a presence that comes and goes cannot
        # hold the vehicle there past the gate's limit).
        blocked = None
        if unsafe and self._in_gate_band(state):
            blocked = "a person seen inside the footprint" if footprint.occupied_seen else "the zone shrank"
            unsafe = False
            if self.walkers.passed:
                self.walkers.rearm()
        self._unsafe_frames = self._unsafe_frames + 1 if unsafe else 0
        if self._unsafe_frames >= c.unsafe_frames_to_abort:
            self._unsafe_frames = 0
            if footprint.occupied_seen:
                return self._abort_descent(state, "person seen inside the footprint")
            assert track is not None
            return self._abort_descent(state, f"zone {locked.track_id} shrank to {track.radius_m:.2f} m")
        if c.blind_landing or (trusted and footprint.known_fraction >= c.footprint_known_fraction and footprint.clear):
            self._landing_map_s = state.t_s
        offset = math.hypot(locked.north_m - state.north_m, locked.east_m - state.east_m)
        gate = self._walker_gate(result, state, locked, trusted, blocked)
        if isinstance(gate, Decision):
            return gate
        low = state.altitude_m <= c.land_altitude_m + c.land_tolerance_m and offset <= c.capture_radius_m
        if low and gate is None:
            age = math.inf if self._landing_map_s is None else state.t_s - self._landing_map_s
            if age > c.landing_map_max_age_s:
                return self._abort_descent(
                    state, f"no map saw the footprint free in the last {c.landing_map_max_age_s:g} s"
                )
            self._enter(LandingPhase.LAND, state.t_s)
            return Decision(
                state.t_s,
                LandingPhase.LAND,
                CommandKind.LAND,
                None,
                locked,
                f"land on zone {locked.track_id} (map {age:.1f} s old)",
            )
        goal_alt = c.approach_height_m if offset <= c.capture_radius_m else state.altitude_m
        reason = f"descend over zone {locked.track_id} (offset {offset:.2f} m)"
        if gate is not None:
            gate_m, watch_says = gate
            goal_alt = max(goal_alt, gate_m)
            if watch_says:
                reason = f"{WAITING_AT_GATE} {gate_m:.1f} m over zone {locked.track_id}: {watch_says}"
        return self._setpoint(state, LandingPhase.DESCENT, locked, reason, locked.north_m, locked.east_m, goal_alt)

    def _gate_m(self) -> float:
        """The walker gate's altitude (m above ground): just above the floor below which no map decides."""
        return self.config.perception_min_altitude_m + self.config.land_tolerance_m

    def _in_gate_band(self, state: VehicleState) -> bool:
        """Whether the vehicle is between the walker gate (with its slack) and the floor, with a watch to keep."""
        c = self.config
        if not c.walkers.enabled or c.blind_landing:
            return False
        return c.perception_min_altitude_m <= state.altitude_m <= self._gate_m() + GATE_SLACK_M

    def _walker_gate(
        self, result: FrameResult, state: VehicleState, locked: Target, trusted: bool, blocked: str | None
    ) -> Decision | tuple[float, str] | None:
        """The gate above the blind last metres (:mod:`companion.guidance.walker_watch`): None once passed (or
        without a watch), else the lowest altitude allowed now and what the watch sees, or an abort when someone
        kept walking in, or stayed in the footprint (``blocked``: what this map saw there), for too long."""
        c = self.config
        watch = self.walkers
        if not c.walkers.enabled or c.blind_landing or watch.passed:
            return None
        gate_m = self._gate_m()
        if not trusted:  # sank past the floor while stopping at the gate: back up, where the maps see
            return gate_m, "back up to the gate"
        if state.altitude_m > gate_m + GATE_SLACK_M:
            watch.reset()  # only maps taken at the gate count: higher up, standing people drift in (parallax)
            return gate_m, ""
        approach = watch.observe(result.head_plane, locked.north_m, locked.east_m, state.t_s)
        if watch.ready(approach, state.t_s, blocked=blocked is not None):
            return None
        if watch.waited_too_long(state.t_s):
            watch.reset()
            if blocked is not None and approach is None:
                reason = f"person seen inside the footprint at the gate for {c.walkers.max_wait_s:g} s"
            else:
                reason = f"a person kept walking towards the footprint for {c.walkers.max_wait_s:g} s"
            return self._abort_descent(state, reason)
        if blocked is not None:
            return gate_m, blocked
        return gate_m, approach.describe() if approach is not None else "watching"

    def _search_waypoint(self, state: VehicleState) -> tuple[float, float]:
        """Expanding square around where the search began, one leg per ``search_timeout_s``, inside the fence."""
        c = self.config
        if self._search_origin is None:
            self._search_origin = (state.north_m, state.east_m)
            self._search_started_s = state.t_s
        elapsed = state.t_s - self._search_started_s
        k = int(elapsed // c.search_timeout_s)
        # Legs: N, E, S, S, W, W, N, N, N, ... lengths 1, 1, 2, 2, 3, 3, ... times the leg.
        n, e = self._search_origin
        directions = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)]
        for leg in range(k + 1):
            dn, de = directions[leg % 4]
            length = c.search_leg_m * (leg // 2 + 1)
            n, e = n + dn * length, e + de * length
        n, e, _ = self.geofence.clamp(n, e, self._search_altitude_m)
        return n, e

    def time_used_up(self, state: VehicleState) -> Decision | None:
        """The failsafe (hold) once ``mission_time_limit_s`` has passed since :meth:`start` without a landing."""
        if self._started_s is None or self.phase not in (*ACTIVE_PHASES, LandingPhase.HOLD):
            return None
        if state.t_s - self._started_s < self.config.mission_time_limit_s:
            return None
        return self.give_up(state, f"no landing within {self.config.mission_time_limit_s:g} s of the start")

    def give_up(self, state: VehicleState, reason: str) -> Decision:
        """End the mission before a landing, for a limit that ``reason`` names: the failsafe phase with
        ``last_resort`` (hold or return; never land where the map has not chosen)."""
        return self._failsafe(state, reason, self.config.last_resort)

    def perception_silent(self, state: VehicleState, silent_s: float) -> Decision | None:
        """No processed frame for ``silent_s`` (wall or vehicle time, the caller's watchdog): T1 hold, T2 failsafe."""
        c = self.config
        if self.phase in ACTIVE_PHASES and silent_s >= c.hold_after_silence_s:
            self._resume_phase = LandingPhase.SEARCH if self.phase is LandingPhase.DESCENT else self.phase
            if self.phase is LandingPhase.DESCENT:
                self._locked = None
            self._hold = self.safe_setpoint(state, state.north_m, state.east_m, state.altitude_m)
            self._enter(LandingPhase.HOLD, state.t_s)
            return Decision(
                state.t_s,
                LandingPhase.HOLD,
                CommandKind.SETPOINT,
                self._hold,
                None,
                f"perception silent {silent_s:.1f} s: hold",
            )
        if self.phase is LandingPhase.HOLD and silent_s >= c.failsafe_after_silence_s:
            return self._failsafe(state, f"perception silent {silent_s:.1f} s")
        return None

    def landed(self, t_s: float) -> Decision:
        """The autopilot reports the vehicle on the ground."""
        self._enter(LandingPhase.DONE, t_s)
        return Decision(t_s, LandingPhase.DONE, CommandKind.NONE, None, self._locked, "landed")

    def pilot_took_over(self, t_s: float, mode: str) -> Decision:
        """The flight mode left OFFBOARD without us: yield at once, for the rest of the flight."""
        self._enter(LandingPhase.YIELDED, t_s)
        return Decision(t_s, LandingPhase.YIELDED, CommandKind.NONE, None, None, f"pilot took over (mode {mode})")

    @property
    def commanding(self) -> bool:
        """True while the companion may still send setpoints."""
        return self.phase in (*ACTIVE_PHASES, LandingPhase.HOLD)
