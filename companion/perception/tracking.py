"""Multiple landing zone tracking: one Kalman filter per zone, IoU + Hungarian association (paper, II-C).

State ``x = [north_m, east_m, radius_m, v_north_mps, v_east_mps, v_radius_mps]``, constant-velocity model
``F = [[I3, dt I3], [0, I3]]``, process noise ``Q = sigma_a * [[dt^4/4 I3, dt^3/2 I3], [dt^3/2 I3, dt^2 I3]]``
(the paper's form: ``sigma_a`` scales an acceleration variance), measurement ``z = [I3 0] x + v``,
``v ~ N(0, R)`` with ``R = diag(s_p^2, s_p^2, s_r^2)``.

Each frame: every track predicts to the frame's time; predicted circles and detected zones are paired by the
Hungarian algorithm on their IoU, and pairs below ``mu`` are rejected. A paired track is corrected; an unpaired
track counts a miss and is deleted after ``mu_1`` consecutive misses; an unpaired zone starts a track while
fewer than ``M_p`` exist (largest zones first). Times are the vehicle's clock, in seconds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from companion.perception.config import TrackingConfig
from companion.perception.errors import PerceptionError
from companion.perception.kalman import KalmanFilter
from companion.perception.zones import Zone, circle_iou


@dataclass(frozen=True)
class TrackedZone:
    """A snapshot of one track after a frame.

    Attributes
    ----------
    track_id : int
        Unique within the tracker's life, starting at 1.
    north_m, east_m, radius_m : float
        Filtered circle on the head plane (world NED).
    v_north_mps, v_east_mps, v_radius_mps : float
        Filtered rates of change.
    created_s, last_seen_s : float
        Vehicle-clock times of the track's first and latest associated zone.
    age_s : float
        Time since creation at the snapshot's frame.
    hits : int
        Number of frames with an associated zone.
    misses : int
        Consecutive frames without one (0 if seen in this frame).
    """

    track_id: int
    north_m: float
    east_m: float
    radius_m: float
    v_north_mps: float
    v_east_mps: float
    v_radius_mps: float
    created_s: float
    last_seen_s: float
    age_s: float
    hits: int
    misses: int

    @property
    def area_m2(self) -> float:
        """Area of the tracked disc, m^2."""
        return math.pi * self.radius_m**2


class _Track:
    def __init__(self, track_id: int, zone: Zone, t_s: float, config: TrackingConfig) -> None:
        self.track_id = track_id
        self.created_s = t_s
        self.last_seen_s = t_s
        self.hits = 1
        self.misses = 0
        sp, sr, sv = (
            config.measurement_std_position_m,
            config.measurement_std_radius_m,
            config.initial_std_velocity_mps,
        )
        self.kf = KalmanFilter(
            x=np.array([zone.north_m, zone.east_m, zone.radius_m, 0.0, 0.0, 0.0]),
            P=np.diag([sp**2, sp**2, sr**2, sv**2, sv**2, sv**2]),
            H=np.hstack([np.eye(3), np.zeros((3, 3))]),
            R=np.diag([sp**2, sp**2, sr**2]),
        )

    def predict(self, F: npt.NDArray[np.float64], Q: npt.NDArray[np.float64]) -> None:
        self.kf.predict(F=F, Q=Q)
        self.kf.x[2] = max(float(self.kf.x[2]), 0.0)

    def update(self, zone: Zone) -> None:
        self.kf.update(np.array([zone.north_m, zone.east_m, zone.radius_m]))
        self.kf.x[2] = max(float(self.kf.x[2]), 0.0)

    def circle(self) -> tuple[float, float, float]:
        x = self.kf.x
        return float(x[0]), float(x[1]), float(x[2])

    def snapshot(self, t_s: float) -> TrackedZone:
        x = [float(v) for v in self.kf.x]
        return TrackedZone(
            track_id=self.track_id,
            north_m=x[0],
            east_m=x[1],
            radius_m=x[2],
            v_north_mps=x[3],
            v_east_mps=x[4],
            v_radius_mps=x[5],
            created_s=self.created_s,
            last_seen_s=self.last_seen_s,
            age_s=t_s - self.created_s,
            hits=self.hits,
            misses=self.misses,
        )


class ZoneTracker:
    """Tracks zones across frames (see the module docstring for the model)."""

    def __init__(self, config: TrackingConfig) -> None:
        self.config = config
        self._tracks: list[_Track] = []
        self._next_id = 1
        self._last_t_s: float | None = None
        self._cached_model: tuple[float, npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None

    def reset(self) -> None:
        """Forget every track (ids keep increasing)."""
        self._tracks.clear()
        self._last_t_s = None

    def _advance(self, t_s: float, where: str) -> None:
        if not math.isfinite(t_s):
            raise PerceptionError(where, f"time must be finite, got {t_s}")
        if self._last_t_s is not None and t_s < self._last_t_s:
            raise PerceptionError(
                where, f"time went backwards: {t_s:.6f} s after {self._last_t_s:.6f} s (frames out of order?)"
            )
        dt_s = 0.0 if self._last_t_s is None else t_s - self._last_t_s
        if dt_s > 0.0 and self._tracks:
            F, Q = self._model(dt_s)
            for track in self._tracks:
                track.predict(F, Q)
        self._last_t_s = t_s

    def _model(self, dt_s: float) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Transition F (6, 6) and process noise Q (6, 6) for a step of ``dt_s``, cached for the last dt."""
        if self._cached_model is None or self._cached_model[0] != dt_s:
            i3 = np.eye(3)
            F = np.block([[i3, dt_s * i3], [np.zeros((3, 3)), i3]])
            Q = self.config.sigma_a * np.block(
                [[dt_s**4 / 4.0 * i3, dt_s**3 / 2.0 * i3], [dt_s**3 / 2.0 * i3, dt_s**2 * i3]]
            )
            self._cached_model = (dt_s, F, Q)
        return self._cached_model[1], self._cached_model[2]

    def predict(self, t_s: float) -> list[TrackedZone]:
        """Advance every track to ``t_s`` without an observation (a frame that could not be evaluated).

        No miss is counted: nothing was seen either way.
        """
        self._advance(t_s, "tracking.predict")
        return self.snapshot(t_s)

    def update(self, t_s: float, zones: Sequence[Zone]) -> list[TrackedZone]:
        """Process the zones found in the frame captured at ``t_s`` (vehicle clock, s).

        An empty ``zones`` is a frame that was evaluated and showed no zone: tracks are predicted only and
        each counts a miss.
        """
        self._advance(t_s, "tracking.update")
        unmatched_zones = list(range(len(zones)))
        matched_tracks: set[int] = set()
        if self._tracks and zones:
            iou = circle_iou([t.circle() for t in self._tracks], [(z.north_m, z.east_m, z.radius_m) for z in zones])
            rows, cols = linear_sum_assignment(-iou)
            for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
                if iou[r, c] >= self.config.iou_threshold:
                    track = self._tracks[r]
                    track.update(zones[c])
                    track.hits += 1
                    track.misses = 0
                    track.last_seen_s = t_s
                    matched_tracks.add(r)
                    unmatched_zones.remove(c)
        survivors = []
        for i, track in enumerate(self._tracks):
            if i not in matched_tracks:
                track.misses += 1
                if track.misses >= self.config.max_misses:
                    continue
            survivors.append(track)
        self._tracks = survivors
        for c in sorted(unmatched_zones, key=lambda k: (-zones[k].radius_m, k)):
            if len(self._tracks) >= self.config.max_tracks:
                break
            self._tracks.append(_Track(self._next_id, zones[c], t_s, self.config))
            self._next_id += 1
        return self.snapshot(t_s)

    def snapshot(self, t_s: float) -> list[TrackedZone]:
        """Every live track, in creation order."""
        return [track.snapshot(t_s) for track in self._tracks]
