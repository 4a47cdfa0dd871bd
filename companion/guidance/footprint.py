"""The disc a landing needs, on one head-plane map: how much of it is known, and whether a person is seen in it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from companion.perception.projection import HeadPlaneOccupancy


@dataclass(frozen=True)
class FootprintView:
    """What one head-plane map says about a disc: the known share of its cells, and whether any is occupied."""

    known_fraction: float
    occupied_seen: bool

    @property
    def clear(self) -> bool:
        """Nothing occupied seen inside."""
        return not self.occupied_seen


def square_around(
    head_plane: HeadPlaneOccupancy, north_m: float, east_m: float, radius_m: float
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """The rows and the columns of a map whose cell centres lie within ``radius_m`` of a point, north and east
    separately: the square around a disc (either may be empty)."""
    g = head_plane.grid
    rows = np.nonzero(np.abs(g.north_centres_m - north_m) <= radius_m)[0]
    cols = np.nonzero(np.abs(g.east_centres_m - east_m) <= radius_m)[0]
    return rows, cols


def footprint_view(head_plane: HeadPlaneOccupancy, north_m: float, east_m: float, radius_m: float) -> FootprintView:
    """Inspect the cells of a head-plane map within ``radius_m`` of a point."""
    g = head_plane.grid
    rows, cols = square_around(head_plane, north_m, east_m, radius_m)
    total = math.pi * radius_m**2 / g.resolution_m**2
    if not len(rows) or not len(cols):
        return FootprintView(0.0, False)
    nn, ee = np.meshgrid(g.north_centres_m[rows], g.east_centres_m[cols], indexing="ij")
    inside = np.hypot(nn - north_m, ee - east_m) <= radius_m
    known = head_plane.known[np.ix_(rows, cols)] & inside
    occupied = known & ~head_plane.free[np.ix_(rows, cols)]
    return FootprintView(min(1.0, float(known.sum()) / max(total, 1.0)), bool(occupied.any()))


def nearest_occupied_m(head_plane: HeadPlaneOccupancy, north_m: float, east_m: float) -> float | None:
    """The horizontal distance (m) from a point to the nearest cell centre the map saw occupied (a person, with the
    map's safety dilation: so a lower bound of the distance to a body); None when the map saw no occupied cell."""
    occupied = head_plane.known & ~head_plane.free
    rows, cols = np.nonzero(occupied)
    if not len(rows):
        return None
    g = head_plane.grid
    return float(np.hypot(g.north_centres_m[rows] - north_m, g.east_centres_m[cols] - east_m).min())
