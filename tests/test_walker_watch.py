"""The walker gate's watch (companion/guidance/walker_watch.py): who walks towards the landing point, from maps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.guidance.walker_watch import WalkerWatch, WalkerWatchConfig, sector_distances_m, theil_sen_slope
from companion.perception.projection import GridSpec, HeadPlaneOccupancy

pytestmark = pytest.mark.unit

GRID = GridSpec(north_min_m=-10.0, east_min_m=-10.0, resolution_m=0.1, rows=200, cols=200)
FOOTPRINT_M = 1.0
FRAME_S = 0.1  # 10 frames a second, as the SITL's camera


def people_map(people_ne_m: list[tuple[float, float]], body_m: float = 0.3) -> HeadPlaneOccupancy:
    """Everything seen and free except a disc of ``body_m`` around each person."""
    nn, ee = np.meshgrid(GRID.north_centres_m, GRID.east_centres_m, indexing="ij")
    free = np.ones((GRID.rows, GRID.cols), bool)
    for n, e in people_ne_m:
        free &= np.hypot(nn - n, ee - e) > body_m
    return HeadPlaneOccupancy(GRID, free, np.ones_like(free))


def test_each_direction_gets_its_nearest_occupied_cell() -> None:
    def at(bearing_deg: float, range_m: float) -> tuple[float, float]:
        return range_m * math.cos(math.radians(bearing_deg)), range_m * math.sin(math.radians(bearing_deg))

    # Sectors of 45 degrees clockwise from north: people in the middle of sector 0 (two) and of sector 5.
    people = [at(22.5, 3.0), at(22.5, 5.0), at(247.5, 2.0)]
    d = sector_distances_m(people_map(people), 0.0, 0.0, radius_m=8.0, sectors=8)
    assert d[0] == pytest.approx(2.7, abs=0.08)  # the nearer of the two, to its body's edge
    assert d[5] == pytest.approx(1.7, abs=0.08)
    assert np.isinf(np.delete(d, [0, 5])).all()
    assert np.isinf(sector_distances_m(people_map([(9.0, 0.0)]), 0.0, 0.0, radius_m=8.0, sectors=8)).all()


def test_the_theil_sen_slope_shrugs_off_one_outlier() -> None:
    times = [0.1 * k for k in range(20)]
    values = [2.0 - 0.5 * t for t in times]
    values[7] = -5.0  # a false positive near the point for one frame
    assert theil_sen_slope(times, values) == pytest.approx(-0.5, abs=0.05)
    assert math.isnan(theil_sen_slope([1.0], [1.0]))


def watch_until_ready(watch: WalkerWatch, maps: list[HeadPlaneOccupancy]) -> int | None:
    """Feed the maps one frame apart; the frame the descent may go on at (None: never)."""
    for k, head_plane in enumerate(maps):
        t = k * FRAME_S
        if watch.ready(watch.observe(head_plane, 0.0, 0.0, t), t):
            return k
    return None


def test_people_standing_around_the_point_do_not_hold_the_descent() -> None:
    rng = np.random.default_rng(3)
    standing = [(2.0, 0.5), (-1.8, -1.2), (0.3, 2.4)]
    maps = [people_map([(n + rng.normal(0, 0.05), e + rng.normal(0, 0.05)) for n, e in standing]) for _ in range(60)]
    watch = WalkerWatch(WalkerWatchConfig(), FOOTPRINT_M)
    ready_at = watch_until_ready(watch, maps)
    assert ready_at is not None
    assert ready_at * FRAME_S == pytest.approx(WalkerWatchConfig().window_s, abs=FRAME_S + 1e-9)  # a look, no more
    assert watch.waits == 0


def test_a_false_positive_that_flickers_near_the_point_does_not_hold_the_descent() -> None:
    maps = [people_map([(2.5, 0.0)] + ([(1.4, 0.2)] if k % 5 == 2 else [])) for k in range(60)]
    watch = WalkerWatch(WalkerWatchConfig(), FOOTPRINT_M)
    assert watch_until_ready(watch, maps) is not None
    assert watch.waits == 0


def test_someone_walking_in_holds_the_descent_until_they_have_gone_by() -> None:
    # A walker at 1.2 m/s on a line that passes 0.6 m from the point: from 4 m south-west, past it, on north-east.
    speed = 1.2
    start, heading = np.array([-3.0, -2.6]), np.array([1.0, 1.0]) / math.sqrt(2.0)
    maps = [people_map([tuple(start + heading * speed * k * FRAME_S)]) for k in range(120)]
    watch = WalkerWatch(WalkerWatchConfig(), FOOTPRINT_M)
    ready_at = watch_until_ready(watch, maps)
    assert watch.waits == 1
    assert ready_at is not None
    walker = start + heading * speed * ready_at * FRAME_S
    closest_k = int(np.argmin([np.hypot(*(start + heading * speed * k * FRAME_S)) for k in range(120)]))
    assert ready_at > closest_k  # not before the walker has passed the point
    assert float(np.dot(walker, heading)) > 0.0  # ... and is walking away from it


def test_someone_who_keeps_coming_makes_the_wait_too_long() -> None:
    config = WalkerWatchConfig(max_wait_s=2.0)
    watch = WalkerWatch(config, FOOTPRINT_M)
    t = 0.0
    for k in range(40):  # from 6 m north, slowly (0.4 m/s), straight at the point
        t = k * FRAME_S
        approach = watch.observe(people_map([(4.0 - 0.6 * t, 0.0)]), 0.0, 0.0, t)
        assert not watch.ready(approach, t)
    assert watch.waited_too_long(t)
    watch.reset()
    assert not watch.waited_too_long(t)
    assert not watch.passed


def wanderer_north_m() -> list[float]:
    """Issue 63's `moving_10/oldest/0027`, frame by frame: a walker 2.8 m north of the point closes at 0.55 m/s for
    2 s, turns back a little for 0.5 s (the fit's closing speed dips below ``min_closing_mps``), then walks on in."""
    north_m, out = 2.8, []
    for k in range(60):
        north_m += (0.6 if 2.0 <= k * FRAME_S < 2.5 else -0.55) * FRAME_S
        out.append(north_m)
    return out


def test_a_walker_who_wanders_is_watched_until_no_fit_has_seen_them_coming_for_a_while() -> None:
    north_m = wanderer_north_m()
    maps = [people_map([(n, 0.0)]) for n in north_m]
    before = watch_until_ready(WalkerWatch(WalkerWatchConfig(clear_after_walker_s=0.0), FOOTPRINT_M), maps)
    assert before is not None
    assert 2.0 <= before * FRAME_S < 3.0  # the dip's three maps were a look before issue 63 ...
    at_touchdown_m = north_m[before] - 0.3 - 0.55 * WalkerWatchConfig().blind_descent_s  # body edge, walking on in
    assert at_touchdown_m < FOOTPRINT_M  # ... and the walker would have reached the footprint by touchdown
    watch = WalkerWatch(WalkerWatchConfig(), FOOTPRINT_M)
    assert watch_until_ready(watch, maps) is None  # now the dip is no look: the walker comes on and is seen coming
    assert watch.waits == 1
