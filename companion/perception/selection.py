"""Target selection: which tracked zone the vehicle should land in.

Every policy has one method, :meth:`SelectionPolicy.select`, so new ones (a multi-objective cost, say) plug in
beside the paper's. Ties are broken by track id, so a policy is deterministic for the same tracks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from companion.geometry import inside_polygon
from companion.perception.config import SelectionConfig, SelectionPolicyName
from companion.perception.tracking import TrackedZone


@dataclass(frozen=True)
class Target:
    """The chosen landing target on the head plane (world NED, m).

    ``track_id`` is None for a target that does not come from a tracked zone (the blind random baseline).
    """

    north_m: float
    east_m: float
    radius_m: float
    track_id: int | None


@dataclass(frozen=True)
class SelectionContext:
    """What a policy may know besides the tracks.

    Attributes
    ----------
    t_s : float
        Vehicle-clock time of the frame.
    vehicle_north_m, vehicle_east_m : float
        The vehicle's horizontal position (world NED).
    area_centre_ne_m : tuple of float or None
        Centre of the search area (e.g. the ROI), if the mission has one.
    """

    t_s: float
    vehicle_north_m: float
    vehicle_east_m: float
    area_centre_ne_m: tuple[float, float] | None = None


class SelectionPolicy(Protocol):
    """Chooses a target, or None when there is nothing to choose."""

    name: str

    def select(self, tracks: Sequence[TrackedZone], context: SelectionContext) -> Target | None:
        """The target for this frame."""
        ...

    def score(self, track: TrackedZone, context: SelectionContext) -> float:
        """How good a track is under this policy (higher is better; what :meth:`select` maximises), for the
        margin a rival must beat a committed target by (``companion.guidance.commitment``)."""
        ...

    def reset(self) -> None:
        """Forget any state (a new mission)."""
        ...


def target_of(track: TrackedZone) -> Target:
    """The target a tracked zone gives: its filtered circle and its id."""
    return Target(track.north_m, track.east_m, track.radius_m, track.track_id)


class BiggestPolicy:
    """The largest tracked zone (paper: "biggest SLZ")."""

    name = "biggest"

    def select(self, tracks: Sequence[TrackedZone], context: SelectionContext) -> Target | None:
        """The track with the largest radius."""
        if not tracks:
            return None
        return target_of(min(tracks, key=lambda t: (-t.radius_m, t.track_id)))

    def score(self, track: TrackedZone, context: SelectionContext) -> float:
        """The radius, m."""
        return track.radius_m

    def reset(self) -> None:
        """Stateless."""


class OldestPolicy:
    """The longest-lived tracked zone (paper: "oldest SLZ", more robust to moving people)."""

    name = "oldest"

    def select(self, tracks: Sequence[TrackedZone], context: SelectionContext) -> Target | None:
        """The track created first; of tracks born in the same frame, the one seen in most frames since."""
        if not tracks:
            return None
        return target_of(min(tracks, key=lambda t: (t.created_s, -t.hits, t.track_id)))

    def score(self, track: TrackedZone, context: SelectionContext) -> float:
        """The track's age at the frame, s."""
        return context.t_s - track.created_s

    def reset(self) -> None:
        """Stateless."""


class NearestPolicy:
    """The tracked zone whose centre is horizontally closest to the vehicle."""

    name = "nearest"

    def select(self, tracks: Sequence[TrackedZone], context: SelectionContext) -> Target | None:
        """The closest track."""
        if not tracks:
            return None
        return target_of(
            min(
                tracks,
                key=lambda t: (
                    math.hypot(t.north_m - context.vehicle_north_m, t.east_m - context.vehicle_east_m),
                    t.track_id,
                ),
            )
        )

    def score(self, track: TrackedZone, context: SelectionContext) -> float:
        """Minus the horizontal distance to the vehicle, m."""
        return -math.hypot(track.north_m - context.vehicle_north_m, track.east_m - context.vehicle_east_m)

    def reset(self) -> None:
        """Stateless."""


class RandomPolicy:
    """Blind baseline (paper: "random landing"): a seeded uniform point of the search square, or of the landing area
    when the mission has one (``perception.zones.landing_area_ne_m``).

    It ignores perception entirely. The point is drawn once, at the first call after construction or
    :meth:`reset`, and kept, like a blind emergency landing that commits to a spot.
    """

    name = "random"

    def __init__(
        self, seed: int, half_extent_m: float, landing_area_ne_m: Sequence[tuple[float, float]] | None = None
    ) -> None:
        self._seed = seed
        self._half_extent_m = half_extent_m
        self._area = None if landing_area_ne_m is None else np.asarray(landing_area_ne_m, np.float64)
        self._rng = np.random.default_rng(seed)
        self._chosen: Target | None = None

    def select(self, tracks: Sequence[TrackedZone], context: SelectionContext) -> Target | None:
        """The committed random point (radius 0, no track)."""
        if self._chosen is None:
            if self._area is not None:
                north_m, east_m = self._in_area(self._area)
            else:
                centre = context.area_centre_ne_m or (context.vehicle_north_m, context.vehicle_east_m)
                dn, de = self._rng.uniform(-self._half_extent_m, self._half_extent_m, size=2)
                north_m, east_m = centre[0] + float(dn), centre[1] + float(de)
            self._chosen = Target(north_m, east_m, 0.0, None)
        return self._chosen

    def score(self, track: TrackedZone, context: SelectionContext) -> float:
        """Zero: the blind baseline does not rate zones."""
        return 0.0

    def _in_area(self, polygon: npt.NDArray[np.float64]) -> tuple[float, float]:
        """A uniform point of the polygon: uniform points of its bounding box until one falls inside."""
        low, high = polygon.min(axis=0), polygon.max(axis=0)
        while True:  # the area encloses at least one minimum zone (ZoneConfig), so this ends
            north_m, east_m = (float(v) for v in self._rng.uniform(low, high))
            if inside_polygon(polygon, north_m, east_m).item():
                return north_m, east_m

    def reset(self) -> None:
        """Forget the point and restart the random stream from the seed."""
        self._rng = np.random.default_rng(self._seed)
        self._chosen = None


def make_policy(
    config: SelectionConfig, landing_area_ne_m: Sequence[tuple[float, float]] | None = None
) -> SelectionPolicy:
    """The policy named in the config (the random one draws inside ``landing_area_ne_m`` when there is one)."""
    if config.policy is SelectionPolicyName.BIGGEST:
        return BiggestPolicy()
    if config.policy is SelectionPolicyName.OLDEST:
        return OldestPolicy()
    if config.policy is SelectionPolicyName.NEAREST:
        return NearestPolicy()
    return RandomPolicy(config.seed, config.random_half_extent_m, landing_area_ne_m)
