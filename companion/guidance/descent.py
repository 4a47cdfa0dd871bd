"""The descent over a locked landing point: refining the point, the checks that refuse it, the walker gate, the
landing's map age (the *descent* phase of :mod:`companion.guidance.landing`, whose module docstring tells the rules).

:class:`Descent` owns the state of one descent (the landing point, the unsafe frames in a row, the last map that saw
the footprint free, the walker watch) and says after each frame what the descent asks for (:class:`DescentStep`);
the state machine turns that into a decision (and an aborted descent into a climb back).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from companion.guidance.commitment import seen_again
from companion.guidance.config import GuidanceConfig
from companion.guidance.footprint import footprint_view
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent, RefusalCause
from companion.guidance.walker_watch import WalkerWatch
from companion.perception.pipeline import FrameResult
from companion.perception.selection import Target
from companion.perception.tracking import TrackedZone

WAITING_AT_GATE = "wait at"
"""How the reason of a frame spent at the walker gate begins (hovering there, watching or waiting out a person in the
footprint); for people: what counts reads the decision's event."""

GATE_SLACK_M = 0.5
"""The walker gate's maps are those taken within this of its altitude (the vehicle settles onto it from above)."""


class StepKind(enum.Enum):
    """What a descent asks for after a frame."""

    ABORT = "abort"
    """Refuse the landing point (``cause``): the state machine climbs back and re-selects, or gives up."""
    LAND = "land"
    """Command the landing on the landing point."""
    SETPOINT = "setpoint"
    """Go on: a setpoint over the landing point down to ``goal_altitude_m``."""


@dataclass(frozen=True)
class DescentStep:
    """What the descent asks for after one frame, why in words (``reason``) and as data (``event``, ``cause``)."""

    kind: StepKind
    reason: str
    event: DecisionEvent
    cause: RefusalCause | None = None
    goal_altitude_m: float = 0.0


