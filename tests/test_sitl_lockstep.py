"""Lockstep and determinism: one seed and the same inputs give the same flight at any simulation speed."""

from __future__ import annotations

import json
import math
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl.config import SitlConfig
from sitl.harness.process import SitlProcess
from sitl.testing.helpers import LockstepClient, position_setpoint, wait_until

pytestmark = pytest.mark.sitl

DURATION_S = 12.0


def corner_at(t_s: float) -> tuple[float, float, float]:
    """The scripted offboard path: climb, two legs of a square, back."""
    if t_s < 4.0:
        return 0.0, 0.0, -4.0
    if t_s < 7.0:
        return 4.0, 0.0, -4.0
    if t_s < 10.0:
        return 4.0, 4.0, -4.0
    return 0.0, 0.0, -4.0


def fly_in_lockstep(
    tmp_path: Path, instance: int, speed: str, dynamics: str = "rigid_body"
) -> tuple[str, list[tuple[Any, ...]], float]:
    """Fly the script; returns the truth log, the LOCAL_POSITION_NED sequence the client saw, and the wall time."""
    config = tmp_path / f"sitl-{instance}.yaml"
    config.write_text("sitl:\n  position_noise_m: 0.05\n  seed: 42\n")
    log = tmp_path / f"trajectory-{instance}.csv"
    args = ["--config", str(config), "--lockstep", "--speed", speed, "--log", str(log), "--duration", str(DURATION_S)]
    args += ["--dynamics", dynamics]
    sitl = SitlProcess(args, instance, tmp_path).start()
    client = LockstepClient(instance)
    try:
        client.subscribe()
        sysid = client.peer.vehicle_sysid
        start = time.monotonic()
        while True:
            tick = client.next_tick()
            t_s = tick["t_s"]
            client.peer.send(position_setpoint(client.peer.mav, *corner_at(t_s), target_system=sysid))
            if tick["seq"] == 1:
                client.peer.send(
                    client.peer.mav.command_long_encode(
                        sysid,
                        1,
                        mavlink.MAV_CMD_DO_SET_MODE,
                        0,
                        mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                        6,
                        0,
                        0,
                        0,
                        0,
                        0,
                    )
                )
            if tick["seq"] == 2:
                client.peer.send(
                    client.peer.mav.command_long_encode(
                        sysid, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
                    )
                )
            client.peer.poll()
            client.ack(tick["seq"])
            if t_s >= DURATION_S - 0.1 - 1e-9:
                break
        assert sitl.wait(timeout_s=20) == 0
        wall_s = time.monotonic() - start
        client.peer.poll()
        seen = [(m.time_boot_ms, m.x, m.y, m.z) for m in client.peer.messages if m.get_type() == "LOCAL_POSITION_NED"]
        return log.read_text(), seen, wall_s
    finally:
        client.close()
        sitl.stop()


def test_same_seed_same_flight_at_different_speeds(tmp_path: Path, instances: Callable[[], int]) -> None:
    slow_log, slow_seen, slow_wall = fly_in_lockstep(tmp_path, instances(), "2")
    fast_log, fast_seen, fast_wall = fly_in_lockstep(tmp_path, instances(), "0")
    assert slow_wall > DURATION_S / 2 - 0.5  # paced at twice real time
    assert fast_wall < slow_wall  # as fast as possible
    rows = slow_log.splitlines()
    assert len(rows) > 500
    assert slow_log == fast_log  # bit-identical ground truth
    last = rows[-1].split(",")
    assert math.hypot(float(last[1]), float(last[2])) < 1.0
    assert float(last[3]) < -3.5
    assert any(float(r.split(",")[1]) > 3.7 for r in rows[1:])  # reached the 4 m leg
    # The noisy telemetry the client received is the same sequence too (seeded noise, simulated timestamps).
    assert len(slow_seen) > 400
    assert slow_seen == fast_seen


def test_both_dynamics_backends_fly_the_same_script_through_the_sitl(
    tmp_path: Path, instances: Callable[[], int]
) -> None:
    pytest.importorskip("jsbsim")
    tracks = {}
    for dynamics in ("rigid_body", "jsbsim_f450"):
        log, _, _ = fly_in_lockstep(tmp_path, instances(), "0", dynamics)
        rows = [r.split(",") for r in log.splitlines()[1:]]
        tracks[dynamics] = np.array([[float(v) for v in r[:4]] for r in rows])
    rigid, jsb = tracks["rigid_body"], tracks["jsbsim_f450"]
    n = min(len(rigid), len(jsb))
    np.testing.assert_array_equal(rigid[:n, 0], jsb[:n, 0])  # the same simulated sample times
    airborne = rigid[:n, 0] >= 3.0
    # Stated tolerance, once airborne: within 0.5 m horizontally and 0.3 m vertically at every 20 ms sample.
    horizontal = np.linalg.norm(rigid[:n, 1:3] - jsb[:n, 1:3], axis=1)[airborne]
    vertical = np.abs(rigid[:n, 3] - jsb[:n, 3])[airborne]
    assert horizontal.max() < 0.5
    assert vertical.max() < 0.3


