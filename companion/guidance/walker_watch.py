"""Walkers closing in on the landing point: the last metres of a descent are blind, so look before them.

Below ``perception_min_altitude_m`` no map decides (the camera no longer sees the whole footprint), and the last few
metres take several seconds (5.4 s from 4.5 m in the SITL: the position controller slows towards the landing
altitude, then the autopilot lands at its own speed). A person who walks into the footprint in that time is not seen:
two landings of the ROI paper table (issue 33) had a walker 1.8 and 2.7 m from the touchdown point when the vehicle
went blind, and in the footprint 1-3 s later.

So a descent stops at a gate just above the floor and watches before it goes on. Around the landing point, each map
gives the nearest occupied cell in each of ``sectors`` directions; a sector whose distance keeps shrinking is someone
walking in. Its closing speed is the Theil-Sen slope of the sector's distances over the last ``window_s`` (the median
of the pairwise slopes: a false positive that flickers for a frame or two moves it little), and the distance it will
have left at touchdown is the distance now less the closing speed times ``blind_descent_s``. The descent goes on below
the gate once the gate's maps span ``window_s`` and none of the last ``clear_frames`` predicts a person inside the
footprint by touchdown, and, once someone was seen walking in, none has for ``clear_after_walker_s`` (a walker who
wanders makes the fit dip below ``min_closing_mps`` for a few maps, then walks on in: in issue 63's ROI table one did
so after a look of 0.3 s and passed under the landing descent); a wait longer than ``max_wait_s`` refuses the point
(someone keeps coming). Only maps taken at the gate count: higher up, a descending camera sees the bodies of people
standing near the point drift towards it on the head plane (parallax), which is no walk. A person standing still has
no closing speed; a person already in the footprint is the descent's own check, which at the gate waits too (the
vehicle hovers there, 3 m above the heads, and the maps at 4.5-5 m are the model's least sure: a false positive that
flickers passes after ``clear_frames``, a person who stays refuses the point after ``max_wait_s``).

This module has no I/O; times are vehicle-clock seconds, distances metres on the head plane (north/east, NED).
"""

from __future__ import annotations

import collections
import itertools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from pydantic import Field

from companion.config import StrictModel
from companion.guidance.footprint import square_around
from companion.perception.projection import HeadPlaneOccupancy

F64Array = npt.NDArray[np.float64]


class WalkerWatchConfig(StrictModel):
    """When a descent waits for a person walking towards its landing point (metres, seconds, vehicle clock)."""

    enabled: bool = Field(default=True, description="False: descend without watching for walkers (before issue 33).")
    radius_m: float = Field(
        default=8.0, gt=0.0, le=50.0, description="Occupied cells this far from the landing point are watched."
    )
    sectors: int = Field(
        default=8, ge=1, le=64, description="Directions around the landing point, each its own series."
    )
    window_s: float = Field(
        default=2.0,
        gt=0.0,
        le=10.0,
        description="Closing speed fitted over this much time; the least look at the gate.",
    )
    min_samples: int = Field(default=8, ge=2, le=100, description="Maps a sector needs in the window to be fitted.")
    min_closing_mps: float = Field(
        default=0.35,
        ge=0.0,
        le=5.0,
        description="Slower than this is standing (a blob's edge jitters by a cell or two).",
    )
    blind_descent_s: float = Field(
        default=5.5,
        gt=0.0,
        le=60.0,
        description="Time from perception_min_altitude_m to touchdown, when nothing is seen (SITL: 5.4 s from 4.5 m).",
    )
    clear_frames: int = Field(default=3, ge=1, le=100, description="Frames without a threat to resume the descent.")
    clear_after_walker_s: float = Field(
        default=2.0,
        ge=0.0,
        le=30.0,
        description=(
            "After someone was seen walking in, the look without a threat that resumes the descent (s; 0: "
            "clear_frames alone, before issue 63): a walker who wanders drops below min_closing_mps for a few maps."
        ),
    )
    max_wait_s: float = Field(default=20.0, gt=0.0, le=300.0, description="Waiting longer refuses the point.")


@dataclass(frozen=True)
class Approach:
    """A sector where someone walks in: distance now (m), closing speed (m/s), distance left at touchdown (m)."""

    sector: int
    distance_m: float
    closing_mps: float
    at_touchdown_m: float

    def describe(self) -> str:
        """For the flight log."""
        return (
            f"a person {self.distance_m:.1f} m away closing at {self.closing_mps:.1f} m/s "
            f"({self.at_touchdown_m:.1f} m left at touchdown)"
        )


def sector_distances_m(
    head_plane: HeadPlaneOccupancy, north_m: float, east_m: float, radius_m: float, sectors: int
) -> F64Array:
    """The nearest occupied (seen, not free) cell centre in each direction around a point, within ``radius_m``.

    Parameters
    ----------
    head_plane : HeadPlaneOccupancy
        One frame's map.
    north_m, east_m : float
        The point (NED, m): the landing point.
    radius_m : float
        Cells farther than this are not looked at.
    sectors : int
        Directions, each ``360 / sectors`` degrees wide.

    Returns
    -------
    ndarray, shape (sectors,)
        Metres; ``inf`` where the sector has no occupied cell within ``radius_m``. Sector 0 starts at north and they
        go clockwise (towards east), each ``360 / sectors`` degrees.
    """
    g = head_plane.grid
    n = g.north_centres_m
    e = g.east_centres_m
    rows, cols = square_around(head_plane, north_m, east_m, radius_m)
    out = np.full(sectors, np.inf)
    if not len(rows) or not len(cols):
        return out
    window = np.ix_(rows, cols)
    occupied = head_plane.known[window] & ~head_plane.free[window]
    r_idx, c_idx = np.nonzero(occupied)
    if not len(r_idx):
        return out
    dn = n[rows][r_idx] - north_m
    de = e[cols][c_idx] - east_m
    dist = np.hypot(dn, de)
    keep = dist <= radius_m
    dist, dn, de = dist[keep], dn[keep], de[keep]
    sector = (np.floor(np.mod(np.arctan2(de, dn), 2 * math.pi) / (2 * math.pi / sectors)).astype(np.int64)) % sectors
    np.minimum.at(out, sector, dist)
    return out


