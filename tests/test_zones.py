"""Zone proposals and circle IoU against analytic and brute-force references."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from companion.config import ConfigError, validate_config
from companion.perception.config import ZoneConfig
from companion.perception.projection import GridSpec, HeadPlaneOccupancy
from companion.perception.zones import Zone, ZoneFinder, circle_iou, landing_area_mask

pytestmark = pytest.mark.unit

GRID = GridSpec(north_min_m=-20.0, east_min_m=-10.0, resolution_m=0.1, rows=300, cols=400)


def occupancy_with_free_discs(discs: list[tuple[float, float, float]]) -> HeadPlaneOccupancy:
    """Everything occupied except the given (north_m, east_m, radius_m) discs."""
    n = GRID.north_centres_m[:, None]
    e = GRID.east_centres_m[None, :]
    free = np.zeros((GRID.rows, GRID.cols), dtype=bool)
    for dn, de, r in discs:
        free |= np.hypot(n - dn, e - de) <= r
    return HeadPlaneOccupancy(GRID, free=free, known=np.ones_like(free))


def test_known_free_discs_are_found_with_their_centres_and_radii() -> None:
    discs = [(-5.0, 5.0, 4.0), (2.0, -3.0, 2.5), (-14.0, 20.0, 1.6), (5.0, 18.0, 3.2)]
    zones = ZoneFinder(ZoneConfig(n_proposals=10, vehicle_radius_m=0.5, margin_m=0.5)).find(
        occupancy_with_free_discs(discs)
    )
    assert len(zones) == len(discs)
    for zone, (dn, de, r) in zip(zones, sorted(discs, key=lambda d: -d[2]), strict=True):
        assert math.hypot(zone.north_m - dn, zone.east_m - de) <= GRID.resolution_m
        assert abs(zone.radius_m - r) <= GRID.resolution_m
    radii = [z.radius_m for z in zones]
    assert radii == sorted(radii, reverse=True)


def test_zones_never_contain_an_occupied_or_unknown_cell() -> None:
    rng = np.random.default_rng(7)
    free = rng.random((GRID.rows, GRID.cols)) > 0.002
    known = np.ones_like(free)
    known[:, :60] = False
    free &= known
    occupancy = HeadPlaneOccupancy(GRID, free=free, known=known)
    zones = ZoneFinder(ZoneConfig(n_proposals=20, vehicle_radius_m=0.3, margin_m=0.2)).find(occupancy)
    assert len(zones) >= 5
    n = GRID.north_centres_m[:, None]
    e = GRID.east_centres_m[None, :]
    for zone in zones:
        inside = np.hypot(n - zone.north_m, e - zone.east_m) <= zone.radius_m
        assert free[inside].all()


def test_proposals_do_not_overlap_and_respect_n_p() -> None:
    n = GRID.north_centres_m[:, None]
    e = GRID.east_centres_m[None, :]
    free = (np.abs(n + 5.0) < 3.0) & (np.abs(e - 10.0) < 15.0)  # a 6 m x 30 m free strip
    occupancy = HeadPlaneOccupancy(GRID, free=free, known=np.ones_like(free))
    zones = ZoneFinder(ZoneConfig(n_proposals=6, vehicle_radius_m=0.2, margin_m=0.0)).find(occupancy)
    assert len(zones) == 6
    for i, a in enumerate(zones):
        for b in zones[i + 1 :]:
            # Each new disc lies outside the discs already drawn (tangent at most, within a cell).
            assert math.hypot(a.north_m - b.north_m, a.east_m - b.east_m) >= a.radius_m + b.radius_m - 0.15


def test_incremental_update_matches_redrawing_and_recomputing() -> None:
    """The one-transform shortcut gives the paper's draw-the-zone-and-recompute answer."""
    rng = np.random.default_rng(11)
    free = rng.random((GRID.rows, GRID.cols)) > 0.003
    config = ZoneConfig(n_proposals=8, vehicle_radius_m=0.2, margin_m=0.0)
    fast = ZoneFinder(config).find(HeadPlaneOccupancy(GRID, free=free, known=np.ones_like(free)))
    assert len(fast) == 8

    mask = free.astype(np.uint8)
    mask[[0, -1], :] = 0
    mask[:, [0, -1]] = 0
    rows = np.arange(GRID.rows)[:, None]
    cols = np.arange(GRID.cols)[None, :]
    for zone in fast:
        reference = cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).max()
        clearance_cells = zone.radius_m / GRID.resolution_m + 0.5
        # The chamfer map nominates centres within 2 % of the exact optimum; sub-cell refinement gains < 0.71 cell.
        assert 0.98 * reference - 0.01 <= clearance_cells <= reference + 0.71
        row, col = GRID.world_to_cell(zone.north_m, zone.east_m)
        mask[np.hypot(rows - row, cols - col) <= clearance_cells] = 0  # draw the zone as occupied


