"""The altitudes of the search, and the climb back after an aborted descent (:mod:`companion.guidance.landing`).

After an aborted descent the vehicle climbs back over the refused point: by ``climb_back_m`` (capped at the search
altitude), or with ``climb_back_m`` None all the way to the altitude the search started from, choosing only there.
The search flies at least at the altitude climbed back to from then on.
"""

from __future__ import annotations

from companion.guidance.config import GuidanceConfig
from companion.guidance.vehicle_state import VehicleState


class ClimbBack:
    """The search's altitudes and the climb back in progress (times: none; altitudes above home, metres).

    Parameters
    ----------
    config : GuidanceConfig
        ``search_altitude_m``, ``climb_back_m`` and ``land_tolerance_m``.
    """

    def __init__(self, config: GuidanceConfig) -> None:
        self.config = config
        self.search_altitude_m = config.search_altitude_m
        """The altitude the search holds and flies its pattern at."""
        self.start_altitude_m = config.search_altitude_m
        """The altitude the search started from."""
        self.to_m: float | None = None
        """Climbing back to this altitude (no descent starts below it); None: not climbing back."""
        self.over_ne_m: tuple[float, float] | None = None
        """Where the climb back holds (the refused point), north and east in metres."""

    def start(self, altitude_m: float) -> None:
        """The search starts at ``altitude_m``."""
        self.search_altitude_m = altitude_m
        self.start_altitude_m = altitude_m

    def after_abort(self, state: VehicleState) -> float:
        """A descent aborted at ``state``: the altitude to climb back to (the search's from now on)."""
        climb_back_m = self.config.climb_back_m
        if climb_back_m is None:
            climb_to = self.start_altitude_m
        else:
            climb_to = min(state.altitude_m + climb_back_m, self.config.search_altitude_m)
        self.search_altitude_m = max(climb_to, state.altitude_m)
        # The next descent starts from there, not from here: low down the camera sees a few metres around the
        # footprint, and a zone next to the one just refused would be captured at once, again and again.
        self.to_m = climb_to if climb_to > state.altitude_m else None
        self.over_ne_m = (state.north_m, state.east_m)
        return climb_to

    def below_choosing(self, state: VehicleState) -> tuple[float, float, float] | None:
        """Climbing all the way back (``climb_back_m`` None) and still below the altitude to choose at: where to hold
        and how high (north, east, altitude; metres). None once up there (within the slack position control leaves:
        the climb back ends) or when not climbing all the way back."""
        if self.to_m is None or self.over_ne_m is None or self.config.climb_back_m is not None:
            return None
        if state.altitude_m < self.to_m - self.config.land_tolerance_m:
            return (*self.over_ne_m, self.to_m)
        self.to_m = None
        return None

    def observe(self, state: VehicleState) -> None:
        """The climb back ends once the vehicle is up there (within the slack position control leaves)."""
        if self.to_m is not None and state.altitude_m >= self.to_m - self.config.land_tolerance_m:
            self.to_m = None
