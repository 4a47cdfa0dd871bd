"""The map-berth benchmark's geometry: where a perfect body detector's head-plane map puts a standing person."""

from __future__ import annotations

import numpy as np
import pytest

from bench.map_berth import head_plane_clearance_m

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
