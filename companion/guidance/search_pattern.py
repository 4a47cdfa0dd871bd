"""The search pattern: an expanding square around where the search began, inside the geofence.

The landing state machine (:mod:`companion.guidance.landing`) holds position while it waits for a target; with none
for a leg's time it flies this pattern, one leg per ``leg_s`` of vehicle time, and starts it again from wherever it
is once a target was chosen and given up.
"""

from __future__ import annotations

from companion.guidance.geofence import Geofence

DIRECTIONS_NE = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))
"""The legs' directions in turn (north, east, south, west), NED."""


class ExpandingSquare:
    """Legs N, E, S, S, W, W, N, N, N, ... of lengths 1, 1, 2, 2, 3, 3, ... times ``leg_m``, one per ``leg_s``.

    Parameters
    ----------
    leg_m : float
        The first leg's length, metres.
    leg_s : float
        Vehicle seconds per leg.
    geofence : Geofence
        Every waypoint is clamped into it.
    """

    def __init__(self, leg_m: float, leg_s: float, geofence: Geofence) -> None:
        self.leg_m, self.leg_s, self.geofence = leg_m, leg_s, geofence
        self._origin_ne_m: tuple[float, float] | None = None
        self._started_s = 0.0

    def reset(self) -> None:
        """The next waypoint starts a new square from where the vehicle is then."""
        self._origin_ne_m = None

    def waypoint(self, t_s: float, north_m: float, east_m: float, altitude_m: float) -> tuple[float, float]:
        """The waypoint (north, east, m) at vehicle time ``t_s``; the square starts at (``north_m``, ``east_m``) when
        none is under way; ``altitude_m`` is the search's, for the fence."""
        if self._origin_ne_m is None:
            self._origin_ne_m = (north_m, east_m)
            self._started_s = t_s
        k = int((t_s - self._started_s) // self.leg_s)
        n, e = self._origin_ne_m
        for leg in range(k + 1):
            dn, de = DIRECTIONS_NE[leg % 4]
            length = self.leg_m * (leg // 2 + 1)
            n, e = n + dn * length, e + de * length
        n, e, _ = self.geofence.clamp(n, e, altitude_m)
        return n, e