def test_small_zones_are_dropped() -> None:
    occupancy = occupancy_with_free_discs([(0.0, 0.0, 0.8), (5.0, 5.0, 3.0)])
    zones = ZoneFinder(ZoneConfig(vehicle_radius_m=0.5, margin_m=0.5)).find(occupancy)
    assert len(zones) == 1
    assert zones[0].radius_m == pytest.approx(3.0, abs=0.1)


def test_fully_occupied_map_has_no_zone() -> None:
    occupancy = occupancy_with_free_discs([])
    assert ZoneFinder(ZoneConfig()).find(occupancy) == []


def numeric_iou(a: tuple[float, float, float], b: tuple[float, float, float], step: float = 0.005) -> float:
    lo = min(a[0] - a[2], b[0] - b[2]) - step
    hi = max(a[0] + a[2], b[0] + b[2]) + step
    lo_e = min(a[1] - a[2], b[1] - b[2]) - step
    hi_e = max(a[1] + a[2], b[1] + b[2]) + step
    n, e = np.meshgrid(np.arange(lo, hi, step), np.arange(lo_e, hi_e, step), indexing="ij")
    in_a = np.hypot(n - a[0], e - a[1]) <= a[2]
    in_b = np.hypot(n - b[0], e - b[1]) <= b[2]
    return float((in_a & in_b).sum() / (in_a | in_b).sum())


@pytest.mark.parametrize(
    ("a", "b"),
    [
        ((0.0, 0.0, 1.0), (0.5, 0.0, 1.0)),
        ((0.0, 0.0, 2.0), (1.0, 1.5, 0.7)),
        ((3.0, -1.0, 1.5), (3.2, -0.8, 0.4)),  # contained
        ((0.0, 0.0, 1.0), (3.0, 0.0, 1.0)),  # disjoint
        ((0.0, 0.0, 1.0), (2.0, 0.0, 1.0)),  # tangent
        ((1.0, 1.0, 2.5), (1.0, 1.0, 2.5)),  # identical
    ],
)
def test_circle_iou_matches_a_numeric_reference(a: tuple[float, float, float], b: tuple[float, float, float]) -> None:
    iou = circle_iou([a], [b])[0, 0]
    assert iou == pytest.approx(numeric_iou(a, b), abs=0.01)
    assert circle_iou([b], [a])[0, 0] == pytest.approx(iou, abs=1e-12)


def test_circle_iou_matrix_shape_and_degenerate_circles() -> None:
    iou = circle_iou([(0, 0, 1), (5, 5, 0)], [(0, 0, 1), (0, 0, 0), (10, 0, 2)])
    assert iou.shape == (2, 3)
    assert iou[0, 0] == pytest.approx(1.0)
    assert iou[1, 1] == 0.0  # two zero-radius circles
    assert np.all((iou >= 0) & (iou <= 1))


def test_zone_area() -> None:
    assert Zone(0.0, 0.0, 2.0).area_m2 == pytest.approx(4 * math.pi)


# -- the landing area ------------------------------------------------------------------------------------------
L_SHAPE = [(-15.0, -5.0), (-15.0, 12.0), (-8.0, 12.0), (-8.0, 2.0), (5.0, 2.0), (5.0, -5.0)]  # concave


def test_the_landing_area_mask_is_the_exact_inside_of_a_concave_polygon() -> None:
    from matplotlib.path import Path as PolygonPath

    mask = landing_area_mask(np.asarray(L_SHAPE), GRID)
    n, e = np.meshgrid(GRID.north_centres_m, GRID.east_centres_m, indexing="ij")
    reference = PolygonPath(L_SHAPE).contains_points(np.stack([n.ravel(), e.ravel()], axis=1)).reshape(n.shape)
    assert mask.shape == (GRID.rows, GRID.cols)
    assert np.array_equal(mask.astype(bool), reference)
    assert mask.sum() == pytest.approx((17 * 7 + 13 * 7) / GRID.resolution_m**2, rel=0.01)  # area 210 m^2


def test_zones_lie_inside_the_landing_area_and_its_edge_bounds_them_like_a_person() -> None:
    everything_free = occupancy_with_free_discs([(0.0, 0.0, 100.0)])
    config = ZoneConfig(n_proposals=10, vehicle_radius_m=0.5, margin_m=0.5, landing_area_ne_m=L_SHAPE)
    zones = ZoneFinder(config).find(everything_free)
    assert len(zones) >= 3
    # The biggest zone sits in the L's outer corner, touching its two outer edges and the inner corner (-8, 2):
    # 2 (r - 7)^2 = r^2, so r = 7 / (1 + 1/sqrt 2) = 4.10 m.
    assert zones[0].radius_m == pytest.approx(7.0 / (1.0 + 1.0 / math.sqrt(2.0)), abs=GRID.resolution_m)
    assert zones[0].north_m == pytest.approx(-10.9, abs=0.15)  # r - 15
    assert zones[0].east_m == pytest.approx(-0.9, abs=0.15)  # r - 5
    boundary = PolygonLine(L_SHAPE)
    for zone in zones:
        assert boundary.inside(zone.north_m, zone.east_m)
        assert boundary.distance_m(zone.north_m, zone.east_m) >= zone.radius_m - GRID.resolution_m / 2 - 1e-9
    # Without the area, the same map's biggest zone is bounded only by the grid.
    assert ZoneFinder(ZoneConfig(n_proposals=1)).find(everything_free)[0].radius_m > 10.0