def test_time_waits_for_the_acknowledgement(tmp_path: Path, instance: int) -> None:
    config = tmp_path / "sitl.yaml"
    config.write_text("sitl:\n  lockstep_timeout_s: 3.0\n")
    sitl = SitlProcess(["--config", str(config), "--lockstep", "--speed", "0"], instance, tmp_path).start()
    client = LockstepClient(instance)
    try:
        client.subscribe()
        tick = client.next_tick()
        assert tick["seq"] == 0
        # No acknowledgement yet: simulated time stays at the tick while the wall clock runs (a heartbeat).
        beats = len(client.peer.heartbeat_wall_times)
        wait_until(lambda: client.peer.poll() is not None and len(client.peer.heartbeat_wall_times) > beats, 2, "1 s")
        assert sitl.state()["t_s"] == 0.0
        client.ack(0)
        assert client.next_tick()["seq"] == 1
        assert sitl.state()["t_s"] == pytest.approx(0.1)
        # A client that stops answering makes the SITL fail loudly after the timeout, not hang.
        assert sitl.wait(timeout_s=10) == 3
        assert "no acknowledgement of tick 1" in sitl.log_tail()
    finally:
        client.close()
        sitl.stop()


def test_a_sitl_waiting_for_its_first_client_is_found_at_once_and_takes_its_camera(
    tmp_path: Path, instance: int
) -> None:
    """Before a client subscribes, simulated time stands still at 0: heartbeats go out ten times a wall second (a
    companion finds the autopilot by one), back to PX4's 1 Hz once a client steps; and a camera that connects first
    is taken at once (its pending connection kept the SITL's wait from waiting: a wall second of CPU a mission)."""
    config = tmp_path / "sitl.yaml"
    config.write_text("sitl:\n  camera: {enabled: true}\n")
    sitl = SitlProcess(["--config", str(config), "--lockstep", "--speed", "0"], instance, tmp_path).start()
    client = LockstepClient(instance)
    camera = socket.create_connection(("127.0.0.1", SitlConfig(instance=instance).frame_port), timeout=5.0)
    try:
        wait_until(lambda: (sitl.state()["frames"] or {}).get("clients") == 1 or None, 5.0, "the camera taken")
        wait_until(lambda: client.peer.poll() is not None and len(client.peer.heartbeat_wall_times) >= 4, 5.0, "beats")
        waiting = np.diff(client.peer.heartbeat_wall_times[:4])
        assert float(np.median(waiting)) < 0.5, f"heartbeats {waiting} s apart while waiting for a client"
        assert sitl.state()["t_s"] == 0.0
        client.subscribe()
        beats = len(client.peer.heartbeat_wall_times)
        client.peer.poll()
        tick = client.next_tick()
        assert tick["seq"] == 0
        # Not acknowledged: time stands at the tick with a client stepping, and heartbeats are PX4's again.
        wait_until(
            lambda: client.peer.poll() is not None and len(client.peer.heartbeat_wall_times) >= beats + 3, 6.0, "beats"
        )
        stepping = np.diff(client.peer.heartbeat_wall_times[beats:])
        assert float(np.min(stepping[1:])) > 0.5, f"heartbeats {stepping} s apart with a client"
        assert sitl.state()["frames"]["clients"] == 1
    finally:
        camera.close()
        client.close()
        sitl.stop()


def test_an_ack_cannot_overtake_the_setpoints_sent_before_it(tmp_path: Path, instance: int) -> None:
    sitl = SitlProcess(["--lockstep", "--speed", "0"], instance, tmp_path).start()
    client = LockstepClient(instance)
    try:
        client.subscribe()
        client.next_tick()
        # Claim one more MAVLink message than actually arrived: the SITL must keep waiting for it.
        client.peer.sent += 1
        client.ack(0)
        beats = len(client.peer.heartbeat_wall_times)
        wait_until(
            lambda: client.peer.poll() is not None and len(client.peer.heartbeat_wall_times) >= beats + 1, 3, "1 s"
        )
        assert sitl.state()["t_s"] == 0.0
        client.peer.send(position_setpoint(client.peer.mav, 0, 0, -1, target_system=client.peer.vehicle_sysid))
        client.peer.sent -= 1  # the message now sent is the one that was announced
        assert client.next_tick()["seq"] == 1
    finally:
        client.close()
        sitl.stop()


