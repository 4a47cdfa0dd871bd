"""MAVProxy against `slz sitl`, as a PX4 user would use it: connect, fetch the parameters, list the mission, upload a
two-waypoint mission, fly it in AUTO.MISSION and land."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from sitl.geodesy import ned_to_geodetic
from sitl.harness.process import SitlProcess
from sitl.testing.helpers import free_udp_port, wait_until
from tests.mavproxy_client import MavProxy

pytestmark = pytest.mark.sitl
pytest.importorskip("MAVProxy", reason="MAVProxy comes with the `dev` extra")

ORIGIN = (47.397742, 8.545594, 488.0)
PARAM_FETCH_LIMIT_S = 2.0
CONNECT_FETCH_LIMIT_S = 4.0


def qgc_wpl(items: list[tuple[int, int, float, float, float, float]]) -> str:
    """A mission file in the QGC WPL 110 format MAVProxy's `wp load` reads: index, current, frame, command, p1-p4,
    latitude, longitude, altitude, autocontinue (tab separated)."""
    lines = ["QGC WPL 110"]
    for i, (frame, command, p1, lat, lon, alt) in enumerate(items):
        fields = [i, 0, frame, command, p1, 0, 0, "nan", f"{lat:.8f}", f"{lon:.8f}", f"{alt:.3f}", 1]
        lines.append("\t".join(str(f) for f in fields))
    return "\n".join(lines) + "\n"


def test_mavproxy_fetches_parameters_lists_uploads_and_flies_a_mission(tmp_path: Path, instance: int) -> None:
    gcs_port = free_udp_port()
    config = tmp_path / "sitl.yaml"
    config.write_text(f"sitl:\n  gcs_port_remote: {gcs_port}\n")
    (wp_a_lat, wp_a_lon, _), (wp_b_lat, wp_b_lon, _) = (
        ned_to_geodetic(n, e, 0, *ORIGIN) for n, e in ((10, 0), (10, 6))
    )
    mission = tmp_path / "two-waypoints.txt"
    mission.write_text(
        qgc_wpl(
            [
                (3, 22, 0, 0.0, 0.0, 5.0),  # takeoff to 5 m where it is
                (3, 16, 0, wp_a_lat, wp_a_lon, 5.0),
                (3, 16, 0, wp_b_lat, wp_b_lon, 5.0),
                (3, 21, 0, wp_b_lat, wp_b_lon, 0.0),  # land at the second waypoint
            ]
        )
    )
    with (
        SitlProcess(["--config", str(config), "--speed", "2"], instance, tmp_path) as sitl,
        MavProxy(gcs_port, tmp_path) as mavproxy,
    ):
        detected, _ = mavproxy.expect(rf"Detected vehicle {sitl.instance + 1}:1", 20)
        # On connect MAVProxy fetches the parameters, over MAVLink FTP first: the NAK sends it to the list within
        # its next one-second check, where an unanswered FTP request costs it its 7 s timeout.
        fetched, _ = mavproxy.expect(r"Received \d+ parameters", 20)
        assert fetched - detected < CONNECT_FETCH_LIMIT_S
        # `wp list` is answered (an empty mission).
        mavproxy.send("wp list")
        mavproxy.expect(r"Requesting 0 waypoints", 5)
        # Upload, and read back.
        mavproxy.send(f"wp load {mission}")
        mavproxy.expect(r"Sent all 4 waypoints", 10)
        mavproxy.expect(r"Got MISSION_ACK: TYPE_MISSION: ACCEPTED", 5)
        mavproxy.send("wp list")
        mavproxy.expect(r"Requesting 4 waypoints", 5)
        for command in (22, 16, 16, 21):  # each item printed back: command, frame, latitude...
            mavproxy.expect(rf"(^|> ){command} \d+ \d+\.\d+ ", 5)
        # MAVProxy 1.8's `mode MISSION` cannot encode a PX4 mode (it hands pymavlink a tuple); PX4 users send the
        # command itself: DO_SET_MODE with the custom-mode flag, main mode AUTO (4), sub-mode MISSION (4).
        mavproxy.send("long DO_SET_MODE 1 4 4")
        wait_until(lambda: sitl.state()["mode"] == "AUTO.MISSION", 10, "AUTO.MISSION")
        mavproxy.send("arm throttle")
        wait_until(lambda: sitl.state()["landed_state"] == "IN_AIR", 20, "the takeoff")
        track: list[list[float]] = []

        def landed() -> bool:
            state = sitl.state()
            track.append(state["position_ned_m"])
            return not state["armed"] and state["landed_state"] == "ON_GROUND"

        wait_until(landed, 90, "the mission flown, landed and disarmed")
        # `param fetch` after the flight (pymavlink sends a list request at most every 2 s, and MAVProxy sent one on
        # connect); MAVProxy knows from the NAK that FTP is not served, so this is the list alone.
        sent = mavproxy.send("param fetch")
        received, match = mavproxy.expect(r"Received (\d+) parameters( \(ftp\))?", 10)
        assert received - sent < PARAM_FETCH_LIMIT_S
        assert int(match.group(1)) >= 150
        assert match.group(2) is None
        mavproxy.send("param show SYS_AUTOSTART")
        mavproxy.expect(r"SYS_AUTOSTART\s+4001", 5)
        printed = [line for _, line in mavproxy.lines]
    # SYS_STATUS's geofence bits as PX4 sends them: present and healthy, so MAVProxy never reports a breach.
    assert not [line for line in printed if "fence breach" in line]
    assert any("fence present" in line for line in printed)
    north, east, _ = track[-1]
    assert math.hypot(north - 10.0, east - 6.0) < 1.0  # on the land item's point
    assert any(math.hypot(n - 10.0, e) < 2.0 and -d > 4.0 for n, e, d in track)  # through the first waypoint
    assert max(-d for _, _, d in track) == pytest.approx(5.0, abs=0.8)
