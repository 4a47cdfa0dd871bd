"""Target selection policies."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from companion.perception.config import SelectionConfig, SelectionPolicyName
from companion.perception.selection import (
    BiggestPolicy,
    NearestPolicy,
    OldestPolicy,
    RandomPolicy,
    SelectionContext,
    make_policy,
)
from companion.perception.tracking import TrackedZone

pytestmark = pytest.mark.unit


def track(track_id: int, north_m: float, east_m: float, radius_m: float, created_s: float) -> TrackedZone:
    return TrackedZone(track_id, north_m, east_m, radius_m, 0, 0, 0, created_s, 5.0, 5.0 - created_s, 3, 0)


TRACKS = [
    track(3, 10.0, 0.0, 4.0, created_s=2.0),  # biggest
    track(5, 1.0, 1.0, 1.5, created_s=3.0),  # nearest to the vehicle at the origin
    track(1, -6.0, 2.0, 2.0, created_s=0.5),  # oldest
]
CONTEXT = SelectionContext(t_s=5.0, vehicle_north_m=0.0, vehicle_east_m=0.0)


@pytest.mark.parametrize(
    ("policy", "expected_id"),
    [(BiggestPolicy(), 3), (OldestPolicy(), 1), (NearestPolicy(), 5)],
)
def test_policies_choose_their_zone(policy: BiggestPolicy | OldestPolicy | NearestPolicy, expected_id: int) -> None:
    target = policy.select(TRACKS, CONTEXT)
    assert target is not None
    assert target.track_id == expected_id
    chosen = next(t for t in TRACKS if t.track_id == expected_id)
    assert (target.north_m, target.east_m, target.radius_m) == (
        chosen.north_m,
        chosen.east_m,
        chosen.radius_m,
    )


@pytest.mark.parametrize("policy", [BiggestPolicy(), OldestPolicy(), NearestPolicy()])
def test_no_tracks_no_target(policy: BiggestPolicy | OldestPolicy | NearestPolicy) -> None:
    assert policy.select([], CONTEXT) is None


def test_ties_are_broken_by_track_id() -> None:
    tied = [track(9, 0, 0, 2.0, 1.0), track(4, 5, 5, 2.0, 1.0)]
    assert BiggestPolicy().select(tied, CONTEXT).track_id == 4  # type: ignore[union-attr]
    assert OldestPolicy().select(tied, CONTEXT).track_id == 4  # type: ignore[union-attr]


def test_random_policy_is_blind_seeded_and_sticky() -> None:
    context = SelectionContext(0.0, 100.0, 100.0, area_centre_ne_m=(0.0, 0.0))
    a, b = RandomPolicy(seed=42, half_extent_m=15.0), RandomPolicy(seed=42, half_extent_m=15.0)
    first = a.select(TRACKS, context)
    assert first is not None
    assert first.track_id is None
    assert abs(first.north_m) <= 15.0
    assert abs(first.east_m) <= 15.0
    assert a.select([], context) == first  # committed, whatever the perception says
    assert b.select([], context) == first  # same seed, same point
    a.reset()
    assert a.select(TRACKS, context) == first
    other = RandomPolicy(seed=43, half_extent_m=15.0).select(TRACKS, context)
    assert other != first


def test_random_points_cover_the_square_uniformly() -> None:
    context = SelectionContext(0.0, 0.0, 0.0)
    points = []
    for seed in range(2000):
        target = RandomPolicy(seed=seed, half_extent_m=15.0).select([], context)
        assert target is not None
        points.append((target.north_m, target.east_m))
    uniform = stats.uniform(loc=-15.0, scale=30.0)
    for axis in (0, 1):
        assert stats.kstest([p[axis] for p in points], uniform.cdf).pvalue > 0.001


def test_with_a_landing_area_random_points_fall_uniformly_inside_it_wherever_the_vehicle_is() -> None:
    # An L-shaped area (concave), the vehicle far outside it: every point inside; both arms hit in proportion.
    area = [(0.0, 0.0), (0.0, 20.0), (5.0, 20.0), (5.0, 5.0), (20.0, 5.0), (20.0, 0.0)]  # 100 + 75 m^2
    context = SelectionContext(0.0, 100.0, -100.0)
    points = np.array(
        [
            (t.north_m, t.east_m)
            for seed in range(2000)
            if (t := RandomPolicy(seed=seed, half_extent_m=15.0, landing_area_ne_m=area).select([], context))
        ]
    )
    assert len(points) == 2000
    in_east_arm = (points[:, 0] <= 5.0) & (points[:, 1] >= 0.0) & (points[:, 1] <= 20.0)
    in_north_arm = (points[:, 0] > 5.0) & (points[:, 0] <= 20.0) & (points[:, 1] >= 0.0) & (points[:, 1] <= 5.0)
    assert (in_east_arm | in_north_arm).all()
    assert stats.binomtest(int(in_east_arm.sum()), 2000, 100.0 / 175.0).pvalue > 0.001
    assert make_policy(SelectionConfig(policy=SelectionPolicyName.RANDOM, seed=3), area).select([], context) == (
        RandomPolicy(seed=3, half_extent_m=15.0, landing_area_ne_m=area).select([], context)
    )


@pytest.mark.parametrize("name", list(SelectionPolicyName))
def test_make_policy_builds_every_named_policy(name: SelectionPolicyName) -> None:
    assert make_policy(SelectionConfig(policy=name)).name == name.value
