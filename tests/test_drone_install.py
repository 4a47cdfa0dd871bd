"""The drone's install on the Jetson's Python: requirements/drone.lock in a CPython 3.10 venv (JetPack 6 ships 3.10),
then the companion's copy with nothing unlocked, as deploy/jetson/install.sh does it (without the GPU onnxruntime).

The lock's CPython 3.10 line (numpy, scipy, onnxruntime older than the 3.11 line the rest of the suite tests) runs
the companion here: the config checks, the README's perception example on the shipped model, and a flight recorded
by this suite's own interpreter replayed decision by decision. Slow (a venv and about 150 MB of wheels, a SITL
mission): in ``make test-slow``. Skipped where no CPython 3.10 is found.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.integration]

REPO_ROOT = Path(__file__).resolve().parent.parent


def find_python_3_10() -> str | None:
    """A CPython 3.10 that runs and has venv: $SLZ_PYTHON_3_10, python3.10 on PATH, or a pyenv installation."""
    candidates = [os.environ.get("SLZ_PYTHON_3_10"), shutil.which("python3.10"), "/usr/bin/python3.10"]
    pyenv_root = Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv"))
    candidates += [str(p) for p in sorted(pyenv_root.glob("versions/3.10*/bin/python3.10"), reverse=True)]
    probe = "import sys, venv; sys.exit(sys.version_info[:2] != (3, 10))"
    for candidate in candidates:
        if candidate and Path(candidate).is_file():
            done = subprocess.run([candidate, "-c", probe], capture_output=True, timeout=30, check=False)
            if done.returncode == 0:
                return candidate
    return None


PYTHON_3_10 = find_python_3_10()


def run(command: list[str], cwd: Path = REPO_ROOT, timeout_s: float = 600) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    env.pop("PYTHONPATH", None)
    return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=timeout_s, env=env, check=False)


def readme_python_example() -> str:
    text = (REPO_ROOT / "README.md").read_text()
    match = re.search(r"^```python\n(.*?)^```", text, re.S | re.M)
    assert match is not None
    return match.group(1)


@pytest.fixture(scope="module")
def drone_venv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A CPython 3.10 venv holding exactly the drone lock's 3.10 pins for this machine, and the project."""
    if PYTHON_3_10 is None:
        pytest.skip("no CPython 3.10 here (python3.10, pyenv, $SLZ_PYTHON_3_10): the Jetson's Python cannot be tried")
    where = tmp_path_factory.mktemp("drone")
    venv = where / "venv"
    assert run([PYTHON_3_10, "-m", "venv", str(venv)]).returncode == 0
    python = str(venv / "bin" / "python")
    machine, lock = os.uname().machine, "requirements/drone.lock"
    pins = run([sys.executable, "scripts/lock.py", "for-target", "--machine", machine, "--python", "3.10", lock])
    assert pins.returncode == 0, pins.stderr
    (where / "pins.txt").write_text(pins.stdout)
    done = run([python, "-m", "pip", "install", "--quiet", "--require-hashes", "--no-deps", "-r", "pins.txt"], where)
    assert done.returncode == 0, done.stderr[-3000:]
    # What deploy/jetson/install.sh copies to the drone: the companion, its models and configs, no lab.
    source = where / "src"
    for part in ("companion", "models", "mission_configs"):
        shutil.copytree(REPO_ROOT / part, source / part, ignore=shutil.ignore_patterns("__pycache__"))
    for part in ("pyproject.toml", "README.md"):
        shutil.copy(REPO_ROOT / part, source / part)
    done = run([python, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation", str(source)])
    assert done.returncode == 0, done.stderr[-3000:]
    assert run([python, "-m", "pip", "check"]).returncode == 0
    # The venv is the lock's 3.10 line exactly (the lock tool's own needs, packaging, are in the drone's lock).
    check = run([python, "scripts/lock.py", "check", lock])
    assert check.returncode == 0, check.stdout + check.stderr
    return venv


def test_the_drone_commands_and_the_readme_example_run_on_python_3_10(drone_venv: Path) -> None:
    slz = str(drone_venv / "bin" / "slz")
    helped = run([slz, "--help"])
    assert helped.returncode == 0
    assert "fly" in helped.stdout
    assert "campaign" not in helped.stdout
    checked = run([slz, "check-config", "mission_configs/px4_serial.yaml", "--never-arm"])
    assert checked.returncode == 0, checked.stderr[-2000:]
    example = run([str(drone_venv / "bin" / "python"), "-c", readme_python_example()])
    assert example.returncode == 0, example.stderr[-2000:]
    assert "target: Target(" in example.stdout


def test_python_3_10_replays_a_flight_recorded_on_this_interpreter(drone_venv: Path, tmp_path: Path) -> None:
    # The same frame results and decisions from the 3.10 line of numpy, scipy and onnxruntime as from the line
    # that flew (this suite's interpreter).
    demo = run([sys.executable, "-m", "companion.cli", "demo", "--seed", "1", "--out", str(tmp_path / "runs")])
    assert demo.returncode == 0, demo.stderr[-3000:]
    flights = sorted((tmp_path / "runs").glob("*/flight"))
    assert len(flights) == 1
    replay = run([str(drone_venv / "bin" / "slz"), "replay", str(flights[0])])
    assert replay.returncode == 0, (replay.stdout[-3000:], replay.stderr[-3000:])
    counts = re.search(r"(\d+) frames, (\d+) decisions replayed: 0 frame and 0 decision differences", replay.stdout)
    assert counts is not None, replay.stdout
    assert int(counts.group(1)) >= 20  # a whole mission's frames
    assert int(counts.group(2)) >= 20
    assert replay.stdout.rstrip().endswith("identical")
