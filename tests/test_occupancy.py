"""Density -> occupancy: thresholds, non-finite values, dilation in metres."""

from __future__ import annotations

import numpy as np
import pytest

from companion.perception.config import OccupancyConfig
from companion.perception.density import DensityMap
from companion.perception.errors import PerceptionError
from companion.perception.occupancy import OccupancyMapper
from companion.perception.projection import FREE, OCCUPIED

pytestmark = pytest.mark.unit


def density(values: np.ndarray, stride: int = 4) -> DensityMap:
    h, w = values.shape
    return DensityMap(values.astype(np.float32), frame_width_px=w * stride, frame_height_px=h * stride)


def test_threshold_without_dilation() -> None:
    d = np.zeros((30, 40))
    d[10, 12] = 0.5
    d[20, 30] = 0.005  # below the 0.01 threshold
    occ = OccupancyMapper(OccupancyConfig(density_threshold=0.01, dilation_m=0.0)).compute(density(d), 0.1)
    assert occ.dilation_px == 0
    assert occ.values[10, 12] == OCCUPIED
    assert (occ.values == OCCUPIED).sum() == 1
    assert occ.values[20, 30] == FREE


def test_relative_threshold_uses_the_frame_peak() -> None:
    d = np.zeros((10, 10))
    d[2, 2], d[5, 5] = 1.0, 0.2
    mapper = OccupancyMapper(OccupancyConfig(density_threshold=0.01, relative_threshold=0.5, dilation_m=0.0))
    occ = mapper.compute(density(d), 0.1)
    assert occ.values[2, 2] == OCCUPIED
    assert occ.values[5, 5] == FREE


def test_non_finite_density_is_occupied() -> None:
    d = np.zeros((10, 10))
    d[3, 3], d[4, 4], d[5, 5] = np.nan, np.inf, -np.inf
    occ = OccupancyMapper(OccupancyConfig(dilation_m=0.0)).compute(density(d), 0.1)
    assert occ.values[3, 3] == OCCUPIED
    assert occ.values[4, 4] == OCCUPIED
    assert occ.values[5, 5] == FREE  # -inf is no people


def test_dilation_radius_follows_metres_and_gsd() -> None:
    d = np.zeros((61, 61))
    d[30, 30] = 1.0
    mapper = OccupancyMapper(OccupancyConfig(dilation_m=1.0))
    # GSD 0.05 m/px, stride 4: a cell is 0.2 m, so 1 m is 5 cells.
    occ = mapper.compute(density(d), 0.05)
    assert occ.dilation_px == 5
    rows, cols = np.nonzero(occ.values == OCCUPIED)
    assert rows.min() == 25
    assert rows.max() == 35
    assert cols.min() == 25
    assert cols.max() == 35
    assert occ.values[30 + 4, 30 + 3] == OCCUPIED  # inside the disc
    assert occ.values[30 + 5, 30 + 5] == FREE  # the disc's corner is outside
    # Twice the altitude, twice the GSD: half the pixels.
    assert mapper.compute(density(d), 0.1).dilation_px == 3  # ceil(2.5)


def test_invalid_gsd() -> None:
    with pytest.raises(PerceptionError, match=r"occupancy\.dilation"):
        OccupancyMapper(OccupancyConfig()).compute(density(np.zeros((4, 4))), 0.0)
