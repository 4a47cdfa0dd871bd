"""What can be checked of the deployment here, without a Jetson.

- The drone's lock (requirements/drone.lock) resolves for the drone: aarch64, CPython 3.10 (JetPack 6), binary wheels
  only, each with a hash in the lock. A pip resolve for that platform from the package registry, nothing installed;
  the container and the Jetson install use that lock.
- The systemd unit passes ``systemd-analyze verify`` and keeps the rules that make it safe on a vehicle.
- The install script passes ``shellcheck`` and refuses a machine that is not a Jetson.
- The GitHub workflow runs the tests on push and the gated nightly campaign.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from packaging.utils import canonicalize_name

pytestmark = pytest.mark.unit

REPO_ROOT = Path(__file__).resolve().parent.parent
UNIT = REPO_ROOT / "deploy" / "systemd" / "slz-lander.service"
INSTALL = REPO_ROOT / "deploy" / "jetson" / "install.sh"
# JetPack 6 is Ubuntu 22.04: glibc 2.35, so any manylinux tag up to 2.35 runs there.
LOCK_TOOL = REPO_ROOT / "scripts" / "lock.py"
DRONE_LOCK = REPO_ROOT / "requirements" / "drone.lock"
AARCH64_PLATFORMS = ["manylinux2014_aarch64", *(f"manylinux_2_{minor}_aarch64" for minor in range(17, 36))]


def test_the_drone_lock_resolves_for_aarch64_python_3_10_with_its_hashes(tmp_path: Path) -> None:
    # The Jetson's pins (markers resolved for aarch64, CPython 3.10: pip evaluates markers for the interpreter it
    # runs on, not the --platform it is given), each a wheel the Jetson can load whose hash is in the lock.
    pins = tmp_path / "drone-aarch64-cp310.txt"
    done = subprocess.run(
        [sys.executable, str(LOCK_TOOL), "for-target", "--machine", "aarch64", "--python", "3.10", str(DRONE_LOCK)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    pins.write_text(done.stdout)
    platforms = [arg for p in AARCH64_PLATFORMS for arg in ("--platform", p)]
    report = tmp_path / "resolve.json"
    command = [sys.executable, "-m", "pip", "install", "--dry-run", "--ignore-installed", "--quiet", "--no-deps"]
    command += ["--require-hashes", "--report", str(report), "--only-binary=:all:", "--python-version", "3.10"]
    command += ["--implementation", "cp", "--abi", "cp310", "--abi", "abi3", "--abi", "none", *platforms]
    command += ["-r", str(pins)]
    env = {**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    done = subprocess.run(command, capture_output=True, text=True, timeout=600, env=env, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    installed = {
        canonicalize_name(item["metadata"]["name"]): item for item in json.loads(report.read_text())["install"]
    }
    pinned = [line.split("==")[0] for line in pins.read_text().splitlines() if line.strip()]
    assert sorted(installed) == sorted(pinned)  # every pin, nothing more
    for requirement in ("numpy", "onnxruntime", "opencv-python-headless", "mavsdk", "scipy", "pydantic", "pyyaml"):
        assert requirement in installed, sorted(installed)
    for name, item in installed.items():  # every wheel is one the Jetson can load
        wheel = item["download_info"]["url"].rsplit("/", 1)[-1]
        assert wheel.endswith("-any.whl") or "aarch64" in wheel, (name, wheel)


def test_the_container_and_the_jetson_install_the_drone_lock() -> None:
    dockerfile = (REPO_ROOT / "deploy" / "container" / "Dockerfile").read_text()
    install = INSTALL.read_text()
    for text in (dockerfile, install):
        assert "--require-hashes" in text
        assert "requirements/drone.lock" in text
        assert "--no-deps --no-build-isolation" in text  # the project itself adds nothing unlocked
        assert "--upgrade pip" not in text


def test_the_systemd_unit_verifies_and_cannot_loop_a_vehicle_into_takeoffs(tmp_path: Path) -> None:
    # An image of the target: the unit in /etc/systemd/system, the host's system units, and the venv's entry point.
    root = tmp_path / "root"
    (root / "etc" / "systemd" / "system").mkdir(parents=True)
    shutil.copy(UNIT, root / "etc" / "systemd" / "system" / UNIT.name)
    for units in (Path("/usr/lib/systemd/system"), Path("/lib/systemd/system")):
        if units.is_dir():
            shutil.copytree(units, root / "usr" / "lib" / "systemd" / "system", symlinks=True, dirs_exist_ok=True)
            break
    entry = root / "opt" / "slz" / "venv" / "bin" / "slz"
    entry.parent.mkdir(parents=True)
    entry.write_text("#!/bin/sh\n")
    entry.chmod(entry.stat().st_mode | stat.S_IXUSR)
    done = subprocess.run(
        ["systemd-analyze", "verify", f"--root={root}", "--man=no", UNIT.name],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    # systemd-analyze exits 0 on a misspelt setting and only says so: any output is a failure.
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == ""
    assert done.stderr.strip() == ""

    settings: dict[str, list[str]] = {}
    for line in UNIT.read_text().splitlines():
        if "=" in line and not line.lstrip().startswith("#"):
            key, _, value = line.partition("=")
            settings.setdefault(key.strip(), []).append(value.strip())
    exec_start = settings["ExecStart"][0]
    assert "--never-arm" in exec_start  # a restart can never take off
    assert "--dry-run" not in exec_start
    assert settings["Restart"] == ["on-failure"]  # a finished flight (exit 0) is not restarted
    assert settings["RestartPreventExitStatus"] == ["3"]  # nor one that handed the vehicle over in a failsafe
    assert int(settings["StartLimitBurst"][0]) <= 3
    assert settings["StandardOutput"] == ["journal"]
    assert settings["NoNewPrivileges"] == ["yes"]
    assert settings["ProtectSystem"] == ["strict"]
    assert settings["ReadWritePaths"] == ["/var/lib/slz"]


def test_the_field_config_never_arms_and_keeps_logs_on_the_persistent_path() -> None:
    from companion.app.mission import load_mission_config

    config = load_mission_config(REPO_ROOT / "mission_configs" / "px4_serial.yaml")
    assert not config.start.arm_and_takeoff
    assert [m.value for m in config.start.handover_modes] == ["HOLD"]
    assert str(config.recorder.directory).startswith("/var/lib/slz")  # the unit's ReadWritePaths
    assert config.recorder.keep_flights > 0
    assert config.perception.model.engine_cache_dir is not None
    assert str(config.perception.model.engine_cache_dir).startswith("/var/lib/slz")


def test_the_shell_scripts_pass_shellcheck() -> None:
    scripts = [INSTALL, REPO_ROOT / "scripts" / "install-system-deps.sh", REPO_ROOT / ".ci" / "run"]
    scripts += sorted((REPO_ROOT / "scripts").glob("*.sh"))
    done = subprocess.run(
        ["shellcheck", "--shell=bash", *sorted({str(s) for s in scripts})],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stdout[-3000:]


def test_the_install_script_refuses_a_machine_that_is_not_a_jetson() -> None:
    if os.uname().machine == "aarch64":
        pytest.skip("this machine is aarch64: the refusal is for the others")
    done = subprocess.run(["bash", str(INSTALL), "--dry-run"], capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 1
    assert f"this is {os.uname().machine}" in done.stderr
    assert "Jetson (aarch64)" in done.stderr


def test_the_github_workflow_tests_on_push_and_gates_a_nightly_campaign() -> None:
    workflow = yaml.safe_load((REPO_ROOT / ".github" / "workflows" / "ci.yml").read_text())
    triggers = workflow[True] if True in workflow else workflow["on"]  # YAML 1.1 reads the key `on` as True
    assert "push" in triggers
    assert "schedule" in triggers
    test_steps = [step.get("run", "") for step in workflow["jobs"]["test"]["steps"]]
    assert "make test" in test_steps
    nightly = workflow["jobs"]["nightly-campaign"]["steps"]
    campaign = next(step["run"] for step in nightly if "slz campaign" in step.get("run", ""))
    assert "--check-against mission_configs/campaigns/baselines/smoke.json" in campaign
    assert (REPO_ROOT / "mission_configs" / "campaigns" / "baselines" / "smoke.json").is_file()
    upload = next(step for step in nightly if step.get("uses", "").startswith("actions/upload-artifact"))
    assert upload["if"] == "always()"
    latest = [step.get("run", "") for step in workflow["jobs"]["latest-releases"]["steps"]]
    assert "make test-latest" in latest  # the newest releases, tested apart from the lock


def test_tensorrt_gets_fp16_and_a_persistent_engine_cache_and_the_others_nothing(tmp_path: Path) -> None:
    from companion.perception.density import execution_provider_options

    cache = tmp_path / "trt-cache"
    options = execution_provider_options("TensorrtExecutionProvider", cache, fp16=True)
    assert options == {
        "trt_fp16_enable": "True",
        "trt_engine_cache_enable": "True",
        "trt_engine_cache_path": str(cache),
        "trt_timing_cache_enable": "True",
        "trt_timing_cache_path": str(cache),
    }
    assert execution_provider_options("TensorrtExecutionProvider", None, fp16=False) == {"trt_fp16_enable": "False"}
    assert execution_provider_options("CUDAExecutionProvider", cache, fp16=True) == {}
    assert execution_provider_options("CPUExecutionProvider", cache, fp16=True) == {}


def test_a_missing_accelerator_falls_back_to_the_cpu_and_says_so(caplog: pytest.LogCaptureFixture) -> None:
    from companion.perception.density import OnnxDensityModel

    wanted = ["TensorrtExecutionProvider", "CUDAExecutionProvider", "CPUExecutionProvider"]
    with caplog.at_level("WARNING", logger="companion.perception.density"):
        model = OnnxDensityModel(REPO_ROOT / "models" / "density" / "slz_lite.onnx", wanted, engine_cache_dir=None)
    if model.providers[0] != "CPUExecutionProvider":
        pytest.skip(f"this machine has {model.providers[0]}")
    assert "falls back to CPUExecutionProvider: TensorrtExecutionProvider is the first choice" in caplog.text
