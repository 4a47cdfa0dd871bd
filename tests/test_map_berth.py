"""The map-berth benchmark's geometry: where a perfect body detector's head-plane map puts a standing person."""

from __future__ import annotations

import numpy as np
import pytest

from bench.map_berth import head_plane_clearance_m, reach_margins_m, run_inner_end_m
from companion.perception.projection import GridSpec, HeadPlaneOccupancy

pytestmark = pytest.mark.unit

HEAD_HEIGHT_M = 1.7
BODY_RADIUS_M = 0.25


def clearance(camera_height_m: float, north_m: float) -> float:
    """Head-plane clearance at ``north_m`` (east 0) of one body standing 2.5 m north of the camera's nadir."""
    positions = np.array([[2.5, 0.0]])
    radii = np.array([BODY_RADIUS_M])
    camera = np.array([0.0, 0.0, -camera_height_m])
    value = head_plane_clearance_m(positions, radii, camera, HEAD_HEIGHT_M, np.array([north_m]), np.array([0.0]))
    return float(value[0])


def test_a_standing_body_reaches_towards_the_nadir_by_its_height_over_the_cameras() -> None:
    """At 5 m the feet meet the head plane at 2.5 m * (5 - 1.7) / 5 = 1.65 m from the nadir, the body's edge 0.165 m
    nearer: from the nadir the map's clearance is 1.485 m where the body's is 2.25 m."""
    assert clearance(5.0, 0.0) == pytest.approx((2.5 - BODY_RADIUS_M) * 3.3 / 5.0, abs=1e-6)


def test_the_reach_shrinks_as_the_camera_climbs() -> None:
    """At 40 m the same body reaches 2.5 * 1.7 / 40 = 0.11 m nearer: nearly the truth."""
    assert clearance(40.0, 0.0) == pytest.approx((2.5 - BODY_RADIUS_M) * 38.3 / 40.0, abs=1e-6)
    assert clearance(40.0, 0.0) > clearance(5.0, 0.0) + 0.6


def test_beyond_the_body_the_head_is_what_is_nearest() -> None:
    """Outward of the body the head's disc, at the true position, is the nearest part: the clearance is the truth."""
    assert clearance(5.0, 4.0) == pytest.approx(4.0 - 2.5 - BODY_RADIUS_M, abs=1e-6)


def test_a_camera_below_the_head_plane_maps_the_bodies_where_they_stand() -> None:
    assert clearance(1.0, 0.0) == pytest.approx(2.5 - BODY_RADIUS_M, abs=1e-6)


GRID = GridSpec(north_min_m=-5.0, east_min_m=-5.0, resolution_m=0.1, rows=100, cols=100)
NADIR = np.array([0.0, 0.0])
BODY = np.array([2.5, 0.0])


def blob_map(north_from_m: float, north_to_m: float, known_from_m: float = -5.0) -> HeadPlaneOccupancy:
    """A head-plane map occupied where north lies in [from, to] and |east| < 0.3 m, known north of ``known_from_m``."""
    north, east = np.meshgrid(GRID.north_centres_m, GRID.east_centres_m, indexing="ij")
    occupied = (north >= north_from_m) & (north <= north_to_m) & (np.abs(east) < 0.3)
    known = north >= known_from_m
    return HeadPlaneOccupancy(grid=GRID, free=known & ~occupied, known=known)


def inner_end(head_plane: HeadPlaneOccupancy, search_from_m: float = 1.4) -> float | None:
    return run_inner_end_m(head_plane, head_plane.known & ~head_plane.free, NADIR, BODY, search_from_m)


def test_the_run_of_a_blob_that_reaches_the_feet_ends_at_the_feet() -> None:
    """A body at 2.5 m seen from 5 m: its feet meet the head plane at 1.65 m; a blob from there to the head ends
    there, and a rule reading that end as the feet puts the body where it stands (less its radius: a margin of minus
    the radius, the column having no width)."""
    end = inner_end(blob_map(1.65, 2.75))
    assert end == pytest.approx(1.65, abs=0.1)
    assert end is not None
    margins = reach_margins_m(end, 2.5, BODY_RADIUS_M, 5.0, HEAD_HEIGHT_M)
    assert margins[0.0] == pytest.approx(-BODY_RADIUS_M, abs=0.2)
    assert margins[1.0] > margins[0.0]


def test_a_blob_on_the_head_alone_would_be_moved_beyond_the_body_by_a_feet_rule() -> None:
    """A head-point network's blob from 2.2 m to 2.75 m: read as reaching the feet, it puts the body at 3.3 m,
    a metre beyond it (margin below -1 m); read as it is, it keeps the body (margin >= 0)."""
    end = inner_end(blob_map(2.2, 2.75))
    assert end == pytest.approx(2.2, abs=0.1)
    assert end is not None
    margins = reach_margins_m(end, 2.5, BODY_RADIUS_M, 5.0, HEAD_HEIGHT_M)
    assert margins[0.0] < -1.0
    no_rule = 2.5 - BODY_RADIUS_M - end
    assert no_rule >= -0.05


def test_a_run_to_the_nadir_ends_at_zero() -> None:
    assert inner_end(blob_map(-1.0, 2.75)) == 0.0


def test_a_body_whose_ray_holds_no_occupied_cell_is_not_measured() -> None:
    assert inner_end(blob_map(3.0, 3.5)) is None


def test_a_run_that_leaves_the_known_map_is_not_measured() -> None:
    assert inner_end(blob_map(1.0, 2.75, known_from_m=1.5)) is None
