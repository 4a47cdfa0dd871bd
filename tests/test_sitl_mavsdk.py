"""The SITL vehicle against real clients: MAVSDK in its own process on 14540, a pymavlink ground station on 14550.

Flight scripts with explicit tolerances and deadlines; ground truth read from the SITL's control channel and its
trajectory log (simulated time).
"""

from __future__ import annotations

import csv
import itertools
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from sitl.autopilot.modes import FlightMode
from sitl.harness.process import SitlProcess
from sitl.testing.helpers import GroundStation, free_udp_port, state_when, wait_until
from sitl.testing.mavsdk_client import Client

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def sitl_factory(tmp_path: Path, instances: Callable[[], int]) -> Iterator[Callable[..., SitlProcess]]:
    """Start a SITL on a leased instance; with ``gcs_port`` its ground-station link sends there (not to 14550,
    which every instance on the machine shares)."""
    started: list[SitlProcess] = []

    def start(*args: str, gcs_port: int | None = None) -> SitlProcess:
        instance = instances()
        if gcs_port is not None:
            config = tmp_path / f"sitl-{instance}.yaml"
            config.write_text(f"sitl:\n  gcs_port_remote: {gcs_port}\n")
            args = ("--config", str(config), *args)
        sitl = SitlProcess(list(args), instance, tmp_path).start()
        started.append(sitl)
        return sitl

    yield start
    for sitl in started:
        sitl.stop()


