"""The per-ray footprint check of bench/gate_footprint.py on made-up maps: what it trims and what it keeps."""

from __future__ import annotations

import numpy as np
import pytest

from bench.gate_footprint import Kept, per_ray_kept
from companion.guidance.footprint import footprint_view
from companion.perception.projection import GridSpec, HeadPlaneOccupancy

pytestmark = pytest.mark.unit

GRID = GridSpec(north_min_m=-5.0, east_min_m=-5.0, resolution_m=0.1, rows=100, cols=100)
CAMERA_M = 4.8  # the gate
HEAD_M = 1.7
FOOTPRINT_M = 1.0


def run_map(
    north_from_m: float, north_to_m: float, known_north_m: tuple[float, float] = (-5.0, 5.0)
) -> HeadPlaneOccupancy:
    """Occupied where north lies in [from, to] and |east| < 0.3 m; known where north lies in ``known_north_m``."""
    north, east = np.meshgrid(GRID.north_centres_m, GRID.east_centres_m, indexing="ij")
    occupied = (north >= north_from_m) & (north <= north_to_m) & (np.abs(east) < 0.3)
    known = (north >= known_north_m[0]) & (north <= known_north_m[1])
    return HeadPlaneOccupancy(grid=GRID, free=known & ~occupied, known=known)


def as_flown(head_plane: HeadPlaneOccupancy) -> bool:
    return footprint_view(head_plane, 0.0, 0.0, FOOTPRINT_M).occupied_seen


def per_ray(head_plane: HeadPlaneOccupancy) -> bool:
    """The footprint around the nadir (the vehicle over its point, as at the gate)."""
    return per_ray_kept(head_plane, (0.0, 0.0), CAMERA_M, HEAD_M, 0.0, 0.0, FOOTPRINT_M) is not None


def test_the_lower_part_of_a_standing_persons_run_is_not_a_person_in_the_footprint() -> None:
    """A person 2.5 m out: their run from 0.9 m (feet at 2.5 * 3.1 / 4.8 = 1.6 m, less blob and dilation) to 2.7 m.
    Read from its inner end, the body stands at 0.9 * 4.8 / 3.1 = 1.4 m or beyond: outside the 1 m footprint."""
    head_plane = run_map(0.9, 2.7)
    assert as_flown(head_plane)
    assert not per_ray(head_plane)


def test_a_run_that_reaches_the_nadir_is_kept_whole() -> None:
    """Someone right under the vehicle: no inner end to read."""
    head_plane = run_map(-0.5, 2.0)
    assert as_flown(head_plane)
    assert per_ray(head_plane)


def test_a_run_that_touches_an_unknown_cell_is_kept_whole() -> None:
    """Its inner end (or its outer end) may lie beyond what the camera saw."""

    def kept(head_plane: HeadPlaneOccupancy) -> str | None:
        return per_ray_kept(head_plane, (0.0, 0.0), CAMERA_M, HEAD_M, 0.0, 0.0, FOOTPRINT_M)

    assert kept(run_map(0.9, 2.7, known_north_m=(0.9, 5.0))) == Kept.INNER_UNKNOWN
    assert kept(run_map(0.9, 2.7, known_north_m=(-5.0, 2.0))) == Kept.OUTER_UNKNOWN
    assert kept(run_map(0.9, 2.7)) is None


def test_a_short_run_inside_the_footprint_is_kept() -> None:
    """A blob from 0.6 to 0.9 m (a head, or a low person): read from its inner end the body would be at 0.93 m, beyond
    the blob, so the check keeps the blob's outer end, inside the footprint."""
    head_plane = run_map(0.6, 0.9)
    assert as_flown(head_plane)
    assert per_ray(head_plane)


def test_a_free_footprint_is_free_either_way() -> None:
    head_plane = run_map(1.5, 2.7)
    assert not as_flown(head_plane)
    assert not per_ray(head_plane)
