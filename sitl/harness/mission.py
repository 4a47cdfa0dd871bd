"""One seeded landing mission: the SITL and the companion (``slz fly``) as two processes in lockstep, and its outcome
measured on the SITL's ground truth.

The companion runs with ``mission_configs/sitl.yaml`` (or another mission config) moved onto the SITL instance's
ports; only the ports, the output folder and the given overrides change. The SITL runs at full speed in lockstep and
writes its ground truth (vehicle, landed state, every person) at each frame instant, which the companion never sees.
The same seed and overrides give the same mission on any machine at any speed.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

import yaml

from companion.app.mission import MISSION_PATH_FIELDS, MissionConfig, camera_mismatches
from companion.config import paths_from, read_yaml_file, validate_config
from companion.errors import SlzError
from companion.flightlog.flight_log import FlightLog, FlightLogError, RecordKind
from companion.guidance.landing import CommandKind, LandingPhase
from sitl.config import SitlConfig
from sitl.harness.process import REPO_ROOT, SitlProcess, child_env, die_with_parent, log_tail, terminate_then_kill
from sitl.vehicle.truth import TruthError, body_edges_m, read_truth, touchdown

logger = logging.getLogger(__name__)

DEFAULT_MISSION_CONFIG = REPO_ROOT / "mission_configs" / "sitl.yaml"
SITL_READY_WALL_S = 60.0  # a SITL starts in about 5 s; a machine busy with parallel missions may take several times it
SETTLE_WALL_S = 60.0  # after the companion ends: how long the SITL may run to finish an autopilot landing
TRUTH_AFTER_TOUCHDOWN_S = 1.0  # simulated: longer than any camera frame period the configs use


class MissionError(SlzError):
    """A mission could not be flown (which process, what happened, the end of its log)."""


def deep_merge(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``overrides`` merged in, recursively for nested mappings."""
    out = dict(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = value
    return out


@dataclass(frozen=True)
class MissionSpec:
    """What to fly.

    Attributes
    ----------
    seed : int
        The scene, its people and their walks, the weather, the sensor noise.
    run_dir : Path
        Everything of the mission goes here (``flight/``, ``truth.jsonl``, logs, ``result.json``).
    instance : int
        SITL instance (its ports); parallel missions need different ones.
    mission_config : Path
        The companion's mission config.
    sitl_overrides : dict
        Merged into the SITL config (``scenario``, ``faults``, ``wind_ned_mps``...).
    mission_overrides : dict
        Merged into the mission config (``guidance``, ``perception``...).
    record_frames : bool
        Save every processed frame losslessly (for ``slz replay`` and the annotated video).
    timeout_s : float
        Wall-clock limit of the companion.
    """

    seed: int
    run_dir: Path
    instance: int = 0
    mission_config: Path = DEFAULT_MISSION_CONFIG
    sitl_overrides: dict[str, Any] = field(default_factory=dict)
    mission_overrides: dict[str, Any] = field(default_factory=dict)
    record_frames: bool = False
    timeout_s: float = 600.0


@dataclass
class MissionResult:
    """How one mission went, from the companion's log and the SITL's ground truth.

    Distances are horizontal, metres; a person's distance is to the edge of their body (centre distance minus body
    radius). ``nearest_person_m`` is at the touchdown instant (NaN when the vehicle did not touch down).
    """

    seed: int
    phase: str
    reason: str
    companion_exit_code: int
    landed: bool
    touchdown_ne_m: tuple[float, float] | None
    touchdown_t_s: float | None
    nearest_person_m: float
    people_within_1m: int
    people_within_1_5m: int
    target_radius_m: float | None
    failsafes: list[str]
    sim_time_s: float
    wall_s: float
    run_dir: str

    def to_json(self) -> dict[str, Any]:
        """JSON-able form (NaN as None)."""
        out = asdict(self)
        for key, value in out.items():
            if isinstance(value, float) and not math.isfinite(value):
                out[key] = None
        return out


class CompanionProcess:
    """One ``slz fly`` child process: start, wait with a deadline, terminate, kill."""

    def __init__(self, config_path: Path, out_dir: Path, timeout_s: float, log_path: Path) -> None:
        self.command = [sys.executable, "-m", "companion.cli", "fly", "--config", str(config_path)]
        self.command += ["--out", str(out_dir), "--timeout", f"{timeout_s:g}"]
        self.log_path = log_path
        self._proc: subprocess.Popen[bytes] | None = None

    def start(self) -> CompanionProcess:
        """Start it (its output goes to ``log_path``)."""
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        with self.log_path.open("wb") as log:
            env = child_env()
            self._proc = subprocess.Popen(
                self.command, cwd=REPO_ROOT, stdout=log, stderr=subprocess.STDOUT, env=env, preexec_fn=die_with_parent
            )
        return self

    def wait(self, timeout_s: float) -> int:
        """Its exit code; :class:`MissionError` (after stopping it) if it runs past ``timeout_s``."""
        assert self._proc is not None
        try:
            return self._proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.stop()
            raise MissionError(f"the companion ran past {timeout_s:g} s:\n{self.log_tail()}") from None

    def stop(self, timeout_s: float = 5.0) -> None:
        """Terminate, then kill."""
        if self._proc is not None:
            terminate_then_kill(self._proc, timeout_s)

    def log_tail(self, lines: int = 30) -> str:
        """The end of its output."""
        return log_tail(self.log_path, lines)


def write_configs(spec: MissionSpec) -> tuple[Path, Path]:
    """The SITL and mission configs of ``spec`` in its run folder; returns their paths."""
    spec.run_dir.mkdir(parents=True, exist_ok=True)
    ports = validate_config(SitlConfig, {"instance": spec.instance}, source="mission spec", prefix="sitl")
    sitl_section = deep_merge(
        {
            "seed": spec.seed,
            "lockstep": True,
            "speed_factor": 0.0,
            "camera": {"enabled": True},
            "truth_path": str(spec.run_dir / "truth.jsonl"),
            "end_after_touchdown_s": TRUTH_AFTER_TOUCHDOWN_S,  # the SITL ends itself: no full-speed run past it
            "log_path": str(spec.run_dir / "trajectory.csv"),
            "ulog_path": str(spec.run_dir / "flight.ulg"),  # as PX4's SITL: the autopilot's log of the flight
        },
        spec.sitl_overrides,
    )
    sitl_path = spec.run_dir / "sitl.yaml"
    sitl_path.write_text(yaml.safe_dump({"sitl": sitl_section}, sort_keys=False))
    # Its relative paths are the file's (as `slz fly` reads it); the campaign's overrides name theirs from the
    # repository. The mission.yaml written into the run folder holds them absolute.
    mission = paths_from(read_yaml_file(spec.mission_config), spec.mission_config.parent, MISSION_PATH_FIELDS)
    frames = {"frame_every": 1, "frame_format": "png"} if spec.record_frames else {"frame_every": 0}
    mission = deep_merge(
        mission,
        {
            # The companion shares the vehicle's system id, as on a real drone: a ground station shows its texts.
            "vehicle": {"url": f"udpin://0.0.0.0:{ports.api_port_remote}", "system_id": ports.system_id},
            "camera": {"url": f"sitl://127.0.0.1:{ports.frame_port}"},
            "simulator": {"lockstep_url": f"udp://127.0.0.1:{ports.control_port}"},
            "recorder": {"directory": str(spec.run_dir), **frames},
            # A failsafe ends the mission: the harness ends the simulator (a hold would otherwise hover for ever).
            "supervision": {"stay_after_failsafe": False},
        },
    )
    mission = deep_merge(mission, paths_from(spec.mission_overrides, REPO_ROOT, MISSION_PATH_FIELDS))
    sitl_config = validate_config(SitlConfig, {**sitl_section, "instance": spec.instance}, "mission spec", "sitl")
    mission_config = validate_config(MissionConfig, mission, source="mission spec")
    mismatches = camera_mismatches(mission_config.perception, sitl_config.camera)
    if mismatches:
        raise MissionError(f"{spec.mission_config}: " + "; ".join(mismatches))
    mission_path = spec.run_dir / "mission.yaml"
    mission_path.write_text(yaml.safe_dump(mission, sort_keys=False))
    return sitl_path, mission_path


def evaluate(spec: MissionSpec, exit_code: int, wall_s: float) -> MissionResult:
    """The mission's result from its flight log and ground truth."""
    try:
        header, records = read_truth(spec.run_dir / "truth.jsonl")
    except TruthError as exc:
        raise MissionError(str(exc)) from None
    flight = _flight_log(spec.run_dir / "flight")
    outcome = flight.outcome
    land = next((d for d in reversed(flight.decisions()) if d.kind is CommandKind.LAND), None)
    target = land.target if land else None
    down = touchdown(records)
    nearest, within_1, within_15 = math.nan, 0, 0
    touchdown_ne = None
    if down is not None:
        n, e, _ = down.position_ned_m
        touchdown_ne = (n, e)
        edges = body_edges_m(header, down, n, e)
        nearest = float(edges.min()) if math.isfinite(edges.min()) else math.nan  # NaN: nobody in the scene
        within_1, within_15 = int((edges < 1.0).sum()), int((edges < 1.5).sum())
    return MissionResult(
        seed=spec.seed,
        phase=str(outcome.get("phase", "unknown")),
        reason=str(outcome.get("reason", "")),
        companion_exit_code=exit_code,
        landed=down is not None,
        touchdown_ne_m=touchdown_ne,
        touchdown_t_s=None if down is None else down.t_s,
        nearest_person_m=nearest,
        people_within_1m=within_1,
        people_within_1_5m=within_15,
        target_radius_m=None if target is None else float(target.radius_m),
        failsafes=list(outcome.get("failsafes", [])),
        sim_time_s=records[-1].t_s if records else 0.0,
        wall_s=wall_s,
        run_dir=str(spec.run_dir),
    )


def _flight_log(path: Path) -> FlightLog:
    """The companion's flight log, checked against its schema (a broken one is the mission's error)."""
    try:
        return FlightLog.read(path)
    except FlightLogError as exc:
        raise MissionError(str(exc)) from None


def _autopilot_lands(spec: MissionSpec) -> bool:
    """Whether the vehicle comes down without the companion: it asked for a landing or a return, or it stopped
    commanding in OFFBOARD (the autopilot's offboard-loss failsafe lands); not after a hold or a pilot takeover."""
    path = spec.run_dir / "flight" / "flight.jsonl"
    if not path.is_file():
        return True
    flight = _flight_log(path)
    commands = flight.of(RecordKind.COMMAND)
    if any(r["phase"] == LandingPhase.YIELDED for r in flight.of(RecordKind.PHASE)):
        return False
    return not commands or commands[-1]["command"] != CommandKind.HOLD


class SitlHandle(Protocol):
    """What :func:`fly` needs of a mission's SITL (:class:`~sitl.harness.process.SitlProcess`,
    :class:`~sitl.harness.warm.WarmSitl`)."""

    def start(self, ready_timeout_s: float) -> Any:
        """Start it and wait until it answers on its control channel."""

    def state(self) -> dict[str, Any]:
        """Ground truth and counters (``TimeoutError`` when it does not answer)."""

    @property
    def running(self) -> bool:
        """It has not ended."""

    def wait(self, timeout_s: float) -> int:
        """Its exit code once it ends by itself (``subprocess.TimeoutExpired`` after ``timeout_s``)."""

    def stop(self) -> int | None:
        """End it."""

    def log_tail(self, lines: int = 40) -> str:
        """The end of its output."""


class CompanionHandle(Protocol):
    """What :func:`fly` needs of a mission's companion (:class:`CompanionProcess`,
    :class:`~sitl.harness.warm.WarmCompanion`)."""

    def start(self) -> Any:
        """Start it."""

    def wait(self, timeout_s: float) -> int:
        """Its exit code; an exception (after stopping it) past ``timeout_s``."""

    def stop(self) -> None:
        """End it."""

    def log_tail(self, lines: int = 30) -> str:
        """The end of its output."""


class MissionProcesses(Protocol):
    """Where a mission's SITL and companion run: fresh processes (:class:`ColdProcesses`) or a campaign worker's
    warm ones (:class:`~sitl.harness.warm.WarmWorker`). Either way the same command lines, so the same result."""

    def sitl(self, instance: int, config_path: Path, log_path: Path) -> SitlHandle:
        """The SITL of one mission (``slz sitl --instance INSTANCE --config CONFIG_PATH``)."""

    def companion(self, config_path: Path, out_dir: Path, timeout_s: float, log_path: Path) -> CompanionHandle:
        """The companion of one mission (``slz fly --config CONFIG_PATH --out OUT_DIR --timeout TIMEOUT_S``)."""


class ColdProcesses:
    """Each mission in two new processes (the demo, the tests, a campaign with ``--cold``)."""

    def sitl(self, instance: int, config_path: Path, log_path: Path) -> SitlProcess:
        """A new ``slz sitl`` process; its output in ``log_path``'s folder as ``sitl-<instance>.log``."""
        return SitlProcess(["--config", str(config_path)], instance, log_path.parent)

    def companion(self, config_path: Path, out_dir: Path, timeout_s: float, log_path: Path) -> CompanionProcess:
        """A new ``slz fly`` process."""
        return CompanionProcess(config_path, out_dir, timeout_s, log_path)


def fly(spec: MissionSpec, processes: MissionProcesses | None = None) -> MissionResult:
    """Fly one mission (see the module docstring) on ``processes`` (default: new ones); writes ``result.json`` in
    the run folder.

    A run folder holds one mission: the companion's flight log appends (it must survive a crash), so the log of an
    earlier flight in the same folder (a replay flown again) is removed first.
    """
    processes = processes or ColdProcesses()
    shutil.rmtree(spec.run_dir / "flight", ignore_errors=True)
    sitl_path, mission_path = write_configs(spec)
    started = time.monotonic()
    sitl = processes.sitl(spec.instance, sitl_path, spec.run_dir / f"sitl-{spec.instance}.log")
    companion = processes.companion(
        mission_path, spec.run_dir / "flight", spec.timeout_s, spec.run_dir / "companion.log"
    )
    try:
        sitl.start(ready_timeout_s=SITL_READY_WALL_S)
        companion.start()
        exit_code = companion.wait(spec.timeout_s + 30.0)
        # The companion has let go of the lockstep: an autopilot landing it asked for finishes at full speed, and the
        # SITL ends itself TRUTH_AFTER_TOUCHDOWN_S (simulated) after the touchdown or at a disarm
        # (end_after_touchdown_s, set above), so the ground truth holds the touchdown.
        if _autopilot_lands(spec):
            with contextlib.suppress(subprocess.TimeoutExpired):
                sitl.wait(SETTLE_WALL_S)
    finally:
        companion.stop()
        sitl.stop()
    wall_s = time.monotonic() - started
    if not (spec.run_dir / "flight" / "flight.jsonl").is_file():
        raise MissionError(f"the companion wrote no flight log (exit {exit_code}):\n{companion.log_tail()}")
    result = evaluate(spec, exit_code, wall_s)
    (spec.run_dir / "result.json").write_text(json.dumps(result.to_json(), indent=2) + "\n")
    return result