@pytest.mark.slow  # 40 s at real speed; the companion's own MAVSDK flight is tests/test_vehicle_link.py
def test_mavsdk_flies_an_offboard_square_while_a_ground_station_watches(
    sitl_factory: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    log = tmp_path / "square.csv"
    gcs_port = free_udp_port()
    sitl = sitl_factory("--speed", "1", "--log", str(log), gcs_port=gcs_port)
    gcs = GroundStation(sitl.instance, gcs_port)
    modes_seen: set[str] = set()

    def watch() -> None:
        for msg in gcs.poll():
            if msg.get_type() == "HEARTBEAT" and msg.get_srcSystem() == sitl.instance + 1:
                mode = FlightMode.from_custom_mode(msg.custom_mode)
                armed = bool(msg.base_mode & 128)
                modes_seen.add(f"{mode.px4_name if mode else msg.custom_mode}{'+armed' if armed else ''}")

    client = Client("square", sitl.instance)
    try:
        client.expect("connected", 20, watch)
        client.expect("healthy", 20, watch)
        client.expect("armed", 10, watch)
        client.expect("took_off", 30, watch)
        client.expect("offboard", 10, watch)
        corners = [client.expect("corner_held", 40, watch) for _ in range(4)]
        assert all(c["worst_error_m"] <= 0.3 for c in corners)
        client.expect("on_ground", 60, watch)
        client.expect("disarmed", 20, watch)
        client.expect("done", 10, watch)
    finally:
        client.kill()
    # The ground station saw the same vehicle (sysid = instance + 1) through the flight, on its own link.
    assert {"AUTO.TAKEOFF+armed", "OFFBOARD+armed", "AUTO.LAND+armed", "AUTO.LAND"} <= modes_seen
    gcs.send(gcs.mav.param_request_read_encode(sitl.instance + 1, 1, b"MIS_TAKEOFF_ALT", -1))
    value = wait_until(lambda: gcs.latest("PARAM_VALUE"), 3.0, "PARAM_VALUE on the GCS link")
    assert value.param_value == pytest.approx(5.0)  # set by MAVSDK on the other link
    gcs.close()
    state = sitl.state()
    assert state["links"]["gcs"]["received"] >= 1
    assert state["links"]["api"]["received"] > 50

    # Ground truth in simulated time: each corner was held within 0.3 m for 2 s.
    assert sitl.stop() == 0
    rows = list(csv.DictReader(log.open()))
    t = np.array([float(r["t_s"]) for r in rows])
    pos = np.array([[float(r["north_m"]), float(r["east_m"]), float(r["down_m"])] for r in rows])
    for corner in ([6, 0], [6, 6], [0, 6], [0, 0]):
        inside = np.linalg.norm(pos - [*corner, -5.0], axis=1) <= 0.3
        longest, start = 0.0, None
        for ti, ok in zip(t, inside, strict=True):
            if ok and start is None:
                start = ti
            if not ok:
                start = None
            if start is not None:
                longest = max(longest, ti - start)
        assert longest >= 2.0, f"corner {corner} held only {longest:.2f} s"
    assert rows[-1]["armed"] == "0"
    assert rows[-1]["landed_state"] == "ON_GROUND"


def test_offboard_loss_failsafe_fires_after_com_of_loss_t_when_the_client_dies(
    sitl_factory: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    ulog, csv_log = tmp_path / "flight.ulg", tmp_path / "flight.csv"
    sitl = sitl_factory("--speed", "1", "--ulog", str(ulog), "--log", str(csv_log))
    client = Client("hover", sitl.instance)
    try:
        client.expect("offboard", 60)
        wait_until(lambda: sitl.state()["mode"] == "OFFBOARD", 5, "OFFBOARD")
    finally:
        client.kill()
    killed_at_s = sitl.state()["t_s"]
    state = state_when(sitl, lambda s: bool(s["failsafe"]), 5.0, "the offboard-loss failsafe")
    assert state["failsafe"] == "Offboard lost"
    # PX4 v1.15's default, COM_OBL_RC_ACT = 0, with the RC there: position mode, the pilot's vehicle.
    assert state["mode"] == "POSCTL"
    # COM_OF_LOSS_T = 1 s after the last setpoint (sent at most ~0.1 s before the kill).
    assert 0.85 <= state["failsafe_since_s"] - killed_at_s <= 1.3
    # On centred sticks it hovers where it was: no landing in place.
    later = state_when(sitl, lambda s: s["t_s"] >= state["t_s"] + 5.0, 15, "five seconds of the failsafe")
    assert later["mode"] == "POSCTL"
    assert later["armed"]
    assert later["landed_state"] == "IN_AIR"
    moved_m = np.subtract(later["position_ned_m"], state["position_ned_m"])
    assert np.hypot(moved_m[0], moved_m[1]) < 1.0
    assert abs(moved_m[2]) < 0.5
    sitl.stop()
    # Issue 67: the SITL wrote the flight as PX4's SITL does, a ULog pyulog reads, whose modes and failsafe are the
    # SITL's own log's on the same clock.
    from pyulog import ULog

    flight = ULog(str(ulog))
    assert flight.msg_info_dict["ver_sw_release"] == "v1.15.0"
    assert flight.initial_parameters["COM_OBL_RC_ACT"] == 0
    status = flight.get_dataset("vehicle_status").data
    t_us, nav_state = status["timestamp"], status["nav_state"]
    changes = [int(nav_state[0])] + [int(b) for a, b in itertools.pairwise(nav_state) if a != b]
    assert changes[-2:] == [14, 2]  # OFFBOARD, then position mode: the failsafe
    switched_s = t_us[list(nav_state).index(2)] / 1e6
    assert abs(switched_s - state["failsafe_since_s"]) <= 0.05  # the sample after the switch (50 Hz)
    assert bool(status["failsafe"][-1])
    assert any("Failsafe: Offboard lost, position" in m.message for m in flight.logged_messages)
    commands = flight.get_dataset("vehicle_command_ack").data
    assert 400 in set(commands["command"].tolist())  # MAV_CMD_COMPONENT_ARM_DISARM, taken
    # The trajectory CSV's modes at the same instants.
    rows = list(csv.DictReader(csv_log.open()))
    first_posctl_s = next(float(r["t_s"]) for r in rows if r["mode"] == "POSCTL")
    assert abs(first_posctl_s - switched_s) <= 0.05
    position = flight.get_dataset("vehicle_local_position").data
    last_csv = rows[-1]
    assert position["z"][-1] == pytest.approx(float(last_csv["down_m"]), abs=0.05)


def test_pilot_takeover_leaves_offboard_and_the_vehicle_obeys_the_pilot(
    sitl_factory: Callable[..., SitlProcess],
) -> None:
    sitl = sitl_factory("--speed", "1")
    client = Client("push_north", sitl.instance)
    try:
        client.expect("offboard", 60)
        wait_until(lambda: sitl.state()["position_ned_m"][0] > 1.0, 10, "the client pushing north")
        reply = sitl.request({"cmd": "pilot_mode", "mode": "POSCTL"})
        assert reply["result"] == 0
        assert sitl.state()["mode"] == "POSCTL"
        # The pilot's sticks are centred: the vehicle brakes and holds, ignoring the setpoints that keep coming.
        stopped = state_when(sitl, lambda s: bool(np.linalg.norm(s["velocity_ned_mps"]) < 0.2), 10, "braking")
        setpoints_before = sum(stopped["setpoints_by_sender"].values())
        t0 = stopped["t_s"]
        later = state_when(sitl, lambda s: s["t_s"] >= t0 + 2.0, 5, "2 s of hold")
        assert np.linalg.norm(np.subtract(later["position_ned_m"][:2], stopped["position_ned_m"][:2])) < 0.3
        assert later["position_ned_m"][0] < 7.0  # never reached the client's 8 m
        assert sum(later["setpoints_by_sender"].values()) >= setpoints_before + 20  # still streaming
        assert later["mode"] == "POSCTL"
        # The pilot pushes the stick east: the vehicle goes east.
        sitl.request({"cmd": "pilot_sticks", "east": 0.4})
        east0 = later["position_ned_m"][1]
        wait_until(lambda: sitl.state()["position_ned_m"][1] > east0 + 2.0, 8, "moving east under the pilot")
    finally:
        client.kill()


@pytest.mark.parametrize(("speed", "max_sim_s"), [("0.05", 0.5), ("0", None)])
def test_heartbeats_follow_the_wall_clock_at_any_speed(
    sitl_factory: Callable[..., SitlProcess], speed: str, max_sim_s: float | None
) -> None:
    gcs_port = free_udp_port()
    sitl = sitl_factory("--speed", speed, gcs_port=gcs_port)
    gcs = GroundStation(sitl.instance, gcs_port)
    try:
        t0_sim = sitl.state()["t_s"]
        start = time.monotonic()
        wait_until(lambda: gcs.poll() is not None and time.monotonic() - start >= 3.2, 5, "3.2 s of wall time")
        beats = [t for t in gcs.heartbeat_wall_times if t >= start]
        assert 3 <= len(beats) <= 5  # 1 Hz of wall time, whatever the simulation speed
        elapsed_sim = sitl.state()["t_s"] - t0_sim
        if max_sim_s is not None:
            assert elapsed_sim <= max_sim_s
        else:
            assert elapsed_sim > 3.2  # faster than real time
    finally:
        gcs.close()
