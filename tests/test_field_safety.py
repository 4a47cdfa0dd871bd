"""The field path's safety, flown against the SITL over real MAVLink: a wall limit reached mid-descent leaves the
vehicle holding with the program still watching it, and a dry run started on the ground records the whole flight
the pilot flies (issue 50). The same behaviours with a fake link, tick by tick, are in
tests/test_flight_supervision.py."""

from __future__ import annotations

import asyncio
import itertools
import json
import math
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.app.flight import FlightApp
from companion.app.mission import validate_for_flight
from companion.camera.sources import open_frame_source
from companion.flightlog.recorder import FlightRecorder, read_log
from companion.guidance.landing import LandingPhase
from companion.vehicle.lockstep import LockstepClient
from companion.vehicle.mavsdk_link import MavsdkVehicleLink
from sitl.config import SitlConfig
from sitl.testing.helpers import (
    CompanionFlight,
    GroundStation,
    fly_to_the_end,
    free_udp_port,
    pilot_takes_off,
    sitl_mission_yaml,
    start_camera_sitl,
    state_when,
    wait_until,
    wait_until_async,
    write_sitl_mission,
)

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent


class TripsInDescent:
    """The wall clock of a flight whose wall limit is reached at its first tick in the descent."""

    def __init__(self) -> None:
        self.app: FlightApp | None = None
        self.tripped_at_s: float | None = None

    def __call__(self) -> float:
        descending = self.app is not None and self.app.landing.guidance.phase is LandingPhase.DESCENT
        if descending and self.tripped_at_s is None:
            self.tripped_at_s = time.monotonic()
        return time.monotonic() + (0.0 if self.tripped_at_s is None else 1e6)


async def test_a_wall_limit_reached_mid_descent_leaves_the_vehicle_holding_under_the_programs_watch(
    tmp_path: Path, instance: int
) -> None:
    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port(), lockstep=True)
    mission = write_sitl_mission(tmp_path, instance)
    config, pipeline = validate_for_flight(mission)  # as `slz fly` loads it
    clock = TripsInDescent()
    recorder = FlightRecorder(tmp_path / "flight")
    link = MavsdkVehicleLink(config.vehicle.url, config.vehicle.telemetry_rate_hz, config.vehicle.system_id)
    assert config.simulator.lockstep_url is not None
    lockstep = LockstepClient(config.simulator.lockstep_url, config.simulator.tick_timeout_s)
    source = open_frame_source(config.camera.url, vehicle_time_s=link.telemetry.clock.now_s)
    app = FlightApp(config, link, source, pipeline, recorder, lockstep, wall_limit_s=600.0, wall_clock=clock)
    clock.app = app
    loop = asyncio.get_running_loop()

    async def sitl_state_when(predicate: Callable[[dict[str, Any]], bool], what: str) -> dict[str, Any]:
        # In a thread: the flight's loop keeps acknowledging ticks meanwhile.
        return await loop.run_in_executor(None, state_when, sitl, predicate, 120.0, what)

    try:
        run = asyncio.create_task(app.run())
        guidance = app.landing.guidance
        await wait_until_async(lambda: guidance.phase is LandingPhase.FAILSAFE or run.done(), 150, "the wall limit")
        assert not run.done(), run.exception() if run.done() else None
        held = await sitl_state_when(lambda s: s["mode"] == "AUTO.LOITER" and s["t_s"] >= 1.0, "the hold")
        # Ten simulated seconds on: still holding, still watched.
        later = await sitl_state_when(lambda s: s["t_s"] >= held["t_s"] + 10.0, "ten simulated seconds more")
        assert not run.done()
        piloted = await loop.run_in_executor(None, sitl.request, {"cmd": "pilot_mode", "mode": "POSCTL"})
        assert piloted["result"] == 0
        outcome = await asyncio.wait_for(run, 30.0)
    finally:
        await link.close()
        recorder.close()
        sitl.stop()
    assert clock.tripped_at_s is not None
    # At the SITL: hold in the air (never the offboard-loss failsafe's landing), where the descent was stopped.
    assert held["mode"] == "AUTO.LOITER"
    assert not held["on_ground"]
    assert held["armed"]
    assert later["mode"] == "AUTO.LOITER"
    assert not later["on_ground"]
    assert -later["position_ned_m"][2] > 3.0
    moved_m = [abs(a - b) for a, b in zip(held["position_ned_m"], later["position_ned_m"], strict=True)]
    assert max(moved_m) < 1.0, moved_m
    assert not later["failsafe"]
    # At the companion: the limit's last resort from the descent, then watching until the pilot had the vehicle.
    records = read_log(tmp_path / "flight" / "flight.jsonl")
    phases = [r["phase"] for r in records if r["kind"] == "phase"]
    assert phases[-2:] == ["descent", "failsafe"]
    last = [r for r in records if r["kind"] == "decision"][-1]
    assert last["source"] == "limit"
    assert last["decision"]["reason"] == "wall limit of 600 s reached (slz fly --timeout): hold"
    assert [r["command"] for r in records if r["kind"] == "command"][-1] == "hold"
    assert [r["event"] for r in records if r["kind"] == "supervision"] == ["watching", "pilot_has_it"]
    assert outcome.phase == "failsafe"
    assert outcome.reason.endswith("the pilot has it (mode POSCTL)")


