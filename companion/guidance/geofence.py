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
from companion.perception.geometry import polygon_signed_area_m2

F64Array = npt.NDArray[np.float64]


class GeofenceConfig(StrictModel):
    """Where the companion may command the vehicle, local NED metres around the EKF origin."""

    polygon_ne_m: list[tuple[float, float]] = Field(
        default_factory=lambda: [(-25.0, -25.0), (-25.0, 25.0), (25.0, 25.0), (25.0, -25.0)],
        min_length=3,
        description="Vertices (north_m, east_m) of the allowed area, in order (either direction).",
    )
    min_altitude_m: float = Field(default=0.0, ge=-10.0, le=500.0, description="Lowest setpoint altitude.")
    max_altitude_m: float = Field(default=60.0, gt=0.0, le=500.0, description="Highest setpoint altitude.")

    @model_validator(mode="after")
    def _check(self) -> GeofenceConfig:
        if self.max_altitude_m <= self.min_altitude_m:
            raise ValueError(
                f"max_altitude_m ({self.max_altitude_m}) must exceed min_altitude_m ({self.min_altitude_m})"
            )
        if abs(polygon_signed_area_m2(self.polygon_ne_m)) < 1.0:
            raise ValueError("polygon_ne_m must enclose at least 1 m^2")
        return self


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


def horizontal_distance_m(a_ne: tuple[float, float], b_ne: tuple[float, float]) -> float:
    """Horizontal distance between two (north_m, east_m) points."""
    return math.hypot(a_ne[0] - b_ne[0], a_ne[1] - b_ne[1])
