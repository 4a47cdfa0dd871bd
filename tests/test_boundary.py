"""The drone package knows nothing of the lab: ``companion`` never imports ``sitl``, ``models`` or ``tests``, and
``slz`` on a drone's install (only the companion and its own dependencies) lists the drone's commands and works."""

from __future__ import annotations

import ast
import json
import os
import re
import shutil
import subprocess
import sys
import venv
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement

REPO_ROOT = Path(__file__).resolve().parent.parent
LAB = ("sitl", "models", "tests")
DRONE_COMMANDS = {"check-config", "fly", "doctor", "replay", "report", "export", "height-map", "serve"}
LAB_COMMANDS = {"sitl", "demo", "campaign"}


def companion_modules() -> list[str]:
    return sorted(
        ".".join(path.relative_to(REPO_ROOT).with_suffix("").parts).removesuffix(".__init__")
        for path in (REPO_ROOT / "companion").rglob("*.py")
    )


@pytest.mark.unit
def test_no_companion_source_imports_the_lab_even_lazily() -> None:
    offenders = []
    for path in sorted((REPO_ROOT / "companion").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            offenders += [f"{path.relative_to(REPO_ROOT)}:{node.lineno} {n}" for n in names if n.split(".")[0] in LAB]
    assert offenders == []


@pytest.mark.integration
def test_importing_every_drone_module_in_a_clean_interpreter_loads_no_lab_module() -> None:
    script = (
        "import importlib, json, sys\n"
        f"for name in {companion_modules()!r}:\n"
        "    importlib.import_module(name)\n"
        "from companion.cli import build_parser\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
        f"{LAB!r})))\n"
    )
    # The lab's plugin is what adds lab commands; without entry points (a plain source tree) nothing loads it.
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    run = subprocess.run(
        [sys.executable, "-c", script], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120, env=env
    )
    assert run.returncode == 0, run.stderr[-3000:]
    assert json.loads(run.stdout.strip().splitlines()[-1]) == []


def drone_closure() -> set[str]:
    """The distributions the companion needs: pyproject's ``dependencies`` and theirs, markers evaluated here."""
    text = (REPO_ROOT / "pyproject.toml").read_text()
    block = re.search(r"^dependencies = \[(.*?)^\]", text, re.S | re.M)
    assert block is not None
    todo = [Requirement(r) for r in re.findall(r'"([^"]+)"', block.group(1))]
    seen: set[str] = set()
    while todo:
        req = todo.pop()
        if req.marker is not None and not req.marker.evaluate({"extra": ""}):
            continue
        name = req.name.lower().replace("_", "-")
        if name in seen:
            continue
        seen.add(name)
        todo += [Requirement(r) for r in metadata.requires(req.name) or []]
    return seen


def link_distributions(names: set[str], into: Path) -> None:
    """Symlink every top-level file and folder of each installed distribution into ``into``."""
    into.mkdir(parents=True)
    for name in names:
        dist = metadata.distribution(name)
        roots = {Path(str(f)).parts[0] for f in dist.files or [] if not str(f).startswith("..")}
        for root in roots:
            source = Path(str(dist.locate_file(root)))
            target = into / root
            if source.exists() and not target.exists() and root != "__pycache__":
                target.symlink_to(source)


@pytest.mark.integration
def test_slz_on_a_drone_install_lists_only_drone_commands_and_runs_them(tmp_path: Path) -> None:
    # The container's layout: the companion and its models, no sitl package; a venv with only the drone's
    # dependencies (the dev venv's installed copies, linked, so nothing is downloaded).
    project = tmp_path / "drone"
    shutil.copytree(REPO_ROOT / "companion", project / "companion", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(REPO_ROOT / "models" / "density", project / "models" / "density")
    shutil.copytree(REPO_ROOT / "mission_configs", project / "mission_configs")
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=False)
    site = next((env_dir / "lib").glob("python3*/site-packages"))
    names = drone_closure()
    assert "pymavlink" not in names
    assert "pyrender" not in names
    link_distributions(names, tmp_path / "drone_deps")
    (site / "drone_deps.pth").write_text(f"{tmp_path / 'drone_deps'}\n")
    python = env_dir / "bin" / "python"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}

    def slz(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [str(python), "-m", "companion.cli", *args],
            cwd=project,
            capture_output=True,
            text=True,
            timeout=120,
            env=env,
        )

    shown = slz("--help")
    assert shown.returncode == 0, shown.stderr[-3000:]
    listed = set(re.search(r"\{([a-z,-]+)\}", shown.stdout).group(1).split(","))  # type: ignore[union-attr]
    assert listed == DRONE_COMMANDS
    for lab in LAB_COMMANDS:
        missing = slz(lab, "--help")
        assert missing.returncode == 2  # argparse: an unknown command, not a ModuleNotFoundError
        assert "invalid choice" in missing.stderr
        assert "Traceback" not in missing.stderr
    checked = slz("check-config", "mission_configs/px4_serial.yaml")
    assert checked.returncode == 0, checked.stderr[-3000:]
    assert "valid for slz fly" in checked.stdout


@pytest.mark.integration
def test_the_dev_install_adds_the_lab_commands_through_the_plugin() -> None:
    run = subprocess.run(
        [sys.executable, "-m", "companion.cli", "--help"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0
    listed = set(re.search(r"\{([a-z,-]+)\}", run.stdout).group(1).split(","))  # type: ignore[union-attr]
    assert listed == DRONE_COMMANDS | LAB_COMMANDS
