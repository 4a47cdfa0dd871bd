"""The dependency locks (requirements/*.lock, written by scripts/lock.py): complete, hashed, in step with
pyproject.toml and with one another, and the drone's free of the lab.

That the running environment *is* the dev lock is checked by ``make test`` itself (``make lockcheck``), since
``make test-latest`` runs this same suite on other versions on purpose.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

pytestmark = pytest.mark.unit

REPO_ROOT = Path(__file__).resolve().parent.parent

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - CPython 3.10 (the dev lock pins tomli there)
    import tomli as tomllib  # type: ignore[import-not-found, unused-ignore]


def load_lock_tool() -> ModuleType:
    """scripts/lock.py as a module (scripts/ is not a package)."""
    spec = importlib.util.spec_from_file_location("slz_lock_tool", REPO_ROOT / "scripts" / "lock.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


lock = load_lock_tool()


environment = lock.target_environment


# Where each lock must install: the Jetson (aarch64, JetPack 6's CPython 3.10), this project's machines and CI
# (x86-64, 3.11), and the Pythons a laptop may have. The training lock is for this project's machines alone.
TARGETS = {
    "dev": [("x86_64", "3.10"), ("x86_64", "3.11"), ("x86_64", "3.12"), ("x86_64", "3.13"), ("aarch64", "3.11")],
    "drone": [("aarch64", "3.10"), ("x86_64", "3.10"), ("x86_64", "3.11"), ("x86_64", "3.12")],
    "ray": [("x86_64", "3.10"), ("x86_64", "3.11"), ("x86_64", "3.12"), ("aarch64", "3.11")],
    "training": [("x86_64", "3.11")],
}


def pyproject() -> dict[str, object]:
    with (REPO_ROOT / "pyproject.toml").open("rb") as f:
        data: dict[str, object] = tomllib.load(f)["project"]
    return data


def project_requirements(extras: tuple[str, ...]) -> list[Requirement]:
    """What installing the project with ``extras`` asks for: its dependencies, the extras' (self-references
    such as ``slz-lander[sitl,ray]`` followed), and requirements/build.in."""
    project = pyproject()
    optional = project["optional-dependencies"]
    assert isinstance(optional, dict)
    todo = [Requirement(r) for r in project["dependencies"]]  # type: ignore[attr-defined]
    seen_extras: set[str] = set()
    pending = list(extras)
    while pending:
        extra = pending.pop()
        if extra in seen_extras:
            continue
        seen_extras.add(extra)
        for text in optional[extra]:
            requirement = Requirement(text)
            if canonicalize_name(requirement.name) == "slz-lander":
                pending += sorted(requirement.extras)
            else:
                todo.append(requirement)
    for line in (REPO_ROOT / "requirements" / "build.in").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            todo.append(Requirement(line))
    return todo


@pytest.mark.parametrize("name", sorted(lock.LOCKS))
def test_every_lock_pins_and_hashes_every_distribution_once_per_target(name: str) -> None:
    pins = lock.read_lock(lock.LOCKS[name].path)  # raises on an unpinned or unhashed line
    assert all(len(pin.hashes) >= 1 for pin in pins)
    for machine, python in TARGETS[name]:
        chosen = lock.pins_for(pins, environment(machine, python))  # raises on two versions of one package
        assert len(chosen) >= 10, (machine, python)


@pytest.mark.parametrize("name", sorted(lock.LOCKS))
def test_every_lock_satisfies_what_pyproject_asks_for(name: str) -> None:
    spec = lock.LOCKS[name]
    pins = lock.read_lock(spec.path)
    for machine, python in TARGETS[name]:
        env = environment(machine, python)
        chosen = lock.pins_for(pins, env)
        unmet = []
        for requirement in project_requirements(spec.extras):
            if requirement.marker is not None and not requirement.marker.evaluate(env):
                continue
            version = chosen.get(canonicalize_name(requirement.name))
            if version is None or not requirement.specifier.contains(version, prereleases=True):
                unmet.append(f"{requirement} (locked: {version})")
        assert unmet == [], f"{spec.path.name} on {machine} CPython {python}: run `make lock`"


@pytest.mark.parametrize("name", ["drone", "ray", "training"])
def test_a_lock_shares_the_versions_the_dev_lock_tested(name: str) -> None:
    dev_pins = lock.read_lock(lock.LOCKS["dev"].path)
    pins = lock.read_lock(lock.LOCKS[name].path)
    for machine, python in TARGETS[name]:
        env = environment(machine, python)
        tested = lock.pins_for(dev_pins, env)
        chosen = lock.pins_for(pins, env)
        differing = {p: (v, tested[p]) for p, v in chosen.items() if p in tested and tested[p] != v}
        assert differing == {}, (machine, python)


def test_the_training_lock_takes_the_cpu_build_of_torch() -> None:
    chosen = lock.pins_for(lock.read_lock(lock.LOCKS["training"].path), environment("x86_64", "3.11"))
    assert chosen["torch"] == "2.13.0+cpu"
    assert not any(name.startswith("nvidia-") for name in chosen)  # no CUDA runtime packages


def test_the_drone_lock_holds_nothing_of_the_lab() -> None:
    pins = lock.read_lock(lock.LOCKS["drone"].path)
    for machine, python in TARGETS["drone"]:
        chosen = lock.pins_for(pins, environment(machine, python))
        for requirement in ("numpy", "onnxruntime", "opencv-python-headless", "mavsdk", "scipy", "pydantic", "pyyaml"):
            assert requirement in chosen
        lab = ("pymavlink", "pyrender", "jsbsim", "torch", "pytest", "trimesh", "matplotlib", "ray", "uv", "mypy")
        assert [p for p in lab if p in chosen] == []


def test_the_check_names_each_package_that_differs_from_the_lock(tmp_path: Path) -> None:
    text = (
        "# a lock\n"
        "numpy==2.4.6 ; python_full_version == '3.11.*' \\\n"
        "    --hash=sha256:" + "a" * 64 + "\n"
        "numpy==2.2.6 ; python_full_version < '3.11' \\\n"
        "    --hash=sha256:" + "b" * 64 + "\n"
        "pyyaml==6.0.4 \\\n"
        "    --hash=sha256:" + "c" * 64 + "\n"
        "    # via slz-lander\n"
        "ruff==0.17.6 \\\n"
        "    --hash=sha256:" + "d" * 64 + "\n"
    )
    path = tmp_path / "some.lock"
    path.write_text(text)
    locked = lock.pins_for(lock.read_lock(path), environment("x86_64", "3.11"))
    assert locked == {"numpy": "2.4.6", "pyyaml": "6.0.4", "ruff": "0.17.6"}
    installed = {"numpy": "2.4.6", "pyyaml": "6.0.3", "mypy": "2.4.1"}
    assert lock.differences(locked, installed) == [
        "pyyaml: locked 6.0.4, installed 6.0.3",
        "ruff: locked 0.17.6, not installed",
    ]
    assert lock.differences(locked, {**installed, "pyyaml": "6.0.4", "ruff": "0.17.6"}) == []


def test_a_lock_line_without_a_pin_or_a_hash_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "bad.lock"
    path.write_text("numpy>=2 \\\n    --hash=sha256:" + "a" * 64 + "\n")
    with pytest.raises(lock.LockError, match="not pinned"):
        lock.read_lock(path)
    path.write_text("numpy==2.4.6\n")
    with pytest.raises(lock.LockError, match="no hash"):
        lock.read_lock(path)


def test_requirements_for_a_target_keep_only_its_pins_with_their_hashes() -> None:
    pins = lock.read_lock(lock.LOCKS["drone"].path)
    text = lock.requirements_for(pins, environment("aarch64", "3.10"))
    lines = text.splitlines()
    numpy = [line for line in lines if line.startswith("numpy==")]
    assert len(numpy) == 1
    assert ";" not in numpy[0]
    assert "--hash=sha256:" in numpy[0]
    assert not any(line.startswith("jsbsim") for line in lines)
