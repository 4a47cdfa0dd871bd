"""Density map -> binary occupancy map in image space (paper: threshold, then dilate for safety)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from companion.perception.config import OccupancyConfig
from companion.perception.density import DensityMap
from companion.perception.errors import PerceptionError
from companion.perception.projection import FREE, OCCUPIED, U8Array


@dataclass(frozen=True)
class OccupancyImage:
    """A binary occupancy map in the density map's pixel grid.

    Attributes
    ----------
    values : ndarray, shape (h, w), uint8
        255 free, 0 occupied (paper convention), after dilation.
    dilation_px : int
        Radius, in density-map cells, of the safety dilation that was applied.
    """

    values: U8Array
    dilation_px: int


class OccupancyMapper:
    """Thresholds a density map and dilates the occupied cells by a margin given in metres.

    A cell is occupied when its density reaches ``max(density_threshold, relative_threshold * max(D))``.
    Non-finite densities (NaN, inf) count as occupied: a broken network output never makes ground free.
    """

    def __init__(self, config: OccupancyConfig) -> None:
        self.config = config

    def dilation_radius_px(self, density: DensityMap, gsd_m_per_px: float) -> int:
        """Dilation radius in density cells for a frame whose finest GSD is ``gsd_m_per_px`` (m per frame px)."""
        if not (math.isfinite(gsd_m_per_px) and gsd_m_per_px > 0):
            raise PerceptionError("occupancy.dilation", f"ground sampling distance must be > 0, got {gsd_m_per_px}")
        cell_m = gsd_m_per_px * min(density.stride_x, density.stride_y)
        return math.ceil(self.config.dilation_m / cell_m - 1e-9)

    def compute(
        self, density: DensityMap, gsd_m_per_px: float, also_occupied: npt.NDArray[np.bool_] | None = None
    ) -> OccupancyImage:
        """Occupancy map of one density map.

        Parameters
        ----------
        density : DensityMap
            Output of the density model.
        gsd_m_per_px : float
            Finest ground sampling distance of the frame on the head plane, metres per frame pixel.
        also_occupied : ndarray, shape of the density map, bool, optional
            Cells occupied whatever the density says (what the camera's motion shows standing above the ground or
            moving: ``companion.perception.motion_height``); dilated like the rest.
        """
        d = density.values
        finite = np.isfinite(d)
        peak = float(d[finite].max()) if finite.any() else 0.0
        threshold = max(self.config.density_threshold, self.config.relative_threshold * peak)
        occupied = ~(d < threshold)  # NaN compares False: occupied
        if also_occupied is not None:
            if also_occupied.shape != d.shape:
                raise PerceptionError(
                    "occupancy.compute", f"also_occupied is {also_occupied.shape}, the density map {d.shape}"
                )
            occupied = occupied | also_occupied
        values = np.where(occupied, np.uint8(OCCUPIED), np.uint8(FREE)).astype(np.uint8)
        radius = self.dilation_radius_px(density, gsd_m_per_px)
        if radius > 0 and occupied.any():
            kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
            values = cv2.erode(values, kernel)  # eroding the free value grows the occupied cells
        return OccupancyImage(values=values, dilation_px=radius)