def test_a_dry_run_started_on_the_ground_records_the_whole_flight_the_pilot_flies(
    tmp_path: Path, instance: int
) -> None:
    gcs_port = free_udp_port()
    sitl = start_camera_sitl(tmp_path, instance, seed=3, gcs_port=gcs_port, lockstep=False)
    mission = write_sitl_mission(tmp_path, instance)
    with CompanionFlight(sitl, mission, tmp_path / "flight", "--dry-run") as fly:
        gcs = GroundStation(instance, gcs_port)
        try:
            wait_until(lambda: fly.logged('"kind":"waiting"'), 60, "the dry run waiting")
            assert fly.process.poll() is None  # on the bench it waits: no failsafe ends it
            pilot_takes_off(sitl, gcs, instance, altitude_m=10.0)  # the dry run commands nothing: the takeoff holds
            wait_until(lambda: fly.logged('"source":"frame"'), 30, "decisions on frames")
            sysid = SitlConfig(instance=instance).system_id
            gcs.send(gcs.mav.command_long_encode(sysid, 1, mavlink.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0))
            out, err = fly.finish(60)  # it ends by itself once the vehicle is down and disarmed
            after = sitl.state()
        finally:
            gcs.close()
    log = fly.log
    assert fly.returncode == 0, err[-3000:]
    assert "dry_run: dry run over; ended in" in out  # the landing report's ending first (issue 65)
    assert "the flight is over: on the ground and disarmed" in out
    assert not after["armed"]
    assert after["on_ground"]
    assert after["setpoints_by_sender"] == {}  # it commanded nothing
    # The console told the pilot what it waited for and what it decided.
    assert "[dry run] waiting for the vehicle armed and in the air" in err
    assert "[dry run] phase idle -> search" in err
    records = [json.loads(line) for line in log.read_text().splitlines()]
    kinds = [r["kind"] for r in records]
    assert kinds.count("frame_result") >= 10
    assert "command" not in kinds
    waits = [r["waiting_for"] for r in records if r["kind"] == "waiting"]
    assert waits[0] == "the vehicle armed and in the air"
    assert any(r["kind"] == "decision" and r["source"] == "start" for r in records)
    assert [r["event"] for r in records if r["kind"] == "supervision"][-1] == "on_ground"
    assert kinds[-1] == "end"
    # The path of the whole flight, the wait on the bench included: poses once a second, from the ground to the
    # ground, in the air at 10 m between.
    poses = [r for r in records if r["kind"] == "pose"]
    started = next(r["t_s"] for r in records if r["kind"] == "decision" and r["source"] == "start")
    assert [p["in_air"] for p in poses[:1]] == [False]
    assert any(p["t_s"] < started for p in poses)
    assert min(p["down_m"] for p in poses) < -8.0  # sampled once a second on the way to 10 m
    assert all(b["t_s"] - a["t_s"] >= 0.99 for a, b in itertools.pairwise(poses))


