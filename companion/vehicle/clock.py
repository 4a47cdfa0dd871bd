"""The vehicle's clock seen from the companion.

Telemetry is stamped by the autopilot (``time_boot_ms``); a message arrives some milliseconds after its stamp. For
every stamp received at monotonic wall time ``w``, ``stamp - w`` is at most the true offset between the clocks
(the delay only lowers it), so the largest value over a recent window is the best estimate. Frame sources without
their own capture times (V4L2, RTSP, files) stamp frames with :meth:`VehicleClock.now_s` minus their latency.
Only liveness checks use wall time; flight logic uses these vehicle times.
"""

from __future__ import annotations

import math
import time
from collections import deque


class VehicleClock:
    """Maps monotonic wall time to vehicle time.

    Parameters
    ----------
    window : int
        Stamps kept for the estimate (at 50 Hz telemetry, 250 is 5 s: a drifting clock is followed).
    """

    def __init__(self, window: int = 250) -> None:
        self._offsets: deque[float] = deque(maxlen=window)
        self._latest_stamp_s: float | None = None

    def observe(self, stamp_s: float, wall_s: float | None = None) -> None:
        """A telemetry stamp (vehicle seconds) received at ``wall_s`` (monotonic seconds; now if None)."""
        wall = time.monotonic() if wall_s is None else wall_s
        if not math.isfinite(stamp_s):
            raise ValueError(f"non-finite vehicle time stamp {stamp_s}")
        if self._latest_stamp_s is not None and stamp_s + 1.0 < self._latest_stamp_s:
            self._offsets.clear()  # the autopilot rebooted: its clock restarted
        self._latest_stamp_s = stamp_s
        self._offsets.append(stamp_s - wall)

    @property
    def synced(self) -> bool:
        """At least one stamp seen."""
        return bool(self._offsets)

    @property
    def offset_spread_s(self) -> float | None:
        """Largest minus smallest offset in the window: the spread of the transport delay plus the drift over the
        window (None before any stamp). The estimate is as good as the smallest delay; a large spread means a link
        that delays telemetry unevenly."""
        return max(self._offsets) - min(self._offsets) if self._offsets else None

    def delay_spread_s(self, fraction: float = 0.95) -> float | None:
        """How much later than the least delayed stamp ``fraction`` of the window's stamps arrived (seconds; None
        before any stamp): the spread of the transport delay (plus the drift over the window) that most telemetry
        sees. Unlike :attr:`offset_spread_s`, one stamp held up by a scheduling hiccup of a loaded machine does not
        decide it; a link that delays telemetry unevenly still does.

        Parameters
        ----------
        fraction : float
            In (0, 1]: 1 gives :attr:`offset_spread_s`.
        """
        if not 0.0 < fraction <= 1.0:
            raise ValueError(f"fraction must be in (0, 1], got {fraction}")
        if not self._offsets:
            return None
        ordered = sorted(self._offsets)
        # The offset that (1 - fraction) of the stamps fall below: the delay that ``fraction`` of them stay within.
        k = min(len(ordered) - 1, math.floor((1.0 - fraction) * len(ordered)))
        return ordered[-1] - ordered[k]

    def now_s(self, wall_s: float | None = None) -> float:
        """Vehicle time at monotonic wall time ``wall_s`` (now if None). Raises RuntimeError before any stamp."""
        if not self._offsets:
            raise RuntimeError("vehicle clock not synchronised: no telemetry stamp yet")
        wall = time.monotonic() if wall_s is None else wall_s
        return wall + max(self._offsets)
