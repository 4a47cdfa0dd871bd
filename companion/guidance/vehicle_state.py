"""The vehicle as the landing logic sees it at a decision."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class VehicleState:
    """The vehicle at a decision: vehicle-clock time (s), local NED position (m), yaw (deg)."""

    t_s: float
    north_m: float
    east_m: float
    down_m: float
    yaw_deg: float

    @property
    def altitude_m(self) -> float:
        """Height above the local origin (-down)."""
        return -self.down_m