def test_a_fence_in_latitude_and_longitude_is_projected_from_the_ekf_origin_and_flown(
    tmp_path: Path, instance: int
) -> None:
    from companion.tools.replay import replay
    from sitl.geodesy import ned_to_geodetic

    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port(), lockstep=True)
    origin = SitlConfig()
    corners_ne = [(-25.0, -25.0), (-25.0, 25.0), (25.0, 25.0), (25.0, -25.0)]  # sitl.yaml's fence, as a surveyor
    lat0, lon0 = origin.origin_lat_deg, origin.origin_lon_deg
    corners_latlon = [ned_to_geodetic(n, e, 0.0, lat0, lon0, 0.0)[:2] for n, e in corners_ne]
    text = sitl_mission_yaml(instance, flights_dir=tmp_path)  # every 10th frame as JPEG: --replayable overrides it
    fence_ne = "  polygon_ne_m: [[-25.0, -25.0], [-25.0, 25.0], [25.0, 25.0], [25.0, -25.0]]\n"
    assert fence_ne in text
    latlon = ", ".join(f"[{lat:.9f}, {lon:.9f}]" for lat, lon in corners_latlon)
    text = text.replace(fence_ne, f"  polygon_latlon_deg: [{latlon}]\n")
    mission = tmp_path / "mission.yaml"
    mission.write_text(text)
    fly = fly_to_the_end(sitl, mission, tmp_path / "flight", "--replayable", timeout_s=180)
    assert fly.returncode == 0, fly.stderr[-3000:]
    assert "ended in done (landed)" in fly.stdout
    records = read_log(tmp_path / "flight" / "flight.jsonl")
    assert {Path(r["path"]).suffix for r in records if r["kind"] == "frame"} == {".png"}  # issue 65: --replayable
    fence = next(r for r in records if r["kind"] == "fence")
    # PX4's projection (a sphere) against the SITL's (WGS-84 radii at the origin): a few centimetres at 25 m.
    got_ne = [tuple(v) for v in fence["polygon_ne_m"]]
    assert got_ne == [pytest.approx(corner, abs=0.1) for corner in corners_ne]
    assert (fence["origin_lat_deg"], fence["origin_lon_deg"]) == pytest.approx(
        (origin.origin_lat_deg, origin.origin_lon_deg), abs=1e-6
    )
    setpoints = [r["setpoint"] for r in records if r["kind"] == "command" and r["setpoint"]]
    assert setpoints
    assert all(abs(sp["north_m"]) <= 25.1 and abs(sp["east_m"]) <= 25.1 for sp in setpoints)
    # The replay projects nothing: it takes the fence the flight recorded, and decides the same; so does the report.
    report = replay(tmp_path / "flight")
    assert report.identical, report.differences
    reported = subprocess.run(
        [sys.executable, "-m", "companion.cli", "report", str(tmp_path / "flight"), "--no-video"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert reported.returncode == 0, reported.stderr[-2000:]


def test_a_service_stopped_before_its_vehicle_answers_ends_at_once_not_at_the_connect_timeout(
    tmp_path: Path, instance: int
) -> None:
    import signal

    # A campaign interrupted as a mission starts: the worker's SITL died with it, its companion is still looking for
    # the vehicle. Here the camera is up and no autopilot listens on the vehicle's port; the connect would wait 120 s.
    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port())
    mission = tmp_path / "mission.yaml"
    text = sitl_mission_yaml(instance, flights_dir=tmp_path)
    text = text.replace(f"udpin://0.0.0.0:{14540 + instance}", f"udpin://0.0.0.0:{free_udp_port()}")
    assert "connect_timeout_s: 20.0" in text
    mission.write_text(text.replace("connect_timeout_s: 20.0", "connect_timeout_s: 120.0"))
    with CompanionFlight(sitl, mission, tmp_path / "flight") as fly:
        wait_until(lambda: fly.logged('"kind":"start"'), 120, "the run's start")
        fly.process.send_signal(signal.SIGTERM)  # what a worker's death sends (sitl.harness.process.die_with_parent)
        out, err = fly.finish(30)  # a quarter of the connect timeout
    log = fly.log
    assert "SIGTERM received: no vehicle tick within 3 s, ending without the last resort" in out, err[-3000:]
    assert [r["kind"] for r in read_log(log)][-3:] == ["start", "supervision", "end"]


def test_a_stopped_service_leaves_the_vehicle_holding_not_to_the_offboard_loss_failsafe(
    tmp_path: Path, instance: int
) -> None:
    import signal

    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port(), lockstep=True)
    with CompanionFlight(sitl, write_sitl_mission(tmp_path, instance), tmp_path / "flight") as fly:
        wait_until(lambda: fly.logged('"phase":"approach"'), 120, "the approach")
        fly.process.send_signal(signal.SIGINT)  # the systemd unit's KillSignal
        out, err = fly.finish(30)
        held = state_when(sitl, lambda st: st["mode"] == "AUTO.LOITER", 10, "the hold")
    log = fly.log
    assert fly.returncode == 3, err[-3000:]  # a failsafe: the service does not restart on it
    assert "SIGINT received: stopping: hold" in out
    assert not held["on_ground"]
    assert not held["failsafe"]  # the autopilot's own offboard-loss failsafe never fired
    records = read_log(log)
    last = [r for r in records if r["kind"] == "decision"][-1]
    assert last["source"] == "stop"
    assert [r["command"] for r in records if r["kind"] == "command"][-1] == "hold"
    assert records[-1]["kind"] == "end"
    # Issue 65: the landing report names the stop; one failsafe record (the stop's), none for a frame after it.
    assert "fly: stopped;" in out
    report = json.loads((tmp_path / "flight" / "landing_report.json").read_text())
    assert report["outcome"] == "stopped"
    assert len([r for r in records if r["kind"] == "failsafe"]) == 1
    from companion.tools.report import build_flight_report

    assert build_flight_report(tmp_path / "flight", tmp_path / "report", video=False).files


