"""The ``slz`` command as a user runs it: a real process, real files."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.integration


def slz(*args: str, cwd: Path = REPO_ROOT, timeout_s: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "companion.cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
    )


SHIPPED_MISSIONS = ["sitl.yaml", "px4_serial.yaml", "px4_udp.yaml"]


@pytest.mark.parametrize("name", SHIPPED_MISSIONS)
def test_check_config_accepts_every_shipped_config(name: str) -> None:
    path = f"mission_configs/{name}"
    checked = slz("check-config", path, "--show")
    assert checked.returncode == 0, checked.stderr
    assert "valid for slz fly" in checked.stdout
    assert json.loads(checked.stdout.split("\n", 1)[1])["perception"]["zones"]["n_proposals"] == 10


def test_fly_accepts_every_shipped_config_and_then_fails_on_the_missing_camera(tmp_path: Path) -> None:
    # `slz fly` passes the same checks and only then fails, opening a camera that is not there (exit 1, not 2), after
    # camera.wait_for_s: the three run at once, so the suite waits that bound once.
    fly_argv = [sys.executable, "-m", "companion.cli", "fly", "--dry-run", "--timeout", "5"]
    flights = {
        name: subprocess.Popen(
            [*fly_argv, "--config", f"mission_configs/{name}", "--out", str(tmp_path / name)],
            cwd=REPO_ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for name in SHIPPED_MISSIONS
    }
    try:
        ended = {name: fly.communicate(timeout=120) for name, fly in flights.items()}
    finally:
        for fly in flights.values():
            if fly.poll() is None:
                fly.kill()
                fly.communicate(timeout=30)
    for name, (_, err) in ended.items():
        assert flights[name].returncode == 1, f"{name}: {err[-2000:]}"
        assert "invalid configuration" not in err, name
        assert "camera" in err or "cannot" in err, f"{name}: {err[-2000:]}"


def test_a_config_without_a_geofence_is_refused_for_fly_naming_the_fields(tmp_path: Path) -> None:
    # mission_configs/perception.yaml is the pipeline's parameters alone: no fence, so no flight on it.
    for path in ("mission_configs/perception.yaml", str(_mission(tmp_path, geofence="{min_altitude_m: 0.0}"))):
        checked = slz("check-config", path)
        flown = slz("fly", "--dry-run", "--config", path, "--out", str(tmp_path / "flight"))
        for result in (checked, flown):
            assert result.returncode == 2, result.stderr
            assert "geofence.polygon_ne_m or geofence.polygon_latlon_deg: required for slz fly" in result.stderr
            assert "geofence.max_altitude_m: required for slz fly" in result.stderr
        assert not (tmp_path / "flight" / "flight.jsonl").exists()


def test_a_fence_below_the_takeoff_and_search_altitudes_is_refused_naming_both_fields(tmp_path: Path) -> None:
    # The field report: max_altitude_m 10 with takeoff and search at 20 m was "valid"; flown, it climbed to 19.8 m,
    # then every setpoint was clamped to 10 m.
    low = _mission(
        tmp_path, geofence="{polygon_ne_m: [[-25, -25], [-25, 25], [25, 25], [25, -25]], max_altitude_m: 10}"
    )
    checked = slz("check-config", str(low))
    assert checked.returncode == 2, checked.stderr
    assert (
        "start.takeoff_altitude_m (20 m) must lie within geofence.min_altitude_m (0 m) and "
        "geofence.max_altitude_m (10 m)" in checked.stderr
    )
    assert "guidance.search_altitude_m (20 m) must lie within" in checked.stderr
    outside = _mission(tmp_path, start="{arm_and_takeoff: true, start_north_m: 40.0, start_east_m: 0.0}")
    checked = slz("check-config", str(outside))
    assert checked.returncode == 2, checked.stderr
    assert "start.start_north_m, start.start_east_m (40.0, 0.0) lie outside geofence.polygon_ne_m" in checked.stderr
    floor = _mission(
        tmp_path,
        geofence="{polygon_ne_m: [[-25, -25], [-25, 25], [25, 25], [25, -25]], min_altitude_m: 5, max_altitude_m: 40}",
    )
    checked = slz("check-config", str(floor))
    assert checked.returncode == 2, checked.stderr
    assert "geofence.min_altitude_m (5 m) lies above guidance.land_altitude_m (2 m" in checked.stderr


def test_the_last_resort_is_never_a_landing_in_place(tmp_path: Path) -> None:
    checked = slz("check-config", str(_mission(tmp_path, guidance="{last_resort: land}")))
    assert checked.returncode == 2, checked.stderr
    assert "last_resort: must be hold or return (got land)" in checked.stderr


def bad_configs(tmp_path: Path) -> dict[str, tuple[Path, list[str]]]:
    """Ten bad mission configs (and the extra arguments both commands get)."""
    from sitl.testing.hostile_configs import hostile_configs

    chosen = [
        "empty",
        "geofence_bow_tie",
        "start_north_nan",
        "max_altitude_negative",
        "duplicate_nested_key",
        "unknown_section",
        "alias_bomb_lists",
    ]
    out: dict[str, tuple[Path, list[str]]] = {}
    for hostile in hostile_configs():
        if hostile.name in chosen:
            path = tmp_path / f"{hostile.name}.yaml"
            path.write_bytes(hostile.content)
            out[hostile.name] = (path, [])
    shipped = (REPO_ROOT / "mission_configs" / "sitl.yaml").read_text()
    missing_model = tmp_path / "missing_model.yaml"
    missing_model.write_text(shipped + f"\nperception:\n  model:\n    path: {tmp_path / 'none.onnx'}\n")
    out["missing_model"] = (missing_model, [])
    iou = tmp_path / "iou.yaml"
    iou.write_text(shipped + "\nperception:\n  tracking:\n    iou_threshold: 1.5\n")
    out["iou_out_of_range"] = (iou, [])
    out["arms_under_never_arm"] = (REPO_ROOT / "mission_configs" / "sitl.yaml", ["--never-arm"])
    assert len(out) == 10
    return out


def test_check_config_gives_the_verdict_and_message_of_fly_on_ten_bad_configs(tmp_path: Path) -> None:
    for name, (path, extra) in bad_configs(tmp_path).items():
        checked = slz("check-config", str(path), *extra)
        flown = slz("fly", "--dry-run", "--config", str(path), *extra, "--out", str(tmp_path / name))
        assert checked.returncode == flown.returncode, (name, checked.stderr, flown.stderr)
        assert checked.returncode in (1, 2), (name, checked.stderr)
        problem = [line for line in checked.stderr.splitlines() if line.strip()][-1]
        assert problem in flown.stderr, (name, problem, flown.stderr[-2000:])
        assert "Traceback" not in checked.stderr + flown.stderr
    iou_message = slz("check-config", str(tmp_path / "iou.yaml")).stderr
    assert "perception.tracking.iou_threshold: Input should be less than or equal to 1 (got 1.5)" in iou_message


def test_demo_with_a_missing_model_fails_clearly(tmp_path: Path) -> None:
    config = tmp_path / "c.yaml"
    config.write_text(f"perception:\n  model:\n    path: {tmp_path / 'none.onnx'}\n")
    result = slz("demo", "--config", str(config), "--out", str(tmp_path / "out"))
    assert result.returncode == 1
    assert "density.load: model file not found" in result.stderr
    assert not (tmp_path / "out").exists()


def test_sitl_snapshot_writes_a_contact_sheet(tmp_path: Path) -> None:
    out = tmp_path / "sheet.png"
    result = slz("sitl", "snapshot", "--seed", "2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    import cv2

    sheet = cv2.imread(str(out))
    assert sheet is not None
    assert sheet.shape == (6 * 244, 3 * (2 * 320 + 4), 3)  # six conditions x three altitudes, frame + mask each
    assert sheet[:, 320:640].max() == 255  # the first mask column shows people


def _mission(tmp_path: Path, **sections: str) -> Path:
    """A mission config: mission_configs/sitl.yaml with some sections replaced (YAML snippets)."""
    import yaml

    mission = yaml.safe_load((REPO_ROOT / "mission_configs" / "sitl.yaml").read_text())
    for name, text in sections.items():
        mission[name] = yaml.safe_load(text)
    path = tmp_path / "mission.yaml"
    path.write_text(yaml.safe_dump(mission))
    return path


def test_fly_with_a_bad_value_names_the_field_and_starts_nothing(tmp_path: Path) -> None:
    config = _mission(tmp_path, guidance="descent_rate_limit_mps: 9.0")
    result = slz("fly", "--config", str(config), "--out", str(tmp_path / "flight"))
    assert result.returncode == 2
    assert "guidance.descent_rate_limit_mps" in result.stderr
    assert "less than or equal to 5" in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "flight").exists()


def test_fly_with_a_missing_model_fails_before_any_link(tmp_path: Path) -> None:
    config = _mission(tmp_path, perception=f"model: {{path: {tmp_path / 'none.onnx'}}}")
    result = slz("fly", "--config", str(config), "--out", str(tmp_path / "flight"))
    assert result.returncode == 1
    assert "model file not found" in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "flight").exists()


def test_fly_with_no_camera_waits_its_bound_saying_so_and_fails_before_touching_the_vehicle(tmp_path: Path) -> None:
    config = _mission(tmp_path, camera="{url: 'sitl://127.0.0.1:5999', wait_for_s: 1.5}")  # nobody serves frames there
    started = time.monotonic()
    result = slz("fly", "--config", str(config), "--out", str(tmp_path / "flight"), timeout_s=60)
    assert time.monotonic() - started < 30.0  # the bound, not for ever
    assert result.returncode == 1
    assert "waiting for the camera at sitl://127.0.0.1:5999" in result.stderr  # issue 65: said, not silent
    assert "sitl://127.0.0.1:5999: cannot connect" in result.stderr
    assert "Traceback" not in result.stderr
    records = [json.loads(line) for line in (tmp_path / "flight" / "flight.jsonl").read_text().splitlines()]
    assert records[-1]["kind"] == "error"
    assert "cannot connect" in records[-1]["error"]
    assert "command" not in [r["kind"] for r in records]


def test_fly_with_no_autopilot_says_so_within_the_connect_timeout(tmp_path: Path) -> None:
    import cv2
    import numpy as np

    video = tmp_path / "clip.avi"  # a camera that works: a short video file
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))  # type: ignore[attr-defined]
    for k in range(5):
        writer.write(np.full((48, 64, 3), 40 * k, np.uint8))
    writer.release()
    config = _mission(
        tmp_path,
        vehicle="{url: 'udpin://0.0.0.0:14999', connect_timeout_s: 2.0}",
        camera=f"url: 'file://{video}'",
    )
    result = slz("fly", "--config", str(config), "--out", str(tmp_path / "flight"), timeout_s=60)
    assert result.returncode == 1
    assert "udpin://0.0.0.0:14999" in result.stderr
    assert "no autopilot answered within 2 s" in result.stderr
    assert "Traceback" not in result.stderr


def test_fly_never_arm_refuses_a_config_that_takes_off(tmp_path: Path) -> None:
    result = slz("fly", "--config", "mission_configs/sitl.yaml", "--never-arm", "--out", str(tmp_path / "flight"))
    assert result.returncode == 2
    assert "start.arm_and_takeoff: must be false with --never-arm" in result.stderr
    assert not (tmp_path / "flight").exists()


def test_a_handover_mode_of_offboard_is_refused_by_name(tmp_path: Path) -> None:
    config = tmp_path / "mission.yaml"
    config.write_text("start:\n  handover_modes: [OFFBOARD]\n")
    result = slz("fly", "--config", str(config), "--out", str(tmp_path / "flight"))
    assert result.returncode == 2
    assert "start.handover_modes" in result.stderr
    assert "must not list OFFBOARD" in result.stderr


def test_report_of_a_missing_flight_says_so(tmp_path: Path) -> None:
    result = slz("report", str(tmp_path / "nothing"))
    assert result.returncode == 1
    assert f"no flight log at {tmp_path / 'nothing' / 'flight.jsonl'}" in result.stderr
    assert "Traceback" not in result.stderr


def test_help_names_each_default() -> None:
    doctor = slz("doctor", "--help")
    assert doctor.returncode == 0
    assert "camera frames to read (default: 10)" in " ".join(doctor.stdout.split())
    demo = slz("demo", "--help")  # a plugin's command (sitl.cli) gets the same help
    assert "the seed of the scene and the mission (default: 1)" in " ".join(demo.stdout.split())
    sitl = slz("sitl", "--help")
    assert "--camera, --no-camera" in sitl.stdout


def test_a_configs_relative_paths_are_taken_from_its_folder_wherever_slz_runs(tmp_path: Path) -> None:
    import shutil

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    # The shipped configs, checked from another working directory (the field report: "model file not found").
    for name, extra in (("sitl.yaml", []), ("px4_serial.yaml", ["--never-arm"])):
        checked = slz("check-config", str(REPO_ROOT / "mission_configs" / name), *extra, cwd=elsewhere)
        assert checked.returncode == 0, checked.stderr
    # A config of one's own beside a model of one's own, relative paths in it.
    site = tmp_path / "site"
    (site / "nets").mkdir(parents=True)
    shutil.copy(REPO_ROOT / "models" / "density" / "slz_lite_int8.onnx", site / "nets" / "mine.onnx")
    config = site / "mission.yaml"
    shipped = (REPO_ROOT / "mission_configs" / "sitl.yaml").read_text()
    config.write_text(shipped + "perception:\n  model:\n    path: nets/mine.onnx\n")
    checked = slz("check-config", str(config), "--show", cwd=elsewhere)
    assert checked.returncode == 0, checked.stderr
    assert "model mine.onnx" in checked.stdout
    shown = json.loads(checked.stdout.split("\n", 1)[1])
    assert shown["perception"]["model"]["path"] == str(site / "nets" / "mine.onnx")
    assert shown["recorder"]["directory"] == str(tmp_path / "runs" / "flights")  # sitl.yaml's ../runs/flights
