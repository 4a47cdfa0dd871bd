"""End-to-end landing missions: the SITL and ``slz fly`` as real processes over real UDP and TCP, the shipped model,
lockstep (so each mission is the same on any machine at any speed), outcomes read from the SITL's ground truth.

Each test reads like a flight card: the scene (seed, walkers, injected fault), what the companion must do, and the
tolerances it is held to.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from companion.flightlog.recorder import read_log
from companion.guidance.geofence import Geofence, GeofenceConfig
from companion.perception.config import PerceptionConfig
from sitl.harness.instances import leased_instance
from sitl.harness.mission import MissionResult, MissionSpec, fly
from sitl.testing.helpers import ListeningGroundStation, free_udp_port
from sitl.vehicle.truth import read_truth, touchdown

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent
CLEARANCE_M = 1.5  # the bar: no person's body within 1.5 m of the touchdown point
STATIC_SEED = 1  # the README's `make demo`
WALKING_SEED = 6
FAULT_AT_S = 18.0  # simulated: the companion is searching or approaching by then (takeoff ends near 13 s)


def _fly(tmp_path: Path, name: str, seed: int, **spec: object) -> MissionResult:
    with leased_instance() as lease:  # a free SITL instance: never one another run on the machine flies
        return fly(MissionSpec(seed=seed, run_dir=tmp_path / name, instance=lease.instance, timeout_s=300.0, **spec))  # type: ignore[arg-type]


def _records(run_dir: str | Path) -> list[dict[str, Any]]:
    return read_log(Path(run_dir) / "flight" / "flight.jsonl")


def _phases(run_dir: str | Path) -> list[tuple[float, str]]:
    return [(float(r["t_s"]), str(r["phase"])) for r in _records(run_dir) if r["kind"] == "phase"]


@dataclass(frozen=True)
class Demo:
    """``slz demo`` as a user runs it: its output and its run folder."""

    stdout: str
    run_dir: Path
    summary: dict[str, Any]


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Demo:
    """The main job on a static crowd (80-120 people): one mission, every frame saved losslessly."""
    out = tmp_path_factory.mktemp("demo")
    command = [sys.executable, "-m", "companion.cli", "demo", "--seed", str(STATIC_SEED), "--out", str(out)]
    done = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=600, check=False)
    runs = [p for p in out.iterdir() if p.is_dir()]
    assert len(runs) == 1, done.stderr[-3000:]
    assert done.returncode == 0, done.stdout + done.stderr[-3000:]
    return Demo(done.stdout, runs[0], json.loads((runs[0] / "summary.json").read_text()))


def test_the_demo_lands_a_static_crowd_mission_clear_of_people(demo: Demo) -> None:
    s = demo.summary
    assert s["companion_exit_code"] == 0
    assert s["phase"] == "done"
    assert s["landed"]
    assert s["nearest_person_m"] >= CLEARANCE_M
    assert s["people_within_1_5m"] == 0
    assert f"nearest person's body is {s['nearest_person_m']:.2f} m" in demo.stdout
    assert (demo.run_dir / "demo.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"  # the README's picture, made here
    # The landing report the operator files, beside the flight log.
    landing = json.loads((demo.run_dir / "flight" / "landing_report.json").read_text())
    assert landing["ended_in"] == "done"
    assert landing["zone"]["radius_m"] == pytest.approx(s["target_radius_m"])
    assert landing["zone_when_descent_began"]["radius_m"] == pytest.approx(s["descent_zone"]["radius_m"])
    footprint_m = float(PerceptionConfig().zones.min_radius_m)
    assert landing["nearest_occupied_m"] is None or landing["nearest_occupied_m"] >= footprint_m - 0.25
    zone = s["descent_zone"]  # the zone's radius is named for what it is: as seen when the descent began
    assert f"zone {zone['track_id']}: free radius {zone['radius_m']:.2f} m as seen from" in demo.stdout
    assert zone["seen_from_altitude_m"] > 5.0
    assert f"its free radius at the land decision: {s['target_radius_m']:.2f} m" in demo.stdout
    phases = [p for _, p in _phases(demo.run_dir)]
    assert phases[0] == "search"
    assert "descent" in phases
    assert phases[-2:] == ["land", "done"]


def test_the_simulator_draws_frames_only_from_the_start_until_the_landing_is_the_autopilots(demo: Demo) -> None:
    records = _records(demo.run_dir)
    outcome = next(r for r in records if r["kind"] == "end")["outcome"]
    assert outcome["lockstep"]
    assert outcome["frames_before_start"] == 0  # the takeoff and transit came without frames
    assert outcome["frames_missing"] == 0
    assert outcome["frames_processed"] >= 50
    phases = _phases(demo.run_dir)
    search_t_s = phases[0][0]
    first_frame_t_s = min(float(r["t_s"]) for r in records if r["kind"] == "frame_result")
    assert search_t_s < first_frame_t_s <= search_t_s + 0.2  # from the tick after the start on
    # The LAND command is decided on a frame; the tick that carries it asks for no more (the autopilot lands alone).
    land_t_s = next(t for t, phase in phases if phase == "land")
    last_frame_t_s = max(float(r["t_s"]) for r in records if r["kind"] in ("frame", "frame_result", "frame_error"))
    assert last_frame_t_s == pytest.approx(land_t_s, abs=1e-6)
    assert outcome["touchdown_t_s"] > land_t_s + 1.0  # the landing itself took ticks that came without frames


def test_the_demo_writes_a_top_view_and_an_annotated_video(demo: Demo) -> None:
    top = cv2.imread(str(demo.run_dir / "top_view.png"))
    assert top is not None
    assert top.shape[0] >= 400
    assert (top != top[0, 0]).any(axis=2).mean() > 0.05  # drawn on, not blank
    video = cv2.VideoCapture(str(demo.run_dir / "camera.mp4"))
    frames = int(video.get(cv2.CAP_PROP_FRAME_COUNT))
    video.release()
    processed = sum(1 for r in _records(demo.run_dir) if r["kind"] == "frame_result")
    assert frames == processed > 100
    assert demo.summary["replay_identical"]


def test_the_sitls_ulog_lines_up_with_the_companions_log_in_slz_report(demo: Demo, tmp_path: Path) -> None:
    # Issue 67: the SITL writes the flight as PX4's SITL does; `slz report --ulog` draws the autopilot beside the
    # companion on the one boot clock.
    ulog = demo.run_dir / "flight.ulg"
    out = tmp_path / "report"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "companion.cli",
            "report",
            str(demo.run_dir),
            "--no-video",
            "--ulog",
            str(ulog),
            "--out",
            str(out),
        ],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert f"wrote {out / 'autopilot.png'}" in done.stdout
    from companion.tools.autopilot_log import read_autopilot_log

    autopilot = read_autopilot_log(ulog)
    modes = [m for _, m in autopilot.modes]
    # Take-off, the companion's offboard flight, its landing: in that order, the landing last.
    assert modes.index("AUTO.TAKEOFF") < modes.index("OFFBOARD") < modes.index("AUTO.LAND") == len(modes) - 1
    assert "OFFBOARD" in modes
    assert modes[-1] == "AUTO.LAND"
    # The companion's land command and the autopilot's switch to AUTO.LAND are one outer step apart at most (the
    # ULog samples at 50 Hz of the same clock).
    land_sent_s = next(
        float(r["t_s"]) for r in _records(demo.run_dir) if r["kind"] == "command" and r["command"] == "land"
    )
    land_mode_s = next(t for t, m in autopilot.modes if m == "AUTO.LAND")
    assert 0.0 <= land_mode_s - land_sent_s <= 0.1
    page = (out / "report.md").read_text()
    assert "## The autopilot beside the companion" in page
    assert "| autopilot | mode AUTO.LAND |" in page
    assert "| companion | sent land |" in page


def test_slz_export_writes_the_demo_as_mcap_with_every_record_foxglove_reads(demo: Demo, tmp_path: Path) -> None:
    # Issue 67: the flight in the file Foxglove opens; the mcap package's own reader counts every topic.
    out = tmp_path / "demo.mcap"
    command = [sys.executable, "-m", "companion.cli", "export", str(demo.run_dir), "--mcap", "--out", str(out)]
    done = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    from mcap.reader import make_reader

    with out.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        assert summary.statistics is not None
        counts = {
            ch.topic: summary.statistics.channel_message_counts.get(cid, 0) for cid, ch in summary.channels.items()
        }
        schemas = {summary.schemas[ch.schema_id].name for ch in summary.channels.values()}
        times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=False)]
    records = _records(demo.run_dir)

    def count(kind: str, **match: object) -> int:
        return sum(1 for r in records if r["kind"] == kind and all(r.get(k) == v for k, v in match.items()))

    frames_saved = sum(1 for r in records if r["kind"] == "frame" and r.get("path"))
    assert counts["/camera/image"] == frames_saved > 100
    assert counts["/slz/zones"] == count("frame_result") == counts["/tf"] - 1  # and world_ned under world, once
    assert counts["/slz/decisions"] == count("decision")
    assert counts["/slz/phase"] == count("phase")
    assert counts["/slz/setpoint"] == count("command", command="setpoint")
    assert counts["/slz/commands"] == count("command") - count("command", command="setpoint") >= 1  # the land
    assert counts["/truth/people"] >= 1  # the SITL's truth, found beside the flight folder
    events = sum(count(kind) for kind in ("failsafe", "error", "warning", "ground_command", "supervision"))
    assert counts.get("/slz/events", 0) == events
    assert counts.get("/slz/map", 0) == 0  # not in a flight log: the live view sends it
    assert schemas == {
        "foxglove.Grid",
        "foxglove.CompressedImage",
        "foxglove.FrameTransform",
        "foxglove.SceneUpdate",
        "foxglove.Log",
        "foxglove.PoseInFrame",
    }
    assert times == sorted(times)  # in log-time order, as a player replays it


def test_every_setpoint_stays_in_the_geofence_and_within_the_descent_rate(demo: Demo) -> None:
    records = _records(demo.run_dir)
    config = next(r for r in records if r["kind"] == "header")["config"]
    fence = Geofence(GeofenceConfig.model_validate(config["geofence"]))
    limit_mps = float(config["guidance"]["descent_rate_limit_mps"])
    setpoints = [r["setpoint"] for r in records if r["kind"] == "command" and r["command"] == "setpoint"]
    assert len(setpoints) > 100
    for sp in setpoints:
        assert fence.contains(sp["north_m"], sp["east_m"], -sp["down_m"])
    # At the SITL's side: while the companion commanded (OFFBOARD), the true descent never exceeded the limit
    # (10 % for the position controller's overshoot, over 0.5 s windows).
    _, truth = read_truth(demo.run_dir / "truth.jsonl")
    offboard = [(t.t_s, t.position_ned_m[2]) for t in truth if t.mode == "OFFBOARD"]
    t_s, down_m = np.array(offboard).T
    window = 5  # frames of 0.1 s
    rates = (down_m[window:] - down_m[:-window]) / (t_s[window:] - t_s[:-window])
    contiguous = np.isclose(t_s[window:] - t_s[:-window], window * 0.1, atol=1e-6)
    assert rates[contiguous].max() <= 1.1 * limit_mps


def test_slz_replay_reproduces_every_logged_decision(demo: Demo) -> None:
    # The command the demo prints, on the run folder it names.
    shown = next(line for line in demo.stdout.splitlines() if line.startswith("look again: "))
    replay_command = shown.split(", ")[-1]
    assert replay_command == f"slz replay {demo.run_dir}"
    done = subprocess.run(
        [sys.executable, "-m", "companion.cli", *replay_command.split()[1:]],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr[-2000:]
    assert "0 frame and 0 decision differences" in done.stdout
    assert done.stdout.strip().endswith("identical")


def test_a_mission_with_walking_people_lands_safely_inside_its_landing_area(tmp_path: Path) -> None:
    walkers = {"scenario": {"moving_fraction": 0.2}}  # the paper's hardest condition: 20 % of people walk
    roi_half_m = 15.0  # the scenario's 30 m ROI, where the people stand
    area = [[-roi_half_m, -roi_half_m], [-roi_half_m, roi_half_m], [roi_half_m, roi_half_m], [roi_half_m, -roi_half_m]]
    held = {"perception": {"zones": {"landing_area_ne_m": area}}}
    # A ground station listens on the vehicle's GCS link (a free port of its own rather than 14550, which every SITL
    # instance on this machine sends to).
    gcs_port = free_udp_port()
    with ListeningGroundStation(gcs_port) as gcs:
        r = _fly(
            tmp_path,
            "walking",
            WALKING_SEED,
            sitl_overrides={**walkers, "gcs_port_remote": gcs_port},
            mission_overrides=held,
        )
    assert r.companion_exit_code == 0, Path(r.run_dir, "companion.log").read_text()[-3000:]
    assert r.phase == "done"
    assert r.landed
    assert r.nearest_person_m >= CLEARANCE_M
    header, truth = read_truth(Path(r.run_dir) / "truth.jsonl")
    assert sum(header.moving) >= 10  # the walkers were there
    # Every zone the companion acted on lay wholly inside the area (to half a 0.1 m cell), and so did the touchdown
    # (0.5 m for the position controller).
    targets = [
        d["decision"]["target"]
        for d in _records(r.run_dir)
        if d["kind"] == "decision" and d["decision"]["target"] is not None
    ]
    assert targets
    for t in targets:
        assert max(abs(t["north_m"]), abs(t["east_m"])) + t["radius_m"] <= roi_half_m + 0.05, t
    down = touchdown(truth)
    assert down is not None
    assert max(abs(v) for v in down.position_ned_m[:2]) <= roi_half_m + 0.5
    # `slz report` draws the area on the top view.
    reported = subprocess.run(
        [sys.executable, "-m", "companion.cli", "report", str(Path(r.run_dir) / "flight")],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert reported.returncode == 0, reported.stderr[-3000:]
    assert (Path(r.run_dir) / "flight" / "report" / "top_view.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # What the pilot saw at the ground station, forwarded by the autopilot from the companion: every phase change as
    # a status text, the chosen target as LANDING_TARGET (the logged decisions' targets), the zone count and radius.
    companion = [m for m in gcs.messages if m.get_srcComponent() != 1]
    texts = [m.text for m in companion if m.get_type() == "STATUSTEXT"]
    phases = [p for _, p in _phases(r.run_dir)]
    assert [t.split(":")[0] for t in texts if t.startswith("SLZ ")] == [f"SLZ {p}" for p in phases]
    assert all(m.severity in (5, 6) for m in companion if m.get_type() == "STATUSTEXT")  # no failsafe here
    landing_targets = [m for m in companion if m.get_type() == "LANDING_TARGET"]
    assert landing_targets
    assert all(m.position_valid == 1 and m.frame == 1 for m in landing_targets)
    for m in landing_targets:  # each one a target a logged decision acted on (float32 on the wire)
        assert min(math.hypot(m.x - t["north_m"], m.y - t["east_m"]) for t in targets) < 1e-3, (m.x, m.y)
    values = {m.name for m in companion if m.get_type() == "NAMED_VALUE_FLOAT"}
    assert values == {"SLZ_ZONES", "SLZ_R_M", "SLZ_DRY"}
    assert max(m.value for m in companion if m.get_type() == "NAMED_VALUE_FLOAT" and m.name == "SLZ_ZONES") >= 1
    assert all(m.value == 0 for m in companion if m.get_type() == "NAMED_VALUE_FLOAT" and m.name == "SLZ_DRY")
    autopilot = {m.get_srcSystem() for m in gcs.of("HEARTBEAT") if m.get_srcComponent() == 1}
    assert len(autopilot) == 1
    assert {m.get_srcSystem() for m in companion} == autopilot  # one vehicle to the ground station, as on a drone


def test_a_lost_camera_holds_after_t1_then_lands_in_place_after_t2(tmp_path: Path, demo: Demo) -> None:
    # The demo's scene and seed, paced at 4x real time instead of full speed, the camera's cable pulled at 18 s:
    # its connection closed, no frame after it.
    fault = {"faults": [{"kind": "camera_disconnect", "at_s": FAULT_AT_S}], "speed_factor": 4.0}
    r = _fly(tmp_path, "camera", STATIC_SEED, sitl_overrides=fault)
    records = _records(r.run_dir)
    # Lockstep: the same seed decides the same at another speed, until the fault makes the flights differ.
    before = [x["decision"] for x in records if x["kind"] == "decision" and x["t_s"] < FAULT_AT_S]
    demo_before = [x["decision"] for x in _records(demo.run_dir) if x["kind"] == "decision" and x["t_s"] < FAULT_AT_S]
    assert len(before) > 30
    assert before == demo_before
    config = next(x for x in records if x["kind"] == "header")["config"]
    t1 = float(config["guidance"]["hold_after_silence_s"])
    t2 = float(config["guidance"]["failsafe_after_silence_s"])
    phases = _phases(r.run_dir)
    hold_at = next(t for t, p in phases if p == "hold")
    failsafe_at = next(t for t, p in phases if p == "failsafe")
    frame_period_s = 0.1
    assert FAULT_AT_S + t1 - frame_period_s <= hold_at <= FAULT_AT_S + t1 + 2 * frame_period_s
    assert FAULT_AT_S + t2 - frame_period_s <= failsafe_at <= FAULT_AT_S + t2 + 2 * frame_period_s
    commands = [x for x in records if x["kind"] == "command"]
    assert commands[-1]["command"] == "land"  # the configured T2 action
    assert r.phase == "failsafe"
    assert r.companion_exit_code == 3  # the failsafe's exit status: the systemd unit does not restart on it
    assert r.landed  # the autopilot landed where it was
    assert not [x for x in records if x["kind"] == "frame_result" and float(x["t_s"]) > FAULT_AT_S]
    # The companion named the fault in its log.
    camera_errors = [x for x in records if x["kind"] == "error" and x.get("where") == "camera"]
    assert [x["fault"] for x in camera_errors] == ["connection_lost"]
    assert "closed the connection" in camera_errors[0]["error"]
    end = next(x for x in records if x["kind"] == "end")
    assert end["outcome"]["camera_fault"] == "connection_lost"


def test_a_lost_link_stops_commanding_and_the_autopilot_failsafe_lands(tmp_path: Path) -> None:
    # COM_OBL_RC_ACT = 4 (land): the failsafe that ends the flight on its own (v1.15's default, position mode,
    # leaves a hovering vehicle to the pilot: tests/test_sitl_mavsdk.py).
    fault = {"faults": [{"kind": "link_loss", "at_s": FAULT_AT_S}], "params": {"COM_OBL_RC_ACT": 4}}
    r = _fly(tmp_path, "link", STATIC_SEED, sitl_overrides=fault)
    records = _records(r.run_dir)
    failsafes = [x for x in records if x["kind"] == "failsafe"]
    assert failsafes
    assert "link lost" in str(failsafes[-1]["reason"])
    lost_index = records.index(failsafes[-1])
    assert not [x for x in records[lost_index:] if x["kind"] == "command"]  # nothing sent once the link was lost
    end = next(x for x in records if x["kind"] == "end")
    assert end["outcome"]["link_lost"]
    # At the SITL's side: its own offboard-loss failsafe took over and landed the vehicle.
    _, truth = read_truth(Path(r.run_dir) / "truth.jsonl")
    modes_after = {t.mode for t in truth if t.t_s > FAULT_AT_S}
    assert "AUTO.LAND" in modes_after
    assert r.landed
    assert math.isfinite(r.touchdown_t_s or math.nan)
    # Issue 65: the flight an operator most needs a report of gets one, and slz report draws it.
    report = json.loads((Path(r.run_dir) / "flight" / "landing_report.json").read_text())
    assert report["outcome"] == "link_lost"
    assert "failsafe (autopilot)" in [e["event"] for e in report["decisions"]]
    from companion.tools.report import build_flight_report

    drawn = build_flight_report(Path(r.run_dir) / "flight", tmp_path / "report", video=False)
    assert drawn.files