def test_a_companion_killed_in_flight_leaves_px4_v1_15_hovering_in_position_mode_not_landing(
    tmp_path: Path, instance: int
) -> None:
    # Issue 65 (11): the SITL is PX4 v1.15, whose offboard-loss failsafe is COM_OBL_RC_ACT (default 0: position
    # mode, the pilot's sticks). deploy/README.md's story of a companion that dies over a crowd, measured on it:
    # the vehicle hovers where it was, it does not land in place (v1.13's COM_OBL_ACT = 0 did).
    import signal

    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port())  # running free: no lockstep
    mission = write_sitl_mission(tmp_path, instance)
    with CompanionFlight(sitl, mission, tmp_path / "flight", capture=False) as fly:
        wait_until(lambda: fly.logged('"phase":"approach"'), 180, "the approach")
        killed = sitl.state()
        assert killed["mode"] == "OFFBOARD"
        fly.process.send_signal(signal.SIGKILL)  # a crash: no last resort, no goodbye
        fly.process.wait(timeout=10)
        failsafe = state_when(sitl, lambda st: bool(st["failsafe"]), 10, "the offboard-loss failsafe")
        later = state_when(sitl, lambda st: st["t_s"] >= failsafe["t_s"] + 10.0, 30, "ten seconds of the failsafe")
    assert failsafe["failsafe"] == "Offboard lost"
    assert 0.8 <= failsafe["t_s"] - killed["t_s"] <= 2.0  # COM_OF_LOSS_T = 1 s, read through the state channel
    assert failsafe["mode"] == "POSCTL"
    # Ten seconds on, still in the air at the altitude it was left at, near where it stopped (it braked first).
    assert later["mode"] == "POSCTL"
    assert later["armed"]
    assert not later["on_ground"]
    assert abs(later["position_ned_m"][2] - failsafe["position_ned_m"][2]) < 0.5
    north_m, east_m = (later["position_ned_m"][i] - failsafe["position_ned_m"][i] for i in (0, 1))
    assert math.hypot(north_m, east_m) < 5.0
    # The killed flight's log survives to its last record, and slz report names the ending and draws it.
    from companion.flightlog.flight_log import FlightLog
    from companion.tools.landing_report import FlightEnding, landing_report
    from companion.tools.report import build_flight_report

    assert landing_report(FlightLog.read(tmp_path / "flight"))["outcome"] == FlightEnding.CRASHED.value
    assert build_flight_report(tmp_path / "flight", tmp_path / "report", video=False).files