def test_an_ack_can_name_the_setpoint_and_commands_it_waits_for(tmp_path: Path, instance: int) -> None:
    """For clients that cannot count their messages (MAVSDK re-sends setpoints on its own thread)."""
    sitl = SitlProcess(["--lockstep", "--speed", "0"], instance, tmp_path).start()
    client = LockstepClient(instance)
    try:
        client.subscribe()
        client.next_tick()
        expect = {"setpoint": [1.0, 2.0, -3.0, 0.5], "commands": {str(mavlink.MAV_CMD_NAV_LAND): 1}}
        client.control._sock.sendto(  # the ack names what must have arrived, not how many messages
            json.dumps({"cmd": "lockstep_ack", "seq": 0, "expect": expect}).encode(), client.control.address
        )
        beats = len(client.peer.heartbeat_wall_times)
        wait_until(
            lambda: client.peer.poll() is not None and len(client.peer.heartbeat_wall_times) >= beats + 1, 3, "1 s"
        )
        assert sitl.state()["t_s"] == 0.0  # neither has arrived
        sysid = client.peer.vehicle_sysid
        client.peer.send(position_setpoint(client.peer.mav, 1.0, 2.0, -3.0, 0.5, target_system=sysid))
        beats = len(client.peer.heartbeat_wall_times)
        wait_until(
            lambda: client.peer.poll() is not None and len(client.peer.heartbeat_wall_times) >= beats + 1, 3, "1 s"
        )
        assert sitl.state()["t_s"] == 0.0  # the setpoint, but not yet the land command
        client.peer.send(
            client.peer.mav.command_long_encode(sysid, 1, mavlink.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0)
        )
        assert client.next_tick()["seq"] == 1
    finally:
        client.close()
        sitl.stop()


@pytest.mark.parametrize("end_after_touchdown_s", [1.0, None])
def test_a_released_vehicle_on_the_ground_ends_the_run_in_simulated_time(
    tmp_path: Path, instance: int, end_after_touchdown_s: float | None
) -> None:
    """A campaign's SITL ends itself once its client has let go and the vehicle has been on the ground for
    ``end_after_touchdown_s`` (simulated), so it does not run on at full speed until someone stops it; without the
    setting it runs on (a SITL a person flies must not end under them)."""
    config = tmp_path / "sitl.yaml"
    setting = "" if end_after_touchdown_s is None else f"  end_after_touchdown_s: {end_after_touchdown_s}\n"
    config.write_text("sitl:\n  seed: 7\n" + setting)
    log = tmp_path / "trajectory.csv"
    sitl = SitlProcess(["--config", str(config), "--lockstep", "--speed", "0", "--log", str(log)], instance, tmp_path)
    sitl.start()
    client = LockstepClient(instance)
    try:
        client.subscribe()
        sysid = client.peer.vehicle_sysid
        arm = client.peer.mav.command_long_encode(
            sysid, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
        )
        while True:
            tick = client.next_tick()
            if tick["seq"] == 1:
                client.peer.send(arm)  # armed on the ground: landed, as after a touchdown
            client.peer.poll()
            client.ack(tick["seq"])
            if tick["t_s"] >= 1.0 - 1e-9:
                released_at_s = tick["t_s"]
                break
        assert wait_until(lambda: sitl.state()["armed"], 5.0, "armed")
        client.control.release()
        if end_after_touchdown_s is None:
            # Runs free: simulated time goes far past the release (at full speed, seconds of it within a wall second).
            wait_until(lambda: sitl.state()["t_s"] > released_at_s + 10.0, 20.0, "free-running time")
            assert sitl.running
            return
        assert sitl.wait(timeout_s=20.0) == 0  # ended by itself
    finally:
        client.close()
        sitl.stop()
    rows = log.read_text().splitlines()[1:]
    last_t_s = float(rows[-1].split(",")[0])
    armed = rows[-1].split(",")[11]
    assert armed == "1"  # it ended on the ground timer, not on a disarm
    # First seen on the ground at the first outer step after the release, then end_after_touchdown_s on.
    assert released_at_s + end_after_touchdown_s <= last_t_s <= released_at_s + end_after_touchdown_s + 0.2
