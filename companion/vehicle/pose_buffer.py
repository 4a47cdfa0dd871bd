"""A time-indexed buffer of vehicle poses, interpolated at a frame's capture time.

Telemetry arrives as positions (local NED, metres) and attitudes (quaternions, body FRD to world NED), each stamped
with the vehicle's clock (MAVLink ``time_boot_ms`` / ``time_usec``, seconds here). A camera frame is paired with the
pose *at its capture time*: positions are interpolated linearly and attitudes by spherical linear interpolation
between the two samples around that time. A time outside the buffered span, or a gap between samples wider than
``max_gap_s``, gives no pose: the frame is dropped and counted, never paired with a stale pose.
"""

from __future__ import annotations

import bisect
import math
from collections import deque

import numpy as np
import numpy.typing as npt

from companion.errors import SlzError
from companion.geometry import Pose

F64Array = npt.NDArray[np.float64]


class PoseBufferError(SlzError):
    """Bad telemetry given to the pose buffer (what, and the offending value)."""


def slerp(q0: F64Array, q1: F64Array, fraction: float) -> F64Array:
    """Spherical linear interpolation between unit quaternions [w, x, y, z] (shortest arc), normalised."""
    q0 = q0 / np.linalg.norm(q0)
    q1 = q1 / np.linalg.norm(q1)
    dot = float(np.dot(q0, q1))
    if dot < 0.0:  # q and -q are the same rotation: take the short way
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly parallel: linear is exact enough and avoids dividing by ~0
        q = q0 + fraction * (q1 - q0)
        return np.asarray(q / np.linalg.norm(q), np.float64)
    theta = math.acos(min(1.0, dot))
    s = math.sin(theta)
    q = (math.sin((1.0 - fraction) * theta) / s) * q0 + (math.sin(fraction * theta) / s) * q1
    return np.asarray(q / np.linalg.norm(q), np.float64)


class _Series:
    def __init__(self, capacity: int) -> None:
        self.times: deque[float] = deque(maxlen=capacity)
        self.values: deque[F64Array] = deque(maxlen=capacity)

    def add(self, t_s: float, value: F64Array) -> None:
        if self.times and t_s < self.times[-1]:
            raise PoseBufferError(f"time went backwards: {t_s} after {self.times[-1]}")
        if self.times and t_s == self.times[-1]:
            self.values[-1] = value  # the same instant again (duplicate message): keep the latest
            return
        self.times.append(t_s)
        self.values.append(value)

    def around(self, t_s: float, max_gap_s: float) -> tuple[int, int, float] | None:
        """Indices of the samples on each side of ``t_s`` and the fraction between them, or None."""
        if not self.times or t_s < self.times[0] or t_s > self.times[-1]:
            return None
        times = list(self.times)
        i = bisect.bisect_left(times, t_s)
        if times[i] == t_s:
            return i, i, 0.0
        t0, t1 = times[i - 1], times[i]
        if t1 - t0 > max_gap_s:
            return None
        return i - 1, i, (t_s - t0) / (t1 - t0)


class PoseBuffer:
    """Positions and attitudes of the last few seconds, queried at any instant between samples.

    Parameters
    ----------
    capacity : int
        Samples kept per series (at 50 Hz telemetry, 500 is 10 s).
    max_gap_s : float
        Two samples further apart than this are not interpolated between (a telemetry dropout).
    """

    def __init__(self, capacity: int = 500, max_gap_s: float = 0.25) -> None:
        if capacity < 2 or not max_gap_s > 0:
            raise ValueError(f"need capacity >= 2 and max_gap_s > 0, got {capacity}, {max_gap_s}")
        self.max_gap_s = max_gap_s
        self._position = _Series(capacity)
        self._attitude = _Series(capacity)

    def add_position(self, t_s: float, north_m: float, east_m: float, down_m: float) -> None:
        """A local position sample (NED, metres) at vehicle time ``t_s`` (s)."""
        value = np.array([north_m, east_m, down_m], np.float64)
        if not (math.isfinite(t_s) and np.isfinite(value).all()):
            raise PoseBufferError(f"non-finite position sample at t={t_s}: {value.tolist()}")
        self._position.add(t_s, value)

    def add_attitude(self, t_s: float, q_wxyz: npt.ArrayLike) -> None:
        """An attitude sample, unit quaternion [w, x, y, z] (body FRD to world NED), at vehicle time ``t_s`` (s)."""
        q = np.asarray(q_wxyz, np.float64).reshape(4)
        norm = float(np.linalg.norm(q))
        if not (math.isfinite(t_s) and math.isfinite(norm) and norm > 1e-6):
            raise PoseBufferError(f"invalid attitude sample at t={t_s}: {q.tolist()}")
        self._attitude.add(t_s, q / norm)

    @property
    def latest_t_s(self) -> float | None:
        """The newest instant at which both a position and an attitude exist (vehicle time, s)."""
        if not self._position.times or not self._attitude.times:
            return None
        return min(self._position.times[-1], self._attitude.times[-1])

    def pose_at(self, t_s: float) -> Pose | None:
        """The pose at vehicle time ``t_s``, or None when it is outside the buffer or inside a dropout."""
        p = self._position.around(t_s, self.max_gap_s)
        a = self._attitude.around(t_s, self.max_gap_s)
        if p is None or a is None:
            return None
        i0, i1, f = p
        position = (1.0 - f) * self._position.values[i0] + f * self._position.values[i1]
        j0, j1, g = a
        q = slerp(self._attitude.values[j0], self._attitude.values[j1], g)
        return Pose.from_ned_quaternion(float(position[0]), float(position[1]), float(position[2]), q)