def theil_sen_slope(times_s: list[float], values: list[float]) -> float:
    """The median of the slopes between every pair of samples (units of value per second); nan with fewer than 2."""
    slopes = [
        (v2 - v1) / (t2 - t1)
        for (t1, v1), (t2, v2) in itertools.combinations(zip(times_s, values, strict=True), 2)
        if t2 > t1
    ]
    return float(np.median(slopes)) if slopes else math.nan


class WalkerWatch:
    """Watches the maps at one descent's gate (see the module docstring).

    Parameters
    ----------
    config : WalkerWatchConfig
        Its parameters.
    footprint_radius_m : float
        The disc that must stay free of people until touchdown (vehicle radius plus margin).
    """

    def __init__(self, config: WalkerWatchConfig, footprint_radius_m: float) -> None:
        self.config = config
        self.footprint_radius_m = footprint_radius_m
        self._history: collections.deque[tuple[float, F64Array]] = collections.deque()
        self._clear_frames = 0
        self._first_s: float | None = None
        self._walker_seen_s: float | None = None
        self.waiting_since_s: float | None = None
        """When the watch first saw someone walking in, at this gate (None: nobody yet)."""
        self.passed = False
        """The gate is passed: the descent goes on below it."""
        self.waits = 0
        """Gates at which someone walked in, since the watch was made (for the log and the tests)."""

    def reset(self) -> None:
        """A new descent, or a new landing point: forget the maps seen."""
        self._history.clear()
        self._clear_frames = 0
        self._first_s = None
        self._walker_seen_s = None
        self.waiting_since_s = None
        self.passed = False

    def rearm(self) -> None:
        """The gate was passed but the footprint is seen occupied before the floor: watch again from the gate,
        keeping the wait's start, so that :meth:`waited_too_long` still bounds the whole wait (the blocked map that
        follows starts the wait through :meth:`ready` when none had begun)."""
        waiting_since_s = self.waiting_since_s
        self.reset()
        self.waiting_since_s = waiting_since_s

    def observe(self, head_plane: HeadPlaneOccupancy, north_m: float, east_m: float, t_s: float) -> Approach | None:
        """Take one map taken at the gate; the most threatening approach (None: nobody walks in).

        Parameters
        ----------
        head_plane : HeadPlaneOccupancy
            This frame's map.
        north_m, east_m : float
            The landing point (NED, m).
        t_s : float
            The frame's vehicle time.
        """
        c = self.config
        if self._first_s is None:
            self._first_s = t_s
        distances = sector_distances_m(head_plane, north_m, east_m, c.radius_m, c.sectors)
        self._history.append((t_s, distances))
        while self._history and self._history[0][0] < t_s - c.window_s - 1e-9:
            self._history.popleft()
        worst: Approach | None = None
        for sector in range(c.sectors):
            samples = [(t, d[sector]) for t, d in self._history if math.isfinite(d[sector])]
            if len(samples) < c.min_samples or not math.isfinite(distances[sector]):
                continue
            slope = theil_sen_slope([t for t, _ in samples], [d for _, d in samples])
            closing = -slope
            if not (closing >= c.min_closing_mps):
                continue
            left = float(distances[sector]) - closing * c.blind_descent_s
            if left < self.footprint_radius_m and (worst is None or left < worst.at_touchdown_m):
                worst = Approach(sector, float(distances[sector]), closing, left)
        return worst

    def ready(self, approach: Approach | None, t_s: float, blocked: bool = False) -> bool:
        """Whether the descent may go below the gate after this map (see the module docstring). Once True, it stays
        True until :meth:`reset` (the vehicle is then below the floor, where no map decides).

        ``blocked``: this map saw the footprint itself occupied (the descent's own check, which at the gate waits
        rather than refuses): a wait like someone walking in, bounded by the same ``max_wait_s``."""
        c = self.config
        if self.passed:
            return True
        if approach is not None or blocked:
            self._clear_frames = 0
            if approach is not None:
                self._walker_seen_s = t_s
            if self.waiting_since_s is None:
                self.waiting_since_s = t_s
                self.waits += 1
            return False
        self._clear_frames += 1
        looked = self._first_s is not None and t_s - self._first_s >= c.window_s - 1e-9
        walker_gone = self._walker_seen_s is None or t_s - self._walker_seen_s >= c.clear_after_walker_s - 1e-9
        self.passed = looked and walker_gone and self._clear_frames >= c.clear_frames
        return self.passed

    def waited_too_long(self, t_s: float) -> bool:
        """Someone first seen walking in more than ``max_wait_s`` ago, and the gate not passed since."""
        return self.waiting_since_s is not None and t_s - self.waiting_since_s > self.config.max_wait_s