def test_the_geofence_bounds_zones_like_the_landing_area_and_both_apply() -> None:
    everything_free = occupancy_with_free_discs([(0.0, 0.0, 100.0)])
    fence = [(-12.0, -8.0), (-12.0, 12.0), (6.0, 12.0), (6.0, -8.0)]  # 18 m x 20 m inside the 30 m x 40 m grid
    zones = ZoneFinder(ZoneConfig(n_proposals=10), fence_ne_m=fence).find(everything_free)
    assert zones[0].radius_m == pytest.approx(9.0, abs=GRID.resolution_m)  # half the fence's short side
    boundary = PolygonLine(fence)
    for zone in zones:
        assert boundary.inside(zone.north_m, zone.east_m)
        assert boundary.distance_m(zone.north_m, zone.east_m) >= zone.radius_m - GRID.resolution_m / 2 - 1e-9
    # With a landing area as well, a zone lies inside both: the L's corner zone is cut by the fence's south edge.
    both = ZoneConfig(n_proposals=10, vehicle_radius_m=0.5, margin_m=0.5, landing_area_ne_m=L_SHAPE)
    for zone in ZoneFinder(both, fence_ne_m=fence).find(everything_free):
        for edges in (PolygonLine(fence), PolygonLine(L_SHAPE)):
            assert edges.inside(zone.north_m, zone.east_m)
            assert edges.distance_m(zone.north_m, zone.east_m) >= zone.radius_m - GRID.resolution_m / 2 - 1e-9


class PolygonLine:
    """Brute-force reference: point-in-polygon and distance to the polygon's edges."""

    def __init__(self, vertices: list[tuple[float, float]]) -> None:
        self.a = np.asarray(vertices, np.float64)
        self.b = np.roll(self.a, -1, axis=0)

    def distance_m(self, north_m: float, east_m: float) -> float:
        p = np.array([north_m, east_m])
        ab = self.b - self.a
        t = np.clip(np.einsum("ij,ij->i", p - self.a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
        return float(np.min(np.linalg.norm(self.a + t[:, None] * ab - p, axis=1)))

    def inside(self, north_m: float, east_m: float) -> bool:
        from matplotlib.path import Path as PolygonPath

        return bool(PolygonPath(self.a).contains_point((north_m, east_m)))


@pytest.mark.parametrize(
    ("area", "message"),
    [
        ([(0.0, 0.0), (1.0, 1.0)], "at least 3 finite vertices"),
        ([(0.0, 0.0), (0.0, 1.0), (1.0, 0.0)], "encloses 0.50 m^2, less than one zone of the minimum radius"),
    ],
)
def test_a_bad_landing_area_is_named(area: list[tuple[float, float]], message: str) -> None:
    with pytest.raises(ConfigError, match="landing_area_ne_m") as error:
        validate_config(ZoneConfig, {"landing_area_ne_m": area}, prefix="perception.zones")
    assert message in str(error.value)


def test_bounds_masks_kept_per_grid_give_the_same_zones_on_every_grid() -> None:
    """A finder keeps each grid's bounds mask (a hovering vehicle's frames share grids): on grids it has seen, on
    new ones and once older grids were dropped, its zones are those of a finder that sees the grid first."""
    from companion.perception.zones import BOUNDS_MASKS_KEPT

    fence = [(-12.0, -8.0), (-12.0, 12.0), (6.0, 12.0), (6.0, -8.0)]
    config = ZoneConfig(n_proposals=5, vehicle_radius_m=0.5, margin_m=0.5, landing_area_ne_m=L_SHAPE)
    finder = ZoneFinder(config, fence_ne_m=fence)
    rng = np.random.default_rng(7)
    grids = [GridSpec(-20.0 + 0.1 * k, -10.0 - 0.1 * k, 0.1, 300, 400) for k in range(BOUNDS_MASKS_KEPT + 4)]
    for grid in [*grids, grids[0], grids[-1], grids[-1]]:
        free = rng.random((grid.rows, grid.cols)) > 0.002
        occupancy = HeadPlaneOccupancy(grid, free=free, known=np.ones_like(free))
        fresh = ZoneFinder(config, fence_ne_m=fence).find(occupancy)
        assert finder.find(occupancy) == fresh
    assert len(finder._bounds_masks) == BOUNDS_MASKS_KEPT
    assert (finder._bounds_masks.hits, finder._bounds_masks.misses) == (2, len(grids) + 1)  # grids[0] was dropped
