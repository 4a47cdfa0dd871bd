"""`slz doctor` against the SITL: every check passes on a good board, and each missing part fails with its own line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from sitl.harness.process import SitlProcess
from sitl.testing.helpers import sitl_mission_yaml

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent


def doctor(config: Path) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "companion.cli", "doctor", "--config", str(config), "--frames", "5"]
    return subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)


def lines_of(run: subprocess.CompletedProcess[str]) -> dict[str, str]:
    """The report's lines by check name: {"model": "PASS model: ...", ...}."""
    checks = {}
    for line in run.stdout.splitlines():
        status, _, rest = line.partition(" ")
        if status in ("PASS", "WARN", "FAIL", "SKIP"):
            checks[rest.split(":", 1)[0]] = line
    return checks


def mission_config(tmp_path: Path, instance: int, name: str, **replace: str) -> Path:
    """mission_configs/sitl.yaml on this test's SITL instance, free running, with ``replace`` applied."""
    text = sitl_mission_yaml(instance, flights_dir=tmp_path / "flights")
    text = text.replace("connect_timeout_s: 20.0", "connect_timeout_s: 3.0")
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return path


def test_doctor_passes_a_good_board_and_names_each_missing_part(tmp_path: Path, instance: int) -> None:
    sitl_config = tmp_path / "sitl.yaml"  # offboard loss holds: what deploy/README.md asks of a vehicle over people
    sitl_config.write_text("sitl:\n  camera:\n    enabled: true\n  seed: 2\n  params: {COM_OBL_RC_ACT: 5}\n")
    lands_config = tmp_path / "sitl_lands.yaml"  # offboard loss lands in place (v1.13's default; 4 on v1.15)
    lands_config.write_text("sitl:\n  camera:\n    enabled: true\n  seed: 2\n  params: {COM_OBL_RC_ACT: 4}\n")
    good = mission_config(tmp_path, instance, "good")
    no_model_no_camera = mission_config(
        tmp_path,
        instance,
        "broken",
        **{
            f"sitl://127.0.0.1:{5600 + instance}": "sitl://127.0.0.1:9",  # nothing listens on the discard port
            "recorder:": "perception:\n  model:\n    path: models/density/missing.onnx\nrecorder:",
        },
    )
    no_link = mission_config(  # and a vehicle that must fly a model validated on real imagery
        tmp_path,
        instance,
        "no_link",
        **{
            f"udpin://0.0.0.0:{14540 + instance}": "udpin://0.0.0.0:14539",
            "recorder:": "perception:\n  model:\n    require_real_imagery_validation: true\nrecorder:",
        },
    )
    sitl = SitlProcess(["--config", str(sitl_config)], instance, tmp_path).start()
    try:
        ok = doctor(good)
        unlinked = doctor(no_link)
    finally:
        sitl.stop()
    sitl = SitlProcess(["--config", str(lands_config)], instance, tmp_path).start()
    try:
        broken = doctor(no_model_no_camera)
    finally:
        sitl.stop()

    # A good board: every check passes, exit 0; the shipped model is flagged: it is not validated on real imagery.
    checks = lines_of(ok)
    assert ok.returncode == 0, ok.stdout + ok.stderr[-2000:]
    assert set(checks) == {"disk", "model", "validation", "link", "clock", "camera", "failsafe"}
    assert all(line.startswith("PASS") for name, line in checks.items() if name != "validation"), checks
    assert checks["validation"].startswith(
        "WARN validation: slz_yolox.onnx is NOT validated for flight over real people"
    )
    assert "fly a dry run first" in checks["validation"]
    assert "Retrying failed" not in ok.stdout + ok.stderr  # no parameter asked for by a name the autopilot lacks
    assert "CPUExecutionProvider" in checks["model"]
    assert "LOCAL_POSITION_NED" in checks["link"]
    assert "ATTITUDE_QUATERNION" in checks["link"]
    assert "5 frames 640x480" in checks["camera"]
    assert "COM_OF_LOSS_T = 1 s" in checks["failsafe"]
    assert "COM_OBL_RC_ACT = 5 (hold)" in checks["failsafe"]
    assert ok.stdout.rstrip().endswith("ready to fly")

    # No model and no camera: each named, the link still checked and passing, exit 1.
    checks = lines_of(broken)
    assert broken.returncode == 1
    assert checks["model"].startswith("FAIL model:")
    assert "missing.onnx" in checks["model"]
    assert checks["camera"].startswith("FAIL camera:")
    assert "127.0.0.1:9" in checks["camera"]
    assert checks["link"].startswith("PASS")
    assert "NOT READY: model, camera failed" in broken.stdout
    # ...and on an autopilot whose offboard-loss action lands in place, the failsafe line warns and names it.
    assert checks["failsafe"].startswith("WARN failsafe:"), checks["failsafe"]
    assert "COM_OBL_RC_ACT = 4 (land)" in checks["failsafe"]
    assert "COM_OBL_RC_ACT lands in place" in checks["failsafe"]

    # No autopilot on the configured port: the link fails within its timeout, the clock cannot be checked.
    checks = lines_of(unlinked)
    assert unlinked.returncode == 1
    assert checks["link"] == "FAIL link: udpin://0.0.0.0:14539: no autopilot answered within 3 s"
    assert checks["clock"].startswith("SKIP clock:")
    assert checks["failsafe"].startswith("SKIP failsafe:")
    verdict = unlinked.stdout.rstrip().splitlines()[-1]  # what failed, and apart from it what was not checked
    assert verdict.startswith("NOT READY: validation, link"), verdict
    assert verdict.endswith("failsafe not checked"), verdict
    assert checks["model"].startswith("PASS")
    assert checks["validation"].startswith(
        "FAIL validation: slz_yolox.onnx is NOT validated for flight over real people"
    )


def test_doctor_switches_the_warning_device_on_the_bench_and_back_off(tmp_path: Path, instance: int) -> None:
    # Issue 65: the warning device could not be checked before a flight: its switches appeared only in the log.
    sitl_config = tmp_path / "sitl.yaml"
    sitl_config.write_text("sitl:\n  camera:\n    enabled: true\n  seed: 2\n  params: {COM_OBL_RC_ACT: 5}\n")
    config = mission_config(
        tmp_path, instance, "siren", **{"guidance:\n": "guidance:\n  warning: {enabled: true, actuator: 1}\n"}
    )
    sitl = SitlProcess(["--config", str(sitl_config)], instance, tmp_path).start()
    try:
        command = [sys.executable, "-m", "companion.cli", "doctor", "--config", str(config), "--frames", "3"]
        run = subprocess.run([*command, "--actuator-test"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
        warning = sitl.state()["warning"]
    finally:
        sitl.stop()
    checks = lines_of(run)
    assert checks["actuator"].startswith("PASS actuator: Offboard Actuator Set 1 switched to 1 for 2 s, then -1")
    assert warning["times_on"] == 1  # it sounded once, on the SITL's side
    assert warning["on"] is False  # and is off again
