"""Safe landing zone proposals: the largest free circles of the head-plane occupancy (paper, section II-B).

The paper computes the distance transform of the free area, takes its maximum as the largest inscribed circle,
draws that circle as occupied and repeats up to N_p times. Drawing a disc of radius ``r`` at ``c`` changes the
Euclidean distance map to ``min(C, max(0, |p - c| - r))``, and only within ``2 r`` of ``c`` (the map nowhere
exceeds ``r``), so we compute the transform once and apply that update: the same circles for a fraction of
the cost of N_p transforms. The transform only nominates centres: it is OpenCV's 5x5 chamfer approximation (within
about 2 % of Euclidean, five times faster than the exact one), and every zone's radius is then computed exactly
against the nearby samples.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from companion.cache import KeyedCache
from companion.geometry import inside_polygon
from companion.perception.config import ZoneConfig
from companion.perception.projection import GridSpec, HeadPlaneOccupancy

BOUNDS_MASKS_KEPT = 16
"""Grids whose bounds masks a :class:`ZoneFinder` keeps (a hover's few snapped grids; 160 KB each at the default
400 x 400 cells)."""


@dataclass(frozen=True)
class Zone:
    """A circular zone on the head plane: centre (world NED north/east, m) and radius (m)."""

    north_m: float
    east_m: float
    radius_m: float

    @property
    def area_m2(self) -> float:
        """Area of the disc, m^2."""
        return math.pi * self.radius_m**2


def circle_iou(
    a_ne_r: npt.ArrayLike,
    b_ne_r: npt.ArrayLike,
) -> npt.NDArray[np.float64]:
    """Intersection over union of every pair of circles (paper, Eq. 5).

    Parameters
    ----------
    a_ne_r : array_like, shape (N, 3)
        Circles as (north_m, east_m, radius_m).
    b_ne_r : array_like, shape (M, 3)
        Circles as (north_m, east_m, radius_m).

    Returns
    -------
    ndarray, shape (N, M)
        IoU in [0, 1]; 0 where both radii are zero.
    """
    a = np.asarray(a_ne_r, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(b_ne_r, dtype=np.float64).reshape(-1, 3)
    r1 = np.maximum(a[:, 2:3], 0.0)
    r2 = np.maximum(b[None, :, 2], 0.0)
    d = np.hypot(a[:, 0:1] - b[None, :, 0], a[:, 1:2] - b[None, :, 1])
    area1, area2 = np.pi * r1**2, np.pi * r2**2
    with np.errstate(divide="ignore", invalid="ignore"):
        # Lens area of two intersecting circles.
        c1 = np.clip((d**2 + r1**2 - r2**2) / (2 * d * r1), -1.0, 1.0)
        c2 = np.clip((d**2 + r2**2 - r1**2) / (2 * d * r2), -1.0, 1.0)
        k = (-d + r1 + r2) * (d + r1 - r2) * (d - r1 + r2) * (d + r1 + r2)
        lens = r1**2 * np.arccos(c1) + r2**2 * np.arccos(c2) - 0.5 * np.sqrt(np.maximum(k, 0.0))
    inter = np.where(
        d >= r1 + r2,
        0.0,
        np.where(d <= np.abs(r1 - r2), np.minimum(area1, area2), lens),
    )
    union = area1 + area2 - inter
    with np.errstate(divide="ignore", invalid="ignore"):
        iou = np.where(union > 0, inter / union, 0.0)
    return np.asarray(np.clip(np.nan_to_num(iou), 0.0, 1.0), dtype=np.float64)


class ZoneFinder:
    """Finds up to ``n_proposals`` largest free circles of at least ``vehicle_radius_m + margin_m``.

    Grid cells are point samples of the occupancy. A zone's radius is the distance from its centre to the
    nearest non-free sample (or to a zone already drawn) less half a cell, the midpoint between the last free
    and the first non-free sample. The grid's outer ring counts as not free: nothing is known beyond it. With a
    landing area (``ZoneConfig.landing_area_ne_m``), samples outside it count as not free too, so every zone lies
    inside the area (to within half a cell) and its edge bounds a zone's radius as a person would. The geofence
    (``fence_ne_m``, the same polygon the guidance clamps setpoints to) bounds zones the same way: ground the vehicle
    may not fly over is no landing zone, and a zone that reached across the fence overstated its radius.

    The centre is refined below the cell size: a parabola through the distance map at the maximum and its
    neighbours gives a sub-cell offset, and the radius is computed exactly at both the cell and the refined
    centre against the nearby samples; the larger exact radius wins, so refinement never overstates free space.
    """

    def __init__(self, config: ZoneConfig, fence_ne_m: Sequence[tuple[float, float]] | None = None) -> None:
        self.config = config
        self._bounds_ne_m = [
            np.asarray(polygon, np.float64) for polygon in (config.landing_area_ne_m, fence_ne_m) if polygon is not None
        ]
        # The grid is snapped to whole cells (HeadPlaneProjector.grid_for), so frames of a vehicle that hovers or
        # descends share grids: their bounds masks are computed once (a few grids kept; the same arrays either way).
        self._bounds_masks: KeyedCache[npt.NDArray[np.uint8]] = KeyedCache("bounds masks", BOUNDS_MASKS_KEPT)

    def _bounds_mask(self, grid: GridSpec) -> npt.NDArray[np.uint8] | None:
        """1 where a cell's centre lies inside every bound (landing area, fence), shape (rows, cols); None: none."""
        if not self._bounds_ne_m:
            return None
        bounds_ne_m = self._bounds_ne_m

        def build() -> npt.NDArray[np.uint8]:
            mask = landing_area_mask(bounds_ne_m[0], grid)
            for polygon in bounds_ne_m[1:]:
                mask &= landing_area_mask(polygon, grid)
            return mask

        return self._bounds_masks.get(grid, build)

    def find(self, occupancy: HeadPlaneOccupancy) -> list[Zone]:
        """Zones of one head-plane occupancy map, largest first."""
        grid = occupancy.grid
        free = occupancy.free.astype(np.uint8)
        bounds = self._bounds_mask(grid)
        if bounds is not None:
            free &= bounds
        free[[0, -1], :] = 0
        free[:, [0, -1]] = 0
        dist = np.asarray(cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_5), dtype=np.float32)
        min_radius_cells = self.config.min_radius_m / grid.resolution_m
        drawn: list[tuple[float, float, float]] = []  # (row, col, radius) in cells, as drawn into ``dist``
        zones: list[Zone] = []
        rows, cols = dist.shape
        for _ in range(self.config.n_proposals):
            row, col = divmod(int(np.argmax(dist)), cols)
            d = float(dist[row, col])
            if d - 0.5 < min_radius_cells:
                break
            centre, clearance = self._refine(free, dist, drawn, row, col, d)
            radius_cells = clearance - 0.5
            if radius_cells < min_radius_cells:
                dist[row, col] = 0.0  # the approximate map overstated this spot; look at the next best
                continue
            north_m, east_m = grid.cell_to_world(*centre)
            zones.append(Zone(north_m, east_m, radius_cells * grid.resolution_m))
            drawn.append((centre[0], centre[1], clearance))
            # Draw the disc as occupied: dist = min(dist, |p - c| - clearance), only within reach of the centre
            # (dist nowhere exceeds d, so nothing changes beyond d + clearance).
            reach = math.ceil(1.03 * d + clearance) + 1
            r0, r1 = max(0, row - reach), min(rows, row + reach + 1)
            c0, c1 = max(0, col - reach), min(cols, col + reach + 1)
            dr = (np.arange(r0, r1, dtype=np.float32) - np.float32(centre[0]))[:, None]
            dc = (np.arange(c0, c1, dtype=np.float32) - np.float32(centre[1]))[None, :]
            to_disc = np.maximum(np.sqrt(dr * dr + dc * dc) - np.float32(clearance), np.float32(0.0))
            np.minimum(dist[r0:r1, c0:c1], to_disc, out=dist[r0:r1, c0:c1])
        return zones

    @staticmethod
    def _refine(
        free: npt.NDArray[np.uint8],
        dist: npt.NDArray[np.float32],
        drawn: list[tuple[float, float, float]],
        row: int,
        col: int,
        d: float,
    ) -> tuple[tuple[float, float], float]:
        """Sub-cell centre and its exact clearance (cells) to non-free samples and drawn discs."""
        rows, cols = dist.shape

        def offset(before: float, after: float) -> float:
            curvature = before - 2.0 * d + after
            return float(np.clip(0.5 * (before - after) / curvature, -0.5, 0.5)) if curvature < 0 else 0.0

        d_row = offset(float(dist[row - 1, col]), float(dist[row + 1, col])) if 0 < row < rows - 1 else 0.0
        d_col = offset(float(dist[row, col - 1]), float(dist[row, col + 1])) if 0 < col < cols - 1 else 0.0
        reach = math.ceil(1.03 * d) + 2  # the chamfer map is within 2 % of the exact distance
        r0, c0 = max(0, row - reach), max(0, col - reach)
        blocked = np.argwhere(free[r0 : row + reach + 1, c0 : col + reach + 1] == 0).astype(np.float64)
        blocked += (r0, c0)

        def clearance(r: float, c: float) -> float:
            best = float(np.min(np.hypot(blocked[:, 0] - r, blocked[:, 1] - c))) if len(blocked) else math.inf
            for dr_, dc_, radius in drawn:
                best = min(best, math.hypot(r - dr_, c - dc_) - radius)
            return best

        at_cell = clearance(row, col)
        refined = (row + d_row, col + d_col)
        at_refined = clearance(*refined) if (d_row or d_col) else -math.inf
        return (refined, at_refined) if at_refined > at_cell else ((float(row), float(col)), at_cell)


def landing_area_mask(polygon_ne_m: npt.NDArray[np.float64], grid: GridSpec) -> npt.NDArray[np.uint8]:
    """1 where a cell's centre lies inside the polygon (vertices (K, 2) north/east m, world NED), else 0; shape
    (rows, cols)."""
    inside = inside_polygon(polygon_ne_m, grid.north_centres_m[:, None], grid.east_centres_m[None, :])
    return inside.astype(np.uint8)