class Descent:
    """One descent at a time over a locked landing point (see the module docstring).

    Parameters
    ----------
    config : GuidanceConfig
        The landing logic's parameters.
    footprint_radius_m : float
        The disc around the landing point that must be free.
    min_zone_radius_m : float
        Smallest zone a descent may continue over.
    inside_fence : callable
        (north_m, east_m) -> whether a landing point's footprint lies inside the geofence.
    """

    def __init__(
        self,
        config: GuidanceConfig,
        footprint_radius_m: float,
        min_zone_radius_m: float,
        inside_fence: Callable[[float, float], bool],
    ) -> None:
        self.config = config
        self.footprint_radius_m = footprint_radius_m
        self.min_zone_radius_m = min_zone_radius_m
        self.inside_fence = inside_fence
        self.walkers = WalkerWatch(config.walkers, footprint_radius_m)
        self.locked: Target | None = None
        """The landing point (a point on the ground, refined by its track), None without a descent."""
        self._unsafe_frames = 0
        self._landing_map_s: float | None = None  # last frame that saw the whole footprint free

    def lock(self, target: Target) -> None:
        """Begin a descent over ``target``."""
        self.locked = target
        self._unsafe_frames = 0
        self.walkers.reset()

    def drop(self) -> None:
        """No descent any more (refused, or interrupted by silence)."""
        self.locked = None

    def refuse(self) -> None:
        """The landing point was refused: no descent, and its free maps count for no other point."""
        self.locked = None
        self._landing_map_s = None

    def step(self, result: FrameResult, state: VehicleState) -> DescentStep:
        """What the descent asks for after this frame (``state`` at the frame's decision time)."""
        c = self.config
        locked = self.locked
        assert locked is not None
        trusted = state.altitude_m >= c.perception_min_altitude_m
        blind = state.altitude_m < c.blind_altitude_m
        # The landing point is a point on the ground. The locked track refines it while it is seen near it, or the
        # track the tracker started in its place (a zone seen now over the point's circle, as the commitment
        # reacquires its zone); a missing track (the zones of a noisy map come and go) leaves it where it was.
        track = next((t for t in result.tracks if t.track_id == locked.track_id), None)
        if track is None or track.misses > 0:
            track = self._seen_again(result.tracks, locked) or track
        shrunk = False
        seen = (
            track is not None
            and track.misses == 0
            and trusted
            and not blind
            and math.hypot(track.north_m - locked.north_m, track.east_m - locked.east_m) <= c.capture_radius_m
            and self.inside_fence(track.north_m, track.east_m)  # never refined to beyond the fence
        )
        if seen:
            assert track is not None
            shrunk = track.radius_m < self.min_zone_radius_m
            if not shrunk:
                self.locked = locked = Target(track.north_m, track.east_m, track.radius_m, track.track_id)
        # The footprint is where the vehicle will touch down: around the landing point, not under the vehicle now.
        footprint = footprint_view(result.head_plane, locked.north_m, locked.east_m, self.footprint_radius_m)
        unsafe = trusted and (footprint.occupied_seen or shrunk) and not c.blind_landing
        # At the walker gate the vehicle hovers 3 m above the heads and descends no further until the footprint is
        # seen free: there a person (or a false positive that flickers) in the footprint is waited out, up to the
        # gate's limit, instead of refusing the point at once (the maps at 4.5-5 m are the model's least sure).
        # Between the gate and the floor the same holds after the gate was passed: the descent goes back to the gate
        # and watches again, its wait still counted from when it began (so a presence that comes and goes cannot
        # hold the vehicle there past the gate's limit).
        blocked: tuple[RefusalCause, str] | None = None
        if unsafe and self._in_gate_band(state):
            if footprint.occupied_seen:
                blocked = RefusalCause.PERSON_IN_FOOTPRINT, "a person seen inside the footprint"
            else:
                blocked = RefusalCause.ZONE_SHRANK, "the zone shrank"
            unsafe = False
            if self.walkers.passed:
                self.walkers.rearm()
        self._unsafe_frames = self._unsafe_frames + 1 if unsafe else 0
        if self._unsafe_frames >= c.unsafe_frames_to_abort:
            self._unsafe_frames = 0
            if footprint.occupied_seen:
                return _abort("person seen inside the footprint", RefusalCause.PERSON_IN_FOOTPRINT)
            assert track is not None
            return _abort(f"zone {locked.track_id} shrank to {track.radius_m:.2f} m", RefusalCause.ZONE_SHRANK)
        if c.blind_landing or (trusted and footprint.known_fraction >= c.footprint_known_fraction and footprint.clear):
            self._landing_map_s = state.t_s
        offset = math.hypot(locked.north_m - state.north_m, locked.east_m - state.east_m)
        gate = self._walker_gate(result, state, locked, trusted, blocked)
        if isinstance(gate, DescentStep):
            return gate
        low = state.altitude_m <= c.land_altitude_m + c.land_tolerance_m and offset <= c.capture_radius_m
        if low and gate is None:
            age = math.inf if self._landing_map_s is None else state.t_s - self._landing_map_s
            if age > c.landing_map_max_age_s:
                no_map = f"no map saw the footprint free in the last {c.landing_map_max_age_s:g} s"
                return _abort(no_map, RefusalCause.NO_FREE_MAP)
            land = f"land on {_named(locked)} (map {age:.1f} s old)"
            return DescentStep(StepKind.LAND, land, DecisionEvent.LAND)
        goal_alt = c.approach_height_m if offset <= c.capture_radius_m else state.altitude_m
        reason = f"descend over {_named(locked)} (offset {offset:.2f} m)"
        event, cause = DecisionEvent.DESCEND, None
        if gate is not None:
            gate_m, watch_says, cause = gate
            goal_alt = max(goal_alt, gate_m)
            if watch_says:
                reason = f"{WAITING_AT_GATE} {gate_m:.1f} m over {_named(locked)}: {watch_says}"
                event = DecisionEvent.WAIT_AT_GATE
        return DescentStep(StepKind.SETPOINT, reason, event, cause, goal_alt)

    def _seen_again(self, tracks: Sequence[TrackedZone], locked: Target) -> TrackedZone | None:
        """What the landing point's lost zone is seen again as (:func:`~companion.guidance.commitment.seen_again`),
        among the zones seen in this frame that are no smaller than a landing needs; None without one, for a fallback
        site (no zone), or when ``commitment.reacquire_in_descent`` is off."""
        c = self.config.commitment
        if not c.reacquire_in_descent or locked.track_id is None or locked.track_id < 0:
            return None
        seen_now = [
            t
            for t in tracks
            if t.misses == 0 and t.track_id != locked.track_id and t.radius_m >= self.min_zone_radius_m
        ]
        found = seen_again(locked.north_m, locked.east_m, locked.radius_m, seen_now, c.reacquire_iou)
        return None if found is None else found[0]

    def gate_m(self) -> float:
        """The walker gate's altitude (m above ground): just above the floor below which no map decides."""
        return self.config.perception_min_altitude_m + self.config.land_tolerance_m

    def _in_gate_band(self, state: VehicleState) -> bool:
        """Whether the vehicle is between the walker gate (with its slack) and the floor, with a watch to keep."""
        c = self.config
        if not c.walkers.enabled or c.blind_landing:
            return False
        return c.perception_min_altitude_m <= state.altitude_m <= self.gate_m() + GATE_SLACK_M

    def _walker_gate(
        self,
        result: FrameResult,
        state: VehicleState,
        locked: Target,
        trusted: bool,
        blocked: tuple[RefusalCause, str] | None,
    ) -> DescentStep | tuple[float, str, RefusalCause | None] | None:
        """The gate above the blind last metres (:mod:`companion.guidance.walker_watch`): None once passed (or
        without a watch), else the lowest altitude allowed now, what the watch sees and what blocks the footprint,
        or an abort when someone kept walking in, or stayed in the footprint (``blocked``: what this map saw there,
        as a cause and in words), for too long."""
        c = self.config
        watch = self.walkers
        if not c.walkers.enabled or c.blind_landing or watch.passed:
            return None
        gate_m = self.gate_m()
        if not trusted:  # sank past the floor while stopping at the gate: back up, where the maps see
            return gate_m, "back up to the gate", None
        if state.altitude_m > gate_m + GATE_SLACK_M:
            watch.reset()  # only maps taken at the gate count: higher up, standing people drift in (parallax)
            return gate_m, "", None
        approach = watch.observe(result.head_plane, locked.north_m, locked.east_m, state.t_s)
        if watch.ready(approach, state.t_s, blocked=blocked is not None):
            return None
        if watch.waited_too_long(state.t_s):
            watch.reset()
            if blocked is not None and approach is None:
                stayed = f"person seen inside the footprint at the gate for {c.walkers.max_wait_s:g} s"
                return _abort(stayed, RefusalCause.PERSON_AT_GATE)
            kept = f"a person kept walking towards the footprint for {c.walkers.max_wait_s:g} s"
            return _abort(kept, RefusalCause.WALKER_KEPT_COMING)
        if blocked is not None:
            return gate_m, blocked[1], blocked[0]
        return gate_m, approach.describe() if approach is not None else "watching", None


def _named(target: Target) -> str:
    """A landing point in words: its zone, or a fallback site (whose target has a negative track id)."""
    if target.track_id is not None and target.track_id < 0:
        return "the fallback site"
    return f"zone {target.track_id}"


def _abort(reason: str, cause: RefusalCause) -> DescentStep:
    return DescentStep(StepKind.ABORT, reason, DecisionEvent.ABORT, cause)
