"""The configured geofence: a convex or concave polygon in local NED plus an altitude band.

Every setpoint the companion sends is checked here first: a point outside is either clamped to the nearest point
inside (search and approach) or refused (the caller decides). Altitudes are metres above the local origin
(``-down_m``).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from pydantic import Field, model_validator

from companion.config import StrictModel
from companion.geometry import polygon_signed_area_m2

F64Array = npt.NDArray[np.float64]


class GeofenceConfig(StrictModel):
    """Where the companion may command the vehicle, local NED metres around the EKF origin."""

    polygon_ne_m: list[tuple[float, float]] = Field(
        default_factory=lambda: [(-25.0, -25.0), (-25.0, 25.0), (25.0, 25.0), (25.0, -25.0)],
        min_length=3,
        description="Vertices (north_m, east_m) of the allowed area, in order (either direction).",
    )
    polygon_latlon_deg: list[tuple[float, float]] | None = Field(
        default=None,
        min_length=3,
        description="The fence's vertices as (latitude_deg, longitude_deg), WGS-84, instead of polygon_ne_m: turned "
        "into local NED at the flight's start from the autopilot's EKF origin (GPS_GLOBAL_ORIGIN), as PX4 projects "
        "(azimuthal equidistant). Every other place in the config stays in local NED metres.",
    )
    min_altitude_m: float = Field(default=0.0, ge=-10.0, le=500.0, description="Lowest setpoint altitude.")
    max_altitude_m: float = Field(default=60.0, gt=0.0, le=500.0, description="Highest setpoint altitude.")

    @model_validator(mode="after")
    def _check(self) -> GeofenceConfig:
        if self.polygon_latlon_deg is not None:
            if "polygon_ne_m" in self.model_fields_set:
                raise ValueError("give polygon_ne_m or polygon_latlon_deg, not both")
            for lat, lon in self.polygon_latlon_deg:
                if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
                    raise ValueError(f"polygon_latlon_deg vertex ({lat}, {lon}) is not a latitude and longitude")
        if self.max_altitude_m <= self.min_altitude_m:
            raise ValueError(
                f"max_altitude_m ({self.max_altitude_m}) must exceed min_altitude_m ({self.min_altitude_m})"
            )
        if not all(math.isfinite(v) for corner in self.polygon_ne_m for v in corner):
            raise ValueError("polygon_ne_m corners must be finite numbers")
        if abs(polygon_signed_area_m2(self.polygon_ne_m)) < 1.0:
            raise ValueError("polygon_ne_m must enclose at least 1 m^2")
        crossing = first_self_intersection(self.polygon_ne_m)
        if crossing is not None:
            i, j = crossing
            raise ValueError(
                f"polygon_ne_m must be a simple polygon: edge {i} (corner {i} to {(i + 1) % len(self.polygon_ne_m)}) "
                f"touches or crosses edge {j}"
            )
        return self


def _orientation(a: tuple[float, float], b: tuple[float, float], c: tuple[float, float]) -> float:
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _on_segment(a: tuple[float, float], b: tuple[float, float], p: tuple[float, float]) -> bool:
    return min(a[0], b[0]) <= p[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])


def _segments_meet(
    a: tuple[float, float], b: tuple[float, float], c: tuple[float, float], d: tuple[float, float]
) -> bool:
    """Closed segments ab and cd share at least one point."""
    o1, o2, o3, o4 = _orientation(a, b, c), _orientation(a, b, d), _orientation(c, d, a), _orientation(c, d, b)
    if ((o1 > 0 and o2 < 0) or (o1 < 0 and o2 > 0)) and ((o3 > 0 and o4 < 0) or (o3 < 0 and o4 > 0)):
        return True
    return (
        (o1 == 0 and _on_segment(a, b, c))
        or (o2 == 0 and _on_segment(a, b, d))
        or (o3 == 0 and _on_segment(c, d, a))
        or (o4 == 0 and _on_segment(c, d, b))
    )


def first_self_intersection(polygon_ne_m: list[tuple[float, float]]) -> tuple[int, int] | None:
    """The first pair of edges (i, j) of a closed polygon that touch or cross, other than neighbours at their shared
    corner; None for a simple polygon. Edge i runs from corner i to corner i + 1 (the last back to the first)."""
    n = len(polygon_ne_m)
    edges = [(polygon_ne_m[i], polygon_ne_m[(i + 1) % n]) for i in range(n)]
    for i in range(n):
        for j in range(i + 1, n):
            neighbours = j == i + 1 or (i == 0 and j == n - 1)
            if neighbours:
                # Neighbours share one corner; they must not fold back over each other.
                shared = edges[i][1] if j == i + 1 else edges[i][0]
                other_i = edges[i][0] if j == i + 1 else edges[i][1]
                other_j = edges[j][1] if j == i + 1 else edges[j][0]
                collinear = _orientation(shared, other_i, other_j) == 0
                folds = collinear and (_on_segment(shared, other_i, other_j) or _on_segment(shared, other_j, other_i))
                if folds or other_i == shared or other_j == shared:
                    return i, j
                continue
            if _segments_meet(*edges[i], *edges[j]):
                return i, j
    return None


def _closest_on_segment(p: F64Array, a: F64Array, b: F64Array) -> F64Array:
    ab = b - a
    t = float(np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0))
    return np.asarray(a + t * ab, np.float64)


class Geofence:
    """Point-in-polygon and clamping for the configured fence."""

    def __init__(self, config: GeofenceConfig) -> None:
        self.config = config
        self.polygon = np.asarray(config.polygon_ne_m, np.float64)

    def contains_ne(self, north_m: float, east_m: float) -> bool:
        """Inside the polygon (boundary included), by ray casting."""
        p = np.array([north_m, east_m])
        n = len(self.polygon)
        inside = False
        for i in range(n):
            a, b = self.polygon[i], self.polygon[(i + 1) % n]
            if np.linalg.norm(_closest_on_segment(p, a, b) - p) < 1e-9:
                return True
            if (a[1] > east_m) != (b[1] > east_m):
                north_cross = a[0] + (east_m - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
                if north_m < north_cross:
                    inside = not inside
        return inside

    def contains(self, north_m: float, east_m: float, altitude_m: float) -> bool:
        """Inside the polygon and the altitude band."""
        c = self.config
        return c.min_altitude_m <= altitude_m <= c.max_altitude_m and self.contains_ne(north_m, east_m)

    def clamp(self, north_m: float, east_m: float, altitude_m: float) -> tuple[float, float, float]:
        """The nearest allowed point (the point itself when inside)."""
        c = self.config
        alt = min(max(altitude_m, c.min_altitude_m), c.max_altitude_m)
        if self.contains_ne(north_m, east_m):
            return north_m, east_m, alt
        p = np.array([north_m, east_m])
        n = len(self.polygon)
        best = min(
            (_closest_on_segment(p, self.polygon[i], self.polygon[(i + 1) % n]) for i in range(n)),
            key=lambda q: float(np.linalg.norm(q - p)),
        )
        # Step a hair inside so that the clamped point passes contains() despite rounding.
        centroid = self.polygon.mean(axis=0)
        inward = centroid - best
        norm = float(np.linalg.norm(inward))
        if norm > 0:
            nudged = best + inward / norm * min(0.01, norm)
            if self.contains_ne(float(nudged[0]), float(nudged[1])):
                best = nudged
        return float(best[0]), float(best[1]), alt

    def distance_inside_m(self, north_m: float, east_m: float) -> float:
        """Distance to the nearest edge, positive inside, negative outside."""
        p = np.array([north_m, east_m])
        n = len(self.polygon)
        d = min(
            float(np.linalg.norm(_closest_on_segment(p, self.polygon[i], self.polygon[(i + 1) % n]) - p))
            for i in range(n)
        )
        return d if self.contains_ne(north_m, east_m) else -d

    @property
    def bounds_ne_m(self) -> tuple[float, float, float, float]:
        """(north_min, north_max, east_min, east_max) of the polygon."""
        return (
            float(self.polygon[:, 0].min()),
            float(self.polygon[:, 0].max()),
            float(self.polygon[:, 1].min()),
            float(self.polygon[:, 1].max()),
        )


EARTH_RADIUS_M = 6_371_000.0
"""PX4's (CONSTANTS_RADIUS_OF_EARTH): its local frame is an azimuthal equidistant projection on this sphere."""


def latlon_to_ne_m(lat_deg: float, lon_deg: float, origin_lat_deg: float, origin_lon_deg: float) -> tuple[float, float]:
    """(north_m, east_m) of a WGS-84 point in the local NED frame whose origin is ``origin`` (PX4's map projection:
    azimuthal equidistant on a sphere, ``lib/geo`` ``map_projection_project``)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    lat0, lon0 = math.radians(origin_lat_deg), math.radians(origin_lon_deg)
    cos_d_lon = math.cos(lon - lon0)
    arg = max(-1.0, min(1.0, math.sin(lat0) * math.sin(lat) + math.cos(lat0) * math.cos(lat) * cos_d_lon))
    c = math.acos(arg)
    k = c / math.sin(c) if abs(c) > 1e-12 else 1.0
    north = k * (math.cos(lat0) * math.sin(lat) - math.sin(lat0) * math.cos(lat) * cos_d_lon) * EARTH_RADIUS_M
    east = k * math.cos(lat) * math.sin(lon - lon0) * EARTH_RADIUS_M
    return north, east
