"""The project's dependency locks: compile them with uv, check an environment against one, read one.

One lock per install the project offers, each a pip requirements file with every distribution pinned and hashed
(``pip install --require-hashes --no-deps -r requirements/NAME.lock``):

========  ==========================================  ===================================================
lock      what it installs                            where
========  ==========================================  ===================================================
drone     the companion alone (no extras)             the Jetson install, the container
dev       the ``dev`` extra (SITL, Ray, tools)        ``make setup``, ``make demo``, ``make test``, CI
ray       the ``sitl`` and ``ray`` extras             the nodes of a Ray cluster flying campaigns
training  ``dev`` and ``training`` (CPU PyTorch)      ``make training`` (x86-64 Linux, CPython 3.11 only)
========  ==========================================  ===================================================

``dev``, ``drone`` and ``ray`` are *universal* (uv's ``--universal``): one file for every platform and every
CPython from 3.10 (JetPack 6's) up, with markers where a package is platform-specific or where its newest release
has left an older Python behind (numpy, scipy and onnxruntime have a CPython 3.10 line for the Jetson beside the
newer one that CI tests on 3.11; ``make test-slow`` tests the drone's 3.10 line in its own venv where a CPython 3.10
is found). ``drone``, ``ray`` and ``training`` are compiled with ``dev`` as a constraint, so a package they share
with ``dev`` has the version ``dev`` tested. Every lock also
holds pip, setuptools and wheel (``requirements/build.in``): the project itself is installed with
``--no-build-isolation``, so its build backend comes from the lock too.

Usage (from the repository root, with the dev venv's python)::

    python scripts/lock.py compile [--upgrade] [NAME ...]   # `make lock`, `make lock-upgrade`
    python scripts/lock.py check requirements/dev.lock      # the running environment installs exactly the lock
    python scripts/lock.py check --report requirements/dev.lock   # what differs, never fails (`make test-latest`)
    python scripts/lock.py for-target --machine aarch64 --python 3.10 requirements/drone.lock   # the Jetson's pins

This file is a development tool: it imports nothing of the project, and ``packaging`` only (a dev dependency).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import re
import shutil
import subprocess
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from packaging.markers import Marker
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

REPO_ROOT = Path(__file__).resolve().parent.parent
LOCK_DIR = REPO_ROOT / "requirements"
BUILD_IN = LOCK_DIR / "build.in"
# The oldest CPython the project supports (pyproject's requires-python): JetPack 6 ships 3.10.
OLDEST_PYTHON = "3.10"
# Where this project's machines keep the CPU build of PyTorch (pip finds it through its own find-links setting; uv
# does not read pip's configuration, so it is named here). The PyPI wheel of the same version is a CUDA build.
TORCH_WHEELS = Path("/opt/wheels")


@dataclass(frozen=True)
class LockSpec:
    """How one lock is compiled.

    Attributes
    ----------
    name : str
        ``requirements/<name>.lock``.
    extras : tuple of str
        The project's extras it installs (none: the companion alone).
    constrained_by_dev : bool
        Compiled with ``requirements/dev.lock`` as constraints (the versions dev tested).
    platform : str or None
        uv's ``--python-platform`` and ``python`` the ``--python-version`` for a lock of one platform; None: universal.
    inputs : tuple of str
        Further requirement files (relative to the repository root).
    """

    name: str
    extras: tuple[str, ...]
    constrained_by_dev: bool = True
    platform: str | None = None
    python: str = OLDEST_PYTHON
    inputs: tuple[str, ...] = ()

    @property
    def path(self) -> Path:
        return LOCK_DIR / f"{self.name}.lock"


LOCKS: dict[str, LockSpec] = {
    spec.name: spec
    for spec in (
        LockSpec("dev", ("dev",), constrained_by_dev=False),
        LockSpec("drone", ()),
        LockSpec("ray", ("sitl", "ray")),
        LockSpec(
            "training",
            ("dev", "training"),
            platform="x86_64-manylinux_2_28",
            python="3.11",
            inputs=("requirements/training.in",),
        ),
    )
}


class LockError(Exception):
    """A lock file could not be read, or an environment does not match it."""


@dataclass(frozen=True)
class Pin:
    """One line of a lock: ``name==version ; marker`` and its hashes."""

    name: str
    version: str
    marker: Marker | None
    hashes: tuple[str, ...]

    def applies(self, environment: Mapping[str, str] | None = None) -> bool:
        """Whether this pin is installed in ``environment`` (PEP 508 marker values; None: this interpreter)."""
        if self.marker is None:
            return True
        return self.marker.evaluate(dict(environment) if environment is not None else None)


_PIN_START = re.compile(r"^[A-Za-z0-9]")
_HASH = re.compile(r"--hash=(sha256:[0-9a-f]{64})")


def read_lock(path: Path) -> list[Pin]:
    """The pins of a lock file (uv's requirements output with ``--generate-hashes``).

    Raises
    ------
    LockError
        A requirement line that is not ``name==version``, or one without a hash.
    """
    entries: list[list[str]] = []
    for line in path.read_text().splitlines():
        if _PIN_START.match(line):
            entries.append([line])
        elif line.startswith("    --hash=") and entries:
            entries[-1].append(line)
    pins = []
    for lines in entries:
        text = " ".join(part.rstrip("\\ ").strip() for part in lines)
        requirement_text = text.split(" --hash=", 1)[0].strip()
        requirement = Requirement(requirement_text)
        specifiers = list(requirement.specifier)
        if len(specifiers) != 1 or specifiers[0].operator != "==":
            raise LockError(f"{path.name}: {requirement_text!r} is not pinned with ==")
        hashes = tuple(_HASH.findall(text))
        if not hashes:
            raise LockError(f"{path.name}: {requirement.name} has no hash")
        pins.append(Pin(canonicalize_name(requirement.name), specifiers[0].version, requirement.marker, hashes))
    if not pins:
        raise LockError(f"{path.name}: no pinned requirement")
    return pins


def pins_for(pins: Iterable[Pin], environment: Mapping[str, str] | None = None) -> dict[str, str]:
    """``{name: version}`` of the pins that apply in ``environment``.

    Raises
    ------
    LockError
        Two pins of one package apply there.
    """
    chosen: dict[str, str] = {}
    for pin in pins:
        if not pin.applies(environment):
            continue
        if pin.name in chosen and chosen[pin.name] != pin.version:
            raise LockError(f"{pin.name} is pinned to both {chosen[pin.name]} and {pin.version} here")
        chosen[pin.name] = pin.version
    return chosen


def requirements_for(pins: Iterable[Pin], environment: Mapping[str, str]) -> str:
    """A requirements file of the pins that apply in ``environment``, markers resolved, hashes kept: for pip on a
    machine other than the target (``pip install --platform ... --python-version ...`` checks wheel tags for the
    target but evaluates markers for the interpreter it runs on)."""
    lines = []
    for pin in pins:
        if pin.applies(environment):
            hashes = " ".join(f"--hash={h}" for h in pin.hashes)
            lines.append(f"{pin.name}=={pin.version} {hashes}")
    pins_for([p for p in pins if p.applies(environment)], environment)  # one version of each
    return "\n".join(lines) + "\n"


def target_environment(machine: str, python: str) -> dict[str, str]:
    """PEP 508 marker values of a Linux CPython ``python`` (``"3.10"``) on ``machine`` (``uname -m``)."""
    return {
        "implementation_name": "cpython",
        "implementation_version": f"{python}.0",
        "os_name": "posix",
        "platform_machine": machine,
        "platform_python_implementation": "CPython",
        "platform_release": "",
        "platform_system": "Linux",
        "platform_version": "",
        "python_full_version": f"{python}.0",
        "python_version": python,
        "sys_platform": "linux",
        "extra": "",
    }


def installed_versions() -> dict[str, str]:
    """``{name: version}`` of the distributions this interpreter sees."""
    versions: dict[str, str] = {}
    for dist in importlib.metadata.distributions():
        name = dist.metadata["Name"]
        if name:
            versions.setdefault(canonicalize_name(name), dist.version)
    return versions


def differences(locked: Mapping[str, str], installed: Mapping[str, str]) -> list[str]:
    """One line per package whose installed version is not the locked one (missing included), sorted by name."""
    lines = []
    for name in sorted(locked):
        have = installed.get(name)
        if have is None:
            lines.append(f"{name}: locked {locked[name]}, not installed")
        elif Version(have) != Version(locked[name]):
            lines.append(f"{name}: locked {locked[name]}, installed {have}")
    return lines


def uv_command() -> list[str]:
    """uv, from this interpreter's environment (the dev lock pins it), else from PATH."""
    beside = Path(sys.executable).with_name("uv")
    if beside.is_file():
        return [str(beside)]
    found = shutil.which("uv")
    if found is None:
        raise LockError("uv is not installed: `make setup` installs it into .venv (it is pinned in the dev lock)")
    return [found]


def compile_command(spec: LockSpec, upgrade: bool) -> list[str]:
    """The ``uv pip compile`` command line that writes ``spec``'s lock."""
    command = [*uv_command(), "pip", "compile", "pyproject.toml", str(BUILD_IN.relative_to(REPO_ROOT))]
    command += list(spec.inputs)
    for extra in spec.extras:
        command += ["--extra", extra]
    if spec.platform is None:
        command += ["--universal"]
    else:
        command += ["--python-platform", spec.platform]
    command += ["--python-version", spec.python, "--generate-hashes", "--quiet"]
    command += ["--custom-compile-command", f"make lock  (scripts/lock.py, the {spec.name} lock)"]
    if spec.constrained_by_dev:
        command += ["--constraint", str(LOCKS["dev"].path.relative_to(REPO_ROOT))]
    if "training" in spec.extras and TORCH_WHEELS.is_dir():
        command += ["--find-links", str(TORCH_WHEELS)]
    if upgrade:
        command.append("--upgrade")
    command += ["--output-file", str(spec.path.relative_to(REPO_ROOT))]
    return command


def compile_locks(names: list[str], upgrade: bool) -> None:
    """Write the named locks (all when none is named), ``dev`` first: the others are constrained by it."""
    unknown = sorted(set(names) - set(LOCKS))
    if unknown:
        raise LockError(f"no lock named {', '.join(unknown)} (the locks: {', '.join(LOCKS)})")
    for name in LOCKS:  # dict order: dev first
        if names and name not in names:
            continue
        command = compile_command(LOCKS[name], upgrade)
        print("+", " ".join(command), flush=True)
        subprocess.run(command, cwd=REPO_ROOT, check=True)
        read_lock(LOCKS[name].path)  # every line pinned and hashed


def check(lock: Path, report_only: bool) -> int:
    """Compare this interpreter's distributions with ``lock``; print the differences; 1 when any (unless a report)."""
    locked = pins_for(read_lock(lock))
    lines = differences(locked, installed_versions())
    where = f"{lock.relative_to(REPO_ROOT) if lock.is_relative_to(REPO_ROOT) else lock}"
    if not lines:
        print(f"lock: this environment installs exactly {where} ({len(locked)} distributions)")
        return 0
    print(f"lock: {len(lines)} of {len(locked)} distributions differ from {where}:")
    for line in lines:
        print(f"  {line}")
    if report_only:
        return 0
    print("lock: run `make setup` (the environment was changed by hand) or `make lock` (pyproject.toml changed)")
    return 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="scripts/lock.py", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    compiling = commands.add_parser("compile", help="write requirements/*.lock with uv")
    compiling.add_argument("names", nargs="*", help=f"locks to write (default: all of {', '.join(LOCKS)})")
    compiling.add_argument("--upgrade", action="store_true", help="the newest releases, not the locked ones")
    target = commands.add_parser("for-target", help="print a lock's pins for one Linux machine and CPython")
    target.add_argument("lock", type=Path)
    target.add_argument("--machine", required=True, help="uname -m of the target, e.g. aarch64")
    target.add_argument("--python", required=True, help="the target's CPython, e.g. 3.10")
    checking = commands.add_parser("check", help="compare this environment with a lock")
    checking.add_argument("lock", type=Path)
    checking.add_argument("--report", action="store_true", help="print the differences, exit 0")
    args = parser.parse_args(argv)
    try:
        if args.command == "compile":
            compile_locks(args.names, args.upgrade)
            return 0
        if args.command == "for-target":
            sys.stdout.write(requirements_for(read_lock(args.lock), target_environment(args.machine, args.python)))
            return 0
        return check(args.lock.resolve(), args.report)
    except (LockError, OSError, subprocess.CalledProcessError) as exc:
        print(f"lock: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
