"""Commitment to a landing target: a chosen zone is kept until it fails a check, not re-chosen frame by frame.

The paper re-applies its selection policy at every frame. Over a camera that moves with the vehicle, the biggest
zone in view changes as the view does: the vehicle turns towards whatever is biggest now, the view moves, and a
zone elsewhere becomes the biggest (measured: 15 to 666 re-selections in the missions that held for 300 s). Here
the policy chooses once, and the choice stands:

- **Choice.** With nothing committed, the policy (``biggest``, ``oldest``, ``nearest``) picks among the eligible
  tracks of this frame: seen in it, larger than the minimum zone radius by ``choose_margin_m`` (0 by default;
  kept down to the minimum), the footprint around its centre inside the geofence, and not near a point refused
  earlier. So "biggest" and "oldest" mean what they mean at the moment of choice.
- **Observation window.** The mission's first choice waits until zones have been watched for ``observe_s``
  (from the first frame with a zone that may be chosen). Chosen at that first frame, every track is new: "oldest"
  was a tie that the track ids broke in the order the zones were found, biggest first, so ``oldest`` and
  ``biggest`` landed on the same point in most scenes (issue 63: 311 of 400 ROI scene pairs). After the window the
  zones that persisted are older than the ones that came and went, as the paper's "oldest SLZ" means.
- **Follow.** The committed zone is the same zone on the ground, not only the same track: far zones flicker in and
  out of the map and each return starts a new track, so a zone seen now that overlaps its last circle continues
  it (``reacquire_iou``).
- **Release**, only when the committed zone fails a check: it was not seen for ``lost_after_s``, it shrank below
  the vehicle's footprint and margin, its footprint left the geofence, or a person was seen inside the footprint
  around its centre for ``occupied_frames_to_release`` frames in a row (the point is then refused, as after an
  aborted descent).
- **Switch.** A rival replaces the committed zone only when the policy's own score rates it better by
  ``switch_margin`` (relative) for ``switch_after_s`` seconds in a row, it can be reached and landed on within the
  mission's remaining time, and fewer than ``max_switches`` switches were made: re-selection cannot restart the
  approach without end.

Every change is returned with its reason, for the flight log. Times are vehicle-clock seconds; positions world NED
metres. No I/O.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydantic import Field

from companion.config import StrictModel
from companion.guidance.footprint import footprint_view
from companion.guidance.geofence import Geofence
from companion.guidance.vocabulary import CommitmentEvent, RefusalCause, ZoneChange
from companion.perception.projection import HeadPlaneOccupancy
from companion.perception.selection import SelectionContext, SelectionPolicy, Target, target_of
from companion.perception.tracking import TrackedZone
from companion.perception.zones import circle_iou


class CommitmentConfig(StrictModel):
    """How firmly a chosen landing zone is kept (vehicle-clock seconds, metres)."""

    switch_margin: float = Field(
        default=0.3,
        ge=0.0,
        le=10.0,
        description="A rival must score this fraction better than the committed zone under the policy's own score "
        "(biggest: a 30 % larger radius; oldest: 30 % older; nearest: 30 % closer).",
    )
    switch_after_s: float = Field(
        default=3.0, ge=0.0, le=120.0, description="The same rival must stay that much better this long."
    )
    max_switches: int = Field(
        default=3,
        ge=0,
        le=100,
        description="Rival switches in a mission; after them only a failed check releases the committed zone.",
    )
    occupied_frames_to_release: int = Field(
        default=4,
        ge=1,
        le=100,
        description="Consecutive frames with a person seen inside the committed zone's footprint to release it (the "
        "model's false positives flicker for 1-2 frames; a person stays).",
    )
    choose_margin_m: float = Field(
        default=0.0,
        ge=0.0,
        le=10.0,
        description="A zone is chosen only when its radius exceeds the smallest zone radius by this much; once chosen "
        "it is kept down to that radius. A zone just above the footprint flickers in and out of the map and is "
        "given up again within a second or two (issue 33: 150 of the 172 zones of 1.0-1.2 m chosen in the ROI "
        "table's holds), but in a crowd it may be all there is: 0.3 m rescued holds and made others (nothing "
        "chosen for 300 s), so it is not the default.",
    )
    refused_radius_m: float = Field(
        default=3.0,
        ge=0.0,
        le=100.0,
        description="A zone whose centre lies this close to a refused landing point is not chosen.",
    )
    refused_memory_s: float = Field(
        default=60.0, ge=0.0, le=3600.0, description="How long a refused point stays refused (people move)."
    )
    reacquire_iou: float = Field(
        default=0.3,
        gt=0.0,
        le=1.0,
        description="The tracker lost the committed zone: a zone seen now that overlaps its last circle by this IoU "
        "continues it (far zones flicker in and out of the map, and each return starts a new track).",
    )
    reacquire_in_descent: bool = Field(
        default=True,
        description="The same during a descent: a zone seen now that overlaps the landing point's circle by "
        "reacquire_iou, within capture_radius_m of it, refines the point as its own track would (False: before "
        "issue 63, the point stays where its lost track left it; at the walker gate a zone that reshapes as people "
        "pass starts a new track beside it, and the footprint around the stale point overlaps the map's margin).",
    )
    lost_after_s: float = Field(
        default=3.0,
        ge=0.0,
        le=60.0,
        description="Release the committed zone after this long without a zone seen where it was.",
    )
    observe_s: float = Field(
        default=5.0,
        ge=0.0,
        le=60.0,
        description="The mission's first choice waits until zones have been watched this long (from the first frame "
        "with a zone that may be chosen), so that tracks have ages: 'oldest' is then the zone tracked longest, not a "
        "tie among new tracks. 0: choose at the first frame (before issue 63).",
    )
    approach_speed_mps: float = Field(
        default=2.0,
        gt=0.0,
        le=30.0,
        description="Horizontal speed assumed by the reachability check (conservative: the autopilot flies faster).",
    )


def seen_again(
    north_m: float, east_m: float, radius_m: float, seen_now: Sequence[TrackedZone], min_iou: float
) -> tuple[TrackedZone, float] | None:
    """The zone a lost one is seen again as: of the zones ``seen_now``, the one whose circle overlaps the lost
    circle (centre NED, m; radius m) most, with that IoU, when it is at least ``min_iou`` (``reacquire_iou``); None
    otherwise. The commitment follows its zone by it, and a descent its landing point."""
    if not seen_now:
        return None
    iou = circle_iou([(north_m, east_m, radius_m)], [(t.north_m, t.east_m, t.radius_m) for t in seen_now])[0]
    k = int(np.argmax(iou))
    return (seen_now[k], float(iou[k])) if iou[k] >= min_iou else None


@dataclass(frozen=True)
class RefusedPoint:
    """A landing point refused at ``t_s`` (a person seen there, or a descent aborted over it)."""

    north_m: float
    east_m: float
    t_s: float
    reason: str


@dataclass(frozen=True)
class Choice:
    """The committed target after a frame, and what changed in the commitment (in order; empty: nothing)."""

    target: Target | None
    events: tuple[CommitmentEvent, ...] = ()
    watching: str | None = None  # in the observation window before the mission's first choice: in words

    @property
    def text(self) -> str | None:
        """What changed, and the observation window, in words (None: nothing)."""
        return "; ".join([e.text for e in self.events] + ([self.watching] if self.watching else [])) or None


class TargetCommitment:
    """Keeps one chosen zone (see the module docstring).

    Parameters
    ----------
    config : CommitmentConfig
        Margins and times.
    policy : SelectionPolicy
        Chooses among eligible tracks and scores them (higher is better) for the switch margin.
    geofence : Geofence
        The footprint around a zone's centre must lie inside.
    footprint_radius_m : float
        Vehicle radius plus margin: the disc around a zone's centre that must stay free.
    min_zone_radius_m : float
        Smallest zone radius that may be chosen or kept.
    """

    def __init__(
        self,
        config: CommitmentConfig,
        policy: SelectionPolicy,
        geofence: Geofence,
        footprint_radius_m: float,
        min_zone_radius_m: float,
    ) -> None:
        self.config = config
        self.policy = policy
        self.geofence = geofence
        self.footprint_radius_m = footprint_radius_m
        self.min_zone_radius_m = min_zone_radius_m
        self.committed_id: int | None = None
        self.switches = 0
        self._zone: TrackedZone | None = None  # the committed zone as last seen
        self._seen_s = 0.0
        self.refused: list[RefusedPoint] = []
        self._occupied_frames = 0
        self._rival_id: int | None = None
        self._rival_since_s = 0.0
        self._watch_from_s: float | None = None  # the first frame with a zone that may be chosen
        self._chosen_once = False

    def reset(self) -> None:
        """A new mission: nothing committed, nothing refused, the observation window ahead."""
        self._release()
        self.switches = 0
        self.refused.clear()
        self._watch_from_s = None
        self._chosen_once = False

    # -- what the guidance tells it ---------------------------------------------------------------------------------
    def refuse(self, north_m: float, east_m: float, t_s: float, reason: str) -> None:
        """Refuse a landing point (an aborted descent over it) and release the committed zone."""
        self.refused.append(RefusedPoint(north_m, east_m, t_s, reason))
        self._release()

    def is_refused(self, north_m: float, east_m: float, t_s: float) -> bool:
        """A refused point within ``refused_radius_m`` that is still remembered."""
        c = self.config
        return any(
            t_s - p.t_s <= c.refused_memory_s
            and math.hypot(north_m - p.north_m, east_m - p.east_m) < c.refused_radius_m
            for p in self.refused
        )

    def inside_fence(self, north_m: float, east_m: float) -> bool:
        """The footprint around this landing point lies inside the geofence."""
        return self.geofence.distance_inside_m(north_m, east_m) >= self.footprint_radius_m

    def eligible(self, track: TrackedZone, t_s: float) -> bool:
        """May be chosen now: seen in this frame, larger than the smallest zone by ``choose_margin_m``, its footprint
        inside the fence, not refused."""
        return (
            track.misses == 0
            and track.radius_m >= self.min_zone_radius_m + self.config.choose_margin_m
            and self.inside_fence(track.north_m, track.east_m)
            and not self.is_refused(track.north_m, track.east_m, t_s)
        )

    # -- one frame ----------------------------------------------------------------------------------------------------
    def choose(
        self,
        tracks: Sequence[TrackedZone],
        head_plane: HeadPlaneOccupancy,
        context: SelectionContext,
        altitude_m: float,
        trusted: bool,
        time_left_s: float,
        descent_rate_mps: float,
    ) -> Choice:
        """The committed target after this frame.

        Parameters
        ----------
        tracks : sequence of TrackedZone
            The tracker's live tracks after the frame.
        head_plane : HeadPlaneOccupancy
            The frame's map, for the committed zone's footprint.
        context : SelectionContext
            Frame time (vehicle clock) and the vehicle's position, as the policy sees them.
        altitude_m : float
            The vehicle's altitude, for the time a descent takes.
        trusted : bool
            The map decides at this altitude (above ``perception_min_altitude_m``).
        time_left_s : float
            Mission time left for the approach and the landing.
        descent_rate_mps : float
            Vertical speed of a descent, for the reachability check.
        """
        t_s = context.t_s
        events: list[CommitmentEvent] = []
        committed = self._follow(tracks, t_s, events)
        if committed is not None:
            failed: tuple[RefusalCause, str] | None = None
            if committed.radius_m < self.min_zone_radius_m:
                failed = RefusalCause.ZONE_SHRANK, f"zone {committed.track_id} shrank to {committed.radius_m:.2f} m"
            elif not self.inside_fence(committed.north_m, committed.east_m):
                failed = RefusalCause.LEFT_GEOFENCE, f"zone {committed.track_id}'s footprint left the geofence"
            else:
                view = footprint_view(head_plane, committed.north_m, committed.east_m, self.footprint_radius_m)
                seen = trusted and view.occupied_seen
                self._occupied_frames = self._occupied_frames + 1 if seen else 0
                if self._occupied_frames >= self.config.occupied_frames_to_release:
                    failed = (
                        RefusalCause.PERSON_IN_FOOTPRINT,
                        f"person seen inside zone {committed.track_id}'s footprint",
                    )
                    self.refused.append(RefusedPoint(committed.north_m, committed.east_m, t_s, failed[1]))
            if failed is not None:
                events.append(CommitmentEvent(ZoneChange.RELEASE, failed[0], f"released: {failed[1]}"))
                self._release()
                committed = None
        candidates = [t for t in tracks if t.track_id != self.committed_id and self.eligible(t, t_s)]
        if committed is None:
            watching_s = self._watching(candidates, t_s)
            if watching_s is not None:
                words = f"watching zones {watching_s:.1f} of {self.config.observe_s:g} s before the first choice"
                return Choice(None, tuple(events), words)
            best = next((t for t in candidates if t.track_id == self._best_id(candidates, context)), None)
            if best is None:
                return Choice(None, tuple(events))
            self._commit(best, t_s)
            text = f"committed to zone {best.track_id} ({self.policy.name}, r={best.radius_m:.1f} m)"
            events.append(CommitmentEvent(ZoneChange.COMMIT, None, text))
            return Choice(target_of(best), tuple(events))
        switched_to = self._rival(committed, candidates, context, altitude_m, time_left_s, descent_rate_mps)
        if switched_to is not None:
            rival, text = switched_to
            events.append(CommitmentEvent(ZoneChange.SWITCH, None, text))
            committed = rival
        return Choice(target_of(committed), tuple(events))

    def _follow(self, tracks: Sequence[TrackedZone], t_s: float, events: list[CommitmentEvent]) -> TrackedZone | None:
        """The committed zone in this frame's tracks: its own track, else a track seen now that overlaps its last
        circle (the tracker lost it and started another), else its last circle for ``lost_after_s``; None when
        nothing is committed or it was not seen for that long (released)."""
        last = self._zone
        if last is None:
            return None
        own = next((t for t in tracks if t.track_id == last.track_id), None)
        if own is not None and own.misses == 0:
            self._zone, self._seen_s = own, t_s
            return own
        seen_now = [t for t in tracks if t.misses == 0 and t.track_id != last.track_id]
        found = seen_again(last.north_m, last.east_m, last.radius_m, seen_now, self.config.reacquire_iou)
        if found is not None:
            again, overlap = found
            text = f"zone {last.track_id} seen again as zone {again.track_id} (IoU {overlap:.2f})"
            events.append(CommitmentEvent(ZoneChange.REACQUIRE, None, text))
            self._zone, self._seen_s = again, t_s
            self.committed_id = again.track_id
            self._rival_id = None if self._rival_id == again.track_id else self._rival_id
            return again
        if t_s - self._seen_s > self.config.lost_after_s:
            text = f"released: zone {last.track_id} not seen for {self.config.lost_after_s:g} s"
            events.append(CommitmentEvent(ZoneChange.RELEASE, RefusalCause.ZONE_LOST, text))
            self._release()
            return None
        return own if own is not None else last  # coasting: the track's prediction, else where it was last seen

    def _watching(self, candidates: Sequence[TrackedZone], t_s: float) -> float | None:
        """In the observation window before the mission's first choice: how long zones have been watched (s); None
        once it is over (or before any zone may be chosen, when there is nothing to watch)."""
        if self._chosen_once or not candidates:
            return None
        if self._watch_from_s is None:
            self._watch_from_s = t_s
        watched_s = t_s - self._watch_from_s
        return watched_s if watched_s < self.config.observe_s else None

    def _commit(self, track: TrackedZone, t_s: float) -> None:
        self._chosen_once = True
        self._zone, self._seen_s = track, t_s
        self.committed_id = track.track_id
        self._occupied_frames = 0
        self._rival_id = None

    def _release(self) -> None:
        self._zone = None
        self.committed_id = None
        self._occupied_frames = 0
        self._rival_id = None

    def _best_id(self, candidates: Sequence[TrackedZone], context: SelectionContext) -> int | None:
        best = self.policy.select(candidates, context)
        return None if best is None else best.track_id

    def _rival(
        self,
        committed: TrackedZone,
        candidates: list[TrackedZone],
        context: SelectionContext,
        altitude_m: float,
        time_left_s: float,
        descent_rate_mps: float,
    ) -> tuple[TrackedZone, str] | None:
        """Switch to the policy's best rival once it has been clearly better for long enough: the rival and the
        event, or None."""
        c = self.config
        best_id = self._best_id(candidates, context) if self.switches < c.max_switches else None
        rival = next((t for t in candidates if best_id is not None and t.track_id == best_id), None)
        if rival is None or not self._better(rival, committed, context):
            self._rival_id = None
            return None
        distance_m = math.hypot(rival.north_m - context.vehicle_north_m, rival.east_m - context.vehicle_east_m)
        needed_s = distance_m / c.approach_speed_mps + max(altitude_m, 0.0) / descent_rate_mps
        if needed_s > time_left_s:
            self._rival_id = None
            return None
        if self._rival_id != rival.track_id:
            self._rival_id, self._rival_since_s = rival.track_id, context.t_s
        if context.t_s - self._rival_since_s < c.switch_after_s:
            return None
        previous = committed.track_id
        self._commit(rival, context.t_s)
        self.switches += 1
        return rival, (
            f"switched from zone {previous} to zone {rival.track_id}: {self.policy.name} better by more than "
            f"{c.switch_margin:.0%} for {c.switch_after_s:g} s (switch {self.switches} of {c.max_switches})"
        )

    def _better(self, rival: TrackedZone, committed: TrackedZone, context: SelectionContext) -> bool:
        score_rival = self.policy.score(rival, context)
        score_committed = self.policy.score(committed, context)
        return score_rival - score_committed > self.config.switch_margin * abs(score_committed)
