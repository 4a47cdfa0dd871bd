"""`slz fly` against the SITL over real UDP and TCP, as separate processes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from companion.tools.replay import replay
from sitl.harness.process import SitlProcess
from sitl.testing.helpers import (
    CompanionFlight,
    GroundStation,
    fly_to_the_end,
    free_udp_port,
    pilot_takes_off,
    start_camera_sitl,
    state_when,
    wait_until,
    write_sitl_mission,
)

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent


def start_sitl_with_camera(tmp_path: Path, instance: int, seed: int, gcs_port: int) -> SitlProcess:
    """A SITL instance with its camera, its ground-station link on ``gcs_port``, and ``tmp_path/mission.yaml``:
    mission_configs/sitl.yaml on its ports."""
    write_sitl_mission(tmp_path, instance, replayable=True)  # the SITL runs free: no lockstep
    return start_camera_sitl(tmp_path, instance, seed, gcs_port)


def test_a_dry_run_perceives_and_decides_but_never_commands(tmp_path: Path, instance: int) -> None:
    gcs_port = free_udp_port()  # its own ground-station port: every instance would send to 14550
    sitl = start_sitl_with_camera(tmp_path, instance, seed=3, gcs_port=gcs_port)
    gcs = GroundStation(instance, gcs_port)  # this pilot listens to its own vehicle only
    try:
        pilot_takes_off(sitl, gcs, instance, altitude_m=10.0)
        before = sitl.state()
        dry_run = ("--dry-run", "--timeout", "8")
        fly = fly_to_the_end(sitl, tmp_path / "mission.yaml", tmp_path / "flight", *dry_run, timeout_s=90)
    finally:
        gcs.close()
        sitl.stop()  # already stopped unless the takeoff failed
    after = fly.truth
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
    # The team reviews the dry run without the SITL: `slz report` turns the log into plots, video and a page.
    reported = subprocess.run(
        [sys.executable, "-m", "companion.cli", "report", str(tmp_path / "flight")],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert reported.returncode == 0, reported.stderr[-3000:]
    out = tmp_path / "flight" / "report"
    for name in ("top_view.png", "timeline.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "camera_sheet.jpg").read_bytes()[:2] == b"\xff\xd8"
    assert (out / "camera.mp4").stat().st_size > 10_000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mode"] == "dry_run"
    assert summary["commands_sent"] == 0
    assert summary["decisions"] == kinds.count("decision")
    assert summary["camera_frames"] == kinds.count("frame")
    page = (out / "report.md").read_text()
    assert "mode: **dry_run** (decided, never commanded)" in page
    assert "![top_view](top_view.png)" in page


def test_in_the_field_the_companion_waits_for_the_handover_then_yields_at_once_to_the_pilot(
    tmp_path: Path, instance: int
) -> None:
    gcs_port = free_udp_port()
    sitl = start_sitl_with_camera(tmp_path, instance, seed=4, gcs_port=gcs_port)
    field = (tmp_path / "mission.yaml").read_text().replace("arm_and_takeoff: true", "arm_and_takeoff: false")
    (tmp_path / "field.yaml").write_text(field)
    field_options = ("--never-arm", "--timeout", "120")
    with CompanionFlight(sitl, tmp_path / "field.yaml", tmp_path / "flight", *field_options) as fly:
        gcs = GroundStation(instance, gcs_port)
        try:
            # On the ground the companion only waits: it never arms, never takes off, sends nothing.
            wait_until(lambda: fly.logged('"kind":"waiting_for_handover"'), 60, "the wait")
            on_ground = sitl.state()
            # The pilot takes off and hands over by switching to HOLD (the end of a takeoff is HOLD): the companion
            # takes OFFBOARD from there. Then the pilot takes over in position control: it must yield at once.
            pilot_takes_off(sitl, gcs, instance, altitude_m=10.0, then_modes=("OFFBOARD",))
            state_when(sitl, lambda st: st["mode"] == "OFFBOARD", 30, "the companion in OFFBOARD after the handover")
            assert sitl.request({"cmd": "pilot_mode", "mode": "POSCTL"})["result"] == 0
            out, err = fly.finish(20)  # it must yield and end, not fight the pilot
            after = sitl.state()
        finally:
            gcs.close()
    log = fly.log
    assert not on_ground["armed"]
    assert on_ground["setpoints_by_sender"] == {}
    assert fly.returncode == 0, err[-3000:]
    assert "ended in yielded" in out
    assert after["mode"] == "POSCTL"
    records = [json.loads(line) for line in log.read_text().splitlines()]
    handover = next(r for r in records if r["kind"] == "handover")
    assert handover["mode"] == "HOLD"
    assert handover["altitude_m"] > 9.0
    assert not [r for r in records if r["kind"] == "command" and r["t_s"] < handover["t_s"]]  # nothing before it
    phases = [r["phase"] for r in records if r["kind"] == "phase"]
    assert phases[-1] == "yielded"
    yielded_at = next(r["t_s"] for r in records if r["kind"] == "phase" and r["phase"] == "yielded")
    assert not [r for r in records if r["kind"] == "command" and r["t_s"] > yielded_at]  # nothing sent after
    # Issue 65: the landing report names the pilot's takeover, and slz report draws the flight.
    assert "fly: the pilot took over;" in out
    assert json.loads((tmp_path / "flight" / "landing_report.json").read_text())["outcome"] == "pilot_took_over"
    from companion.tools.report import build_flight_report

    assert build_flight_report(tmp_path / "flight", tmp_path / "report", video=False).files
