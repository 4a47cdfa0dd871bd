"""A fallback site flown end to end: a ground station uploads a rally point to the SITL with the rally protocol, the
companion downloads it at its start as a fallback site, its search's budget ends, it flies there, checks the site
with its map and lands on it; the flight replays identically. The logic frame by frame is in tests/test_fallback.py;
a 100-mission campaign in docs/results/fallback_crowded.md."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.flightlog.flight_log import FlightLog, RecordKind
from companion.tools.replay import replay
from sitl.campaign.landing_kinds import LandingKind, landing_outcome_of_run
from sitl.testing.helpers import (
    GroundStation,
    fly_to_the_end,
    free_udp_port,
    start_camera_sitl,
    wait_until,
    write_sitl_mission,
)
from tests.test_sitl_gcs import geo, upload

pytestmark = pytest.mark.sitl

SITE_NE_M = (21.0, -4.0)  # north of the crowd's ROI, inside the fence; the park keeps objects off it


def test_when_the_search_time_is_used_up_the_vehicle_lands_at_the_ground_stations_rally_point_after_checking_it(
    tmp_path: Path, instance: int
) -> None:
    gcs_port = free_udp_port()
    clear = {"clear_ne_m": [[*SITE_NE_M, 3.0]]}
    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=gcs_port, lockstep=True, scenario=clear)
    station = GroundStation(instance, gcs_port)
    try:
        wait_until(lambda: station.latest("HEARTBEAT"), 10, "the vehicle's heartbeat")
        lat, lon = geo(*SITE_NE_M)
        rally: list[tuple[int, int, float, float, float, list[float]]] = [
            (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_CMD_NAV_RALLY_POINT, lat, lon, 10.0, [])
        ]
        assert upload(station, rally, mission_type=mavlink.MAV_MISSION_TYPE_RALLY) == mavlink.MAV_MISSION_ACCEPTED
    finally:
        station.close()
    budget = "  mission_time_limit_s: 4.0\n  fallback: {rally_points: true}"
    mission = write_sitl_mission(tmp_path, instance, replayable=True, guidance=budget)
    fly = fly_to_the_end(sitl, mission, tmp_path / "flight")
    assert fly.returncode == 0, fly.stderr[-3000:]
    assert "ended in done (landed)" in fly.stdout
    sites = FlightLog.read(tmp_path / "flight").first(RecordKind.FALLBACK_SITES)
    assert sites is not None
    assert [s["name"] for s in sites["sites"]] == ["rally_1"]
    # The rally point projected from the EKF origin: PX4's sphere against the SITL's WGS-84 radii and 1e-7 degrees
    # of the protocol's integers, a centimetre or two at 21 m.
    rally_ne_m = (sites["sites"][0]["north_m"], sites["sites"][0]["east_m"])
    assert rally_ne_m == pytest.approx(SITE_NE_M, abs=0.1)
    outcome = landing_outcome_of_run(tmp_path / "flight")
    assert outcome.kind is LandingKind.FALLBACK_SITE
    assert outcome.site_ne_m == pytest.approx(rally_ne_m)
    north_m, east_m, _ = fly.truth["position_ned_m"]
    assert math.hypot(north_m - SITE_NE_M[0], east_m - SITE_NE_M[1]) <= 1.5  # down at the site's centre
    report = replay(tmp_path / "flight")
    assert report.identical, report.differences
