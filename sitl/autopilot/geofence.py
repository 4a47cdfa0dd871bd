"""The autopilot's geofence (PX4's geofence module): the uploaded fence, the distance and height limits from home
(``GF_MAX_HOR_DIST``, ``GF_MAX_VER_DIST``), and the action ``GF_ACTION`` asks once, when the vehicle leaves them in the
air (a breach, not every step outside). Local NED metres, simulated time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.geometry import inside_polygon
from sitl.autopilot.params import ParameterStore
from sitl.dynamics.base import F64Array

GF_ACTIONS = {1: "warn", 2: "hold", 3: "rtl", 4: "land", 5: "land"}  # 4 (terminate) is flown as land: no parachute


@dataclass(frozen=True)
class Fence:
    """An uploaded geofence in local NED: polygons as (K, 2) north/east vertex arrays, circles as (north, east,
    radius). The vehicle must be inside at least one inclusion area when there are any, and outside every exclusion
    area (PX4's ``Geofence::checkPolygons``)."""

    inclusion_polygons: tuple[F64Array, ...] = ()
    exclusion_polygons: tuple[F64Array, ...] = ()
    inclusion_circles: tuple[tuple[float, float, float], ...] = ()
    exclusion_circles: tuple[tuple[float, float, float], ...] = ()

    def __bool__(self) -> bool:
        return bool(
            self.inclusion_polygons or self.exclusion_polygons or self.inclusion_circles or self.exclusion_circles
        )

    def contains(self, north_m: float, east_m: float) -> bool:
        """The point is allowed by every area of the fence."""
        if any(inside_polygon(p, north_m, east_m) for p in self.exclusion_polygons):
            return False
        if any(math.hypot(north_m - n, east_m - e) <= r for n, e, r in self.exclusion_circles):
            return False
        if not (self.inclusion_polygons or self.inclusion_circles):
            return True
        return any(inside_polygon(p, north_m, east_m) for p in self.inclusion_polygons) or any(
            math.hypot(north_m - n, east_m - e) <= r for n, e, r in self.inclusion_circles
        )


class GeofenceWatch:
    """The fence in force and whether the vehicle is outside it.

    Parameters
    ----------
    params : ParameterStore
        Live parameters (``GF_MAX_HOR_DIST``, ``GF_MAX_VER_DIST``, ``GF_ACTION``).
    """

    def __init__(self, params: ParameterStore) -> None:
        self.params = params
        self.fence = Fence()
        self.breached = False
        """The vehicle is outside the fence in force, in the air (SYS_STATUS reports the fence unhealthy)."""

    def set(self, fence: Fence) -> None:
        """A new geofence (an upload or a clear)."""
        self.fence = fence
        self.breached = False

    @property
    def limited(self) -> bool:
        """A fence is in force: uploaded items, or a maximum distance or height."""
        return bool(self.fence) or self.params["GF_MAX_HOR_DIST"] > 0 or self.params["GF_MAX_VER_DIST"] > 0

    def outside(self, position_ned_m: F64Array, home_ned_m: F64Array) -> bool:
        """Outside the uploaded fence, or beyond GF_MAX_HOR_DIST / GF_MAX_VER_DIST from home (0: no limit)."""
        offset = position_ned_m - home_ned_m
        max_horizontal, max_vertical = self.params["GF_MAX_HOR_DIST"], self.params["GF_MAX_VER_DIST"]
        if max_horizontal > 0 and math.hypot(offset[0], offset[1]) > max_horizontal:
            return True
        if max_vertical > 0 and -offset[2] > max_vertical:
            return True
        return bool(self.fence) and not self.fence.contains(float(position_ned_m[0]), float(position_ned_m[1]))

    def breach(self, position_ned_m: F64Array, home_ned_m: F64Array, on_ground: bool) -> str | None:
        """One step of the watch: ``GF_ACTION``'s name (``warn``, ``hold``, ``rtl``, ``land``) when the vehicle has
        just left the fence in the air, else None. On the ground, or with no fence in force, nothing is breached."""
        if not self.limited or on_ground:
            self.breached = False
            return None
        outside = self.outside(position_ned_m, home_ned_m)
        action = GF_ACTIONS.get(int(self.params["GF_ACTION"])) if outside and not self.breached else None
        self.breached = outside
        return action
