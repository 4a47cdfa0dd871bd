"""`slz fly` against the SITL over real UDP and TCP, as separate processes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.app.replay import replay
from sitl.config import SitlConfig
from sitl.process import SitlProcess
from tests.sitl_tools import GroundStation, state_when, wait_until

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent


def start_sitl_with_camera(tmp_path: Path, instance: int, seed: int) -> SitlProcess:
    """A SITL instance with its camera, and ``tmp_path/mission.yaml``: mission_configs/sitl.yaml on its ports."""
    sitl_config = tmp_path / "sitl.yaml"
    sitl_config.write_text(f"sitl:\n  camera:\n    enabled: true\n  seed: {seed}\n")
    mission = (REPO_ROOT / "mission_configs" / "sitl.yaml").read_text()
    mission = mission.replace("udpin://0.0.0.0:14540", f"udpin://0.0.0.0:{14540 + instance}")
    mission = mission.replace("sitl://127.0.0.1:5600", f"sitl://127.0.0.1:{5600 + instance}")
    mission = mission.replace("udp://127.0.0.1:4560", f"udp://127.0.0.1:{4560 + instance}")  # runs free: no lockstep
    mission = mission.replace("frame_every: 10", "frame_every: 1").replace("frame_format: jpeg", "frame_format: png")
    (tmp_path / "mission.yaml").write_text(mission)
    return SitlProcess(["--config", str(sitl_config)], instance, tmp_path).start()


def test_a_dry_run_perceives_and_decides_but_never_commands(tmp_path: Path) -> None:
    instance = 32
    sitl = start_sitl_with_camera(tmp_path, instance, seed=3)
    gcs = GroundStation(SitlConfig().gcs_port_remote)  # PX4 style: every instance talks to the GCS on 14550
    try:
        # The pilot (a ground station) takes off to 10 m: the camera needs to see the head plane.
        wait_until(lambda: gcs.poll() is not None and gcs.vehicle_addr, 10, "the vehicle on the GCS link")
        sysid = SitlConfig(instance=instance).system_id  # PX4 style: instance + 1

        def armed() -> bool:  # the pre-arm checks pass a moment after start: the pilot retries, as pilots do
            gcs.send(
                gcs.mav.command_long_encode(sysid, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            )
            return bool(sitl.state()["armed"])

        wait_until(armed, 15, f"the pilot arming vehicle {sysid}")
        takeoff_amsl_m = SitlConfig().origin_alt_m + 10.0
        gcs.send(
            gcs.mav.command_long_encode(sysid, 1, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, takeoff_amsl_m)
        )
        state_when(sitl, lambda st: st["mode"] == "AUTO.LOITER" and st["position_ned_m"][2] < -9.0, 30, "hover at 10 m")
        before = sitl.state()
        command = ["fly", "--config", str(tmp_path / "mission.yaml"), "--dry-run"]
        command += ["--out", str(tmp_path / "flight"), "--timeout", "8"]
        fly = subprocess.run(
            [sys.executable, "-m", "companion.cli", *command],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
            timeout=90,
        )
        after = sitl.state()
    finally:
        gcs.close()
        sitl.stop()
    assert fly.returncode == 0, fly.stderr[-3000:]
    # At the SITL's side: no setpoint, no arming, no mode change from the companion (the pilot's hold stays).
    assert after["setpoints_by_sender"] == before["setpoints_by_sender"] == {}
    assert after["armed"]
    assert after["mode"] == before["mode"] == "AUTO.LOITER"
    # At the companion's side: frames were processed and decisions logged, none sent.
    records = [json.loads(line) for line in (tmp_path / "flight" / "flight.jsonl").read_text().splitlines()]
    kinds = [r["kind"] for r in records]
    assert kinds[0] == "header"
    assert kinds.count("frame_result") >= 10
    assert kinds.count("decision") >= 10
    assert "command" not in kinds
    end = next(r for r in records if r["kind"] == "end")
    assert end["outcome"]["commands_sent"] == 0
    assert end["outcome"]["frames_processed"] >= 10
    # The logged decisions are the flight logic's, the ones `fly` would send: the same inputs replayed through the
    # same pipeline and state machine give every one of them again.
    report = replay(tmp_path / "flight")
    assert report.decisions == kinds.count("decision")
    assert report.identical, report.differences


def test_the_companion_yields_at_once_when_the_pilot_takes_over(tmp_path: Path) -> None:
    instance = 33
    sitl = start_sitl_with_camera(tmp_path, instance, seed=4)
    command = ["fly", "--config", str(tmp_path / "mission.yaml"), "--out", str(tmp_path / "flight"), "--timeout", "90"]
    fly = subprocess.Popen(
        [sys.executable, "-m", "companion.cli", *command],
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        # The companion takes off and starts its search in OFFBOARD; then the pilot switches to position control.
        state_when(sitl, lambda st: st["mode"] == "OFFBOARD", 60, "the companion in OFFBOARD")
        assert sitl.request({"cmd": "pilot_mode", "mode": "POSCTL"})["result"] == 0
        out, err = fly.communicate(timeout=20)  # it must yield and end, not fight the pilot
        after = sitl.state()
    finally:
        if fly.poll() is None:
            fly.kill()
        sitl.stop()
    assert fly.returncode == 0, err[-3000:]
    assert "ended in yielded" in out
    assert after["mode"] == "POSCTL"
    records = [json.loads(line) for line in (tmp_path / "flight" / "flight.jsonl").read_text().splitlines()]
    phases = [r["phase"] for r in records if r["kind"] == "phase"]
    assert phases[-1] == "yielded"
    yielded_at = next(r["t_s"] for r in records if r["kind"] == "phase" and r["phase"] == "yielded")
    assert not [r for r in records if r["kind"] == "command" and r["t_s"] > yielded_at]  # nothing sent after
