"""Kalman zone tracking: identities, misses, capacity, time handling."""

from __future__ import annotations

import numpy as np
import pytest

from companion.perception.config import TrackingConfig
from companion.perception.errors import PerceptionError
from companion.perception.kalman import KalmanFilter
from companion.perception.tracking import ZoneTracker
from companion.perception.zones import Zone

pytestmark = pytest.mark.unit

DT_S = 0.1


def test_track_keeps_its_id_through_a_moving_zone_and_learns_its_velocity() -> None:
    tracker = ZoneTracker(TrackingConfig(iou_threshold=0.3, max_misses=3))
    v_north_mps, v_east_mps = 0.8, -0.5
    for k in range(60):
        t_s = k * DT_S
        tracks = tracker.update(t_s, [Zone(v_north_mps * t_s, 10.0 + v_east_mps * t_s, 2.0)])
        assert [t.track_id for t in tracks] == [1]
    track = tracks[0]
    assert track.hits == 60
    assert track.misses == 0
    assert track.v_north_mps == pytest.approx(v_north_mps, abs=0.05)
    assert track.v_east_mps == pytest.approx(v_east_mps, abs=0.05)
    assert track.north_m == pytest.approx(v_north_mps * 5.9, abs=0.05)
    assert track.age_s == pytest.approx(5.9)


def test_vanished_zone_is_dropped_after_mu_1_misses_while_others_live() -> None:
    mu_1 = 4
    tracker = ZoneTracker(TrackingConfig(max_misses=mu_1))
    stay, vanish = Zone(0.0, 0.0, 2.0), Zone(20.0, 20.0, 3.0)
    tracks = tracker.update(0.0, [stay, vanish])
    ids = {round(t.north_m): t.track_id for t in tracks}
    for k in range(1, mu_1):
        tracks = tracker.update(k * DT_S, [stay])
        assert {t.track_id for t in tracks} == {ids[0], ids[20]}
        assert next(t for t in tracks if t.track_id == ids[20]).misses == k
    tracks = tracker.update(mu_1 * DT_S, [stay])
    assert [t.track_id for t in tracks] == [ids[0]]


def test_frames_without_zones_predict_only_and_count_misses() -> None:
    tracker = ZoneTracker(TrackingConfig(max_misses=3))
    for k in range(10):
        tracker.update(k * DT_S, [Zone(k * DT_S * 1.0, 0.0, 2.0)])  # 1 m/s north
    coasting = tracker.update(1.0, [])
    assert coasting[0].misses == 1
    assert coasting[0].north_m == pytest.approx(1.0, abs=0.1)  # kept moving with its velocity
    tracker.update(1.1, [])
    assert tracker.update(1.2, []) == []


def test_predict_without_observation_counts_no_miss() -> None:
    tracker = ZoneTracker(TrackingConfig(max_misses=1))
    tracker.update(0.0, [Zone(0.0, 0.0, 2.0)])
    for k in range(1, 5):
        tracks = tracker.predict(k * DT_S)
        assert len(tracks) == 1
        assert tracks[0].misses == 0


def test_capacity_m_p_keeps_the_largest_new_zones() -> None:
    tracker = ZoneTracker(TrackingConfig(max_tracks=2))
    tracks = tracker.update(0.0, [Zone(0, 0, 1.0), Zone(10, 0, 3.0), Zone(20, 0, 2.0)])
    assert sorted(round(t.radius_m) for t in tracks) == [2, 3]


def test_low_iou_starts_a_new_track_instead_of_jumping() -> None:
    tracker = ZoneTracker(TrackingConfig(iou_threshold=0.5, max_misses=2))
    tracker.update(0.0, [Zone(0.0, 0.0, 2.0)])
    tracks = tracker.update(0.1, [Zone(3.5, 0.0, 2.0)])  # IoU of the two discs is ~0.07
    assert sorted(t.track_id for t in tracks) == [1, 2]
    assert next(t for t in tracks if t.track_id == 1).misses == 1


def test_hungarian_assignment_pairs_by_overlap() -> None:
    tracker = ZoneTracker(TrackingConfig())
    first = tracker.update(0.0, [Zone(0.0, 0.0, 2.0), Zone(0.0, 3.0, 2.0)])
    id_at = {round(t.east_m): t.track_id for t in first}
    # Both move 0.5 m east: greedy matching by index would still work; swap the order to be sure.
    second = tracker.update(0.1, [Zone(0.0, 3.5, 2.0), Zone(0.0, 0.5, 2.0)])
    for t in second:
        assert t.track_id == id_at[0 if t.east_m < 2 else 3]
        assert t.hits == 2


def test_time_must_not_go_backwards() -> None:
    tracker = ZoneTracker(TrackingConfig())
    tracker.update(1.0, [Zone(0, 0, 2)])
    with pytest.raises(PerceptionError, match="time went backwards"):
        tracker.update(0.9, [Zone(0, 0, 2)])
    with pytest.raises(PerceptionError, match="finite"):
        tracker.update(float("nan"), [])


def test_radius_never_negative() -> None:
    tracker = ZoneTracker(TrackingConfig(max_misses=100))
    for k in range(10):
        tracker.update(k * DT_S, [Zone(0.0, 0.0, 2.0 - 0.2 * k)])  # shrinking at 2 m/s
    for k in range(10, 40):
        tracks = tracker.update(k * DT_S, [])
        assert tracks[0].radius_m >= 0.0


def test_reset_forgets_tracks_but_ids_stay_unique() -> None:
    tracker = ZoneTracker(TrackingConfig())
    tracker.update(0.0, [Zone(0, 0, 2)])
    tracker.reset()
    tracks = tracker.update(0.0, [Zone(0, 0, 2)])
    assert [t.track_id for t in tracks] == [2]


def test_the_kalman_filter_matches_filterpy_bit_for_bit() -> None:
    filterpy_kalman = pytest.importorskip("filterpy.kalman")  # the dev extra: the reference, never on the drone
    rng = np.random.default_rng(7)
    x0 = np.array([3.0, -2.0, 4.0, 0.0, 0.0, 0.0])
    P0 = np.diag([0.25, 0.25, 0.09, 1.0, 1.0, 1.0])
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    R = np.diag([0.25, 0.25, 0.09])
    ours = KalmanFilter(x=x0, P=P0, H=H, R=R)
    reference = filterpy_kalman.KalmanFilter(dim_x=6, dim_z=3)
    reference.x, reference.P, reference.H, reference.R = x0.copy(), P0.copy(), H, R
    for _ in range(200):
        dt_s = float(rng.uniform(0.05, 0.3))
        F = np.block([[np.eye(3), dt_s * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
        I3 = np.eye(3)
        Q = 0.3 * np.block([[dt_s**4 / 4 * I3, dt_s**3 / 2 * I3], [dt_s**3 / 2 * I3, dt_s**2 * I3]])
        ours.predict(F, Q)
        reference.predict(F=F, Q=Q)
        if rng.random() < 0.8:  # a missed frame now and then: predict only
            z = rng.normal(size=3) * 3.0
            ours.update(z)
            reference.update(z)
        assert np.array_equal(ours.x, reference.x)
        assert np.array_equal(ours.P, reference.P)
    assert not np.allclose(ours.P, P0)  # it did filter


def test_the_kalman_filter_names_shapes_that_do_not_fit() -> None:
    with pytest.raises(ValueError, match="shapes do not fit"):
        KalmanFilter(x=np.zeros(6), P=np.eye(5), H=np.zeros((3, 6)), R=np.eye(3))
