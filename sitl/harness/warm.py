"""Warm workers: a SITL process and a companion process kept across missions (the campaign's default).

A cold mission starts two Python processes, each importing the flight stack, and the SITL creating its OpenGL
context; a warm worker starts them once (``slz serve``, :mod:`companion.tools.serve`) and then sends each mission's
``slz sitl`` and ``slz fly`` command lines to them. Every mission still builds its scene, vehicle, autopilot and
companion (pipeline, tracker, MAVSDK instance) from its own config and seed, in fresh objects, so its result is the
cold mission's: the campaign tests fly the same missions both ways and compare them metric for metric.

Either process that fails a mission (it died, ran past its deadline, or did not finish a command when told to) is
killed, and the next mission starts a new one: a failure never reaches the next mission.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import select
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from companion.errors import SlzError
from companion.vehicle.sim_control import Command
from sitl.harness.process import (
    REPO_ROOT,
    ControlClient,
    ControlledSitl,
    SitlProcessError,
    child_env,
    die_with_parent,
    log_tail,
)

logger = logging.getLogger(__name__)

SERVE_READY_WALL_S = 60.0  # imports on a machine busy with parallel missions
STOP_WALL_S = 10.0  # a SITL told to shut down closes its sockets and logs within this
# Imported before the first mission. pyrender is not: the renderer chooses the OpenGL platform (EGL) before it
# imports pyrender (sitl.render.camera), and the first mission does that.
SITL_PRELOAD = ("sitl.cli", "sitl.vehicle.process", "sitl.vehicle.sim_camera")
COMPANION_PRELOAD = ("companion.app.flight", "companion.app.mission", "companion.vehicle.mavsdk_link", "mavsdk.asyncio")


class ServeProcessError(SlzError):
    """A warm process failed to start, to answer, or to finish a command (which process, what, its log's end)."""


class ServeProcess:
    """One ``slz serve`` child process: start, a positive readiness check, one command at a time, stop.

    Parameters
    ----------
    name : str
        For messages (``sitl``, ``companion``).
    preload : sequence of str
        Modules it imports before it says it is ready.
    log_path : Path
        Its own output outside commands (import errors; each command's output goes to that command's log).
    """

    def __init__(self, name: str, preload: tuple[str, ...], log_path: Path) -> None:
        self.name = name
        self.command = [sys.executable, "-m", "companion.cli", "serve"]
        for module in preload:
            self.command += ["--preload", module]
        self.log_path = log_path
        self._proc: subprocess.Popen[bytes] | None = None
        self._buffer = b""
        self._outstanding = False
        self.commands = 0  # commands finished by this process

    @property
    def pid(self) -> int:
        """The child's process id."""
        assert self._proc is not None
        return self._proc.pid

    @property
    def alive(self) -> bool:
        """Started and not exited."""
        return self._proc is not None and self._proc.poll() is None

    @property
    def busy(self) -> bool:
        """A command was sent and has not finished."""
        return self._outstanding

    def start(self, ready_timeout_s: float = SERVE_READY_WALL_S) -> ServeProcess:
        """Start it and wait for its ``ready`` line."""
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        with self.log_path.open("wb") as log:
            env = child_env()
            self._proc = subprocess.Popen(
                self.command,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=log,
                env=env,
                cwd=REPO_ROOT,
                preexec_fn=die_with_parent,
            )
        self._buffer, self._outstanding, self.commands = b"", False, 0
        reply = self._read_line(time.monotonic() + ready_timeout_s)
        if reply is None or reply.get("ready") != self._proc.pid:
            self.kill()
            raise ServeProcessError(
                f"warm {self.name} process not ready within {ready_timeout_s:g} s (got {reply}):\n"
                f"{log_tail(self.log_path, 20)}"
            )
        return self

    def submit(self, argv: list[str], log_path: Path) -> None:
        """Start a command (``slz <argv>``, its output to ``log_path``); one at a time."""
        assert self._proc is not None
        assert self._proc.stdin is not None
        if self._outstanding:
            raise ServeProcessError(f"warm {self.name} process: a command is still running")
        request = json.dumps({"argv": argv, "log": str(log_path)}) + "\n"
        try:
            self._proc.stdin.write(request.encode())
            self._proc.stdin.flush()
        except OSError as exc:
            raise ServeProcessError(f"warm {self.name} process did not take the command: {exc}") from None
        self._outstanding = True

    def result(self, timeout_s: float) -> dict[str, Any] | None:
        """The running command's reply (``exit_code``, maybe ``error``), waiting at most ``timeout_s``; None when
        it has not finished; :class:`ServeProcessError` if the process died."""
        if not self._outstanding:
            raise ServeProcessError(f"warm {self.name} process: no command is running")
        reply = self._read_line(time.monotonic() + timeout_s)
        if reply is None:
            if not self.alive:
                self._outstanding = False
                code = self._proc.returncode if self._proc is not None else None
                raise ServeProcessError(f"warm {self.name} process died (exit {code}) during a command")
            return None
        self._outstanding = False
        self.commands += 1
        return reply

    def _read_line(self, deadline: float) -> dict[str, Any] | None:
        """The next JSON line of its output, or None at the deadline or its end."""
        assert self._proc is not None
        assert self._proc.stdout is not None
        fd = self._proc.stdout.fileno()
        while b"\n" not in self._buffer:
            remaining = deadline - time.monotonic()
            readable, _, _ = select.select([fd], [], [], max(0.0, remaining))
            if not readable:
                return None
            chunk = os.read(fd, 65536)
            if not chunk:  # it exited
                self._proc.wait()
                return None
            self._buffer += chunk
        line, self._buffer = self._buffer.split(b"\n", 1)
        try:
            reply: dict[str, Any] = json.loads(line)
        except json.JSONDecodeError:
            self.kill()
            raise ServeProcessError(f"warm {self.name} process wrote {line[:200]!r}, not a reply") from None
        return reply

    def kill(self) -> None:
        """Kill it now and reap it (a command it was running is abandoned)."""
        if self._proc is not None:
            if self._proc.poll() is None:
                self._proc.kill()
            self._proc.wait()
            for pipe in (self._proc.stdin, self._proc.stdout):
                if pipe is not None:
                    with contextlib.suppress(OSError):
                        pipe.close()
        self._outstanding = False

    def stop(self, timeout_s: float = 5.0) -> None:
        """End its input, so it exits after its command; then terminate, then kill."""
        proc = self._proc
        if proc is None:
            return
        if proc.poll() is None and proc.stdin is not None:
            with contextlib.suppress(OSError):
                proc.stdin.close()
            try:
                proc.wait(timeout=0.0 if self._outstanding else timeout_s)
            except subprocess.TimeoutExpired:
                proc.terminate()
                with contextlib.suppress(subprocess.TimeoutExpired):
                    proc.wait(timeout=timeout_s)
        self.kill()
        self._proc = None


class WarmSitl(ControlledSitl):
    """One mission's SITL on a warm process: what :func:`sitl.harness.mission.fly` needs of a SITL (as
    :class:`~sitl.harness.process.SitlProcess`)."""

    def __init__(self, process: ServeProcess, instance: int, config_path: Path, log_path: Path) -> None:
        self.process, self.instance = process, instance
        self.argv = ["sitl", "--instance", str(instance), "--config", str(config_path)]
        self.log_path = log_path
        self._control: ControlClient | None = None
        self._exit_code: int | None = None

    def start(self, ready_timeout_s: float = 20.0) -> WarmSitl:
        """Start the mission's SITL and wait until it answers on its control channel."""
        self.process.submit(self.argv, self.log_path)
        self._control = ControlClient(self.instance)
        try:
            self._control.wait_ready(self.process.pid, self._ended, ready_timeout_s, self.log_tail)
        except SitlProcessError:
            self.stop()
            raise
        return self

    def _collect(self, timeout_s: float) -> None:
        """Take the command's exit code if it ends within ``timeout_s`` (-9 when its process died)."""
        try:
            reply = self.process.result(timeout_s)
        except ServeProcessError:
            self._exit_code = -9
            return
        if reply is not None:
            self._exit_code = int(reply.get("exit_code", 1))

    def _ended(self) -> int | None:
        """Its exit code once the command has ended (by itself, or its process died), else None."""
        if self._exit_code is None and self.process.busy:
            self._collect(0.0)
        return self._exit_code

    @property
    def running(self) -> bool:
        """Its command has not ended."""
        return self._ended() is None

    def wait(self, timeout_s: float) -> int:
        """Wait for the SITL to end by itself; its exit code (``subprocess.TimeoutExpired`` after ``timeout_s``)."""
        deadline = time.monotonic() + timeout_s
        while self._ended() is None:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise subprocess.TimeoutExpired(self.argv, timeout_s)
            self._collect(remaining)
        assert self._exit_code is not None
        return self._exit_code

    def stop(self, timeout_s: float = STOP_WALL_S) -> int | None:
        """Ask it to shut down and wait for its command to end; a process that does not end it is killed."""
        if self._control is None:  # never started (the process did not take the command), or stopped already
            return self._exit_code
        if self._ended() is None:
            with contextlib.suppress(TimeoutError, OSError):
                self.request({"cmd": Command.SHUTDOWN.value}, timeout_s=0.5)
            try:
                self.wait(timeout_s)
            except subprocess.TimeoutExpired:
                logger.warning("warm SITL did not end its mission within %g s: killed", timeout_s)
                self.process.kill()
                self._exit_code = -9
        if self._control is not None:
            self._control.close()
            self._control = None
        return self._exit_code

    def log_tail(self, lines: int = 40) -> str:
        """The end of this mission's SITL output."""
        return log_tail(self.log_path, lines)


class WarmCompanion:
    """One mission's companion (``slz fly``) on a warm process: what :func:`sitl.harness.mission.fly` needs of it (as
    :class:`~sitl.harness.mission.CompanionProcess`)."""

    def __init__(self, process: ServeProcess, config_path: Path, out_dir: Path, timeout_s: float, log_path: Path):
        self.process = process
        self.argv = ["fly", "--config", str(config_path), "--out", str(out_dir), "--timeout", f"{timeout_s:g}"]
        self.log_path = log_path

    def start(self) -> WarmCompanion:
        """Start the mission's companion."""
        self.process.submit(self.argv, self.log_path)
        return self

    def wait(self, timeout_s: float) -> int:
        """Its exit code; :class:`ServeProcessError` (after killing the process) past ``timeout_s`` or if it died."""
        try:
            reply = self.process.result(timeout_s)
        except ServeProcessError as exc:
            raise ServeProcessError(f"{exc}:\n{self.log_tail()}") from None
        if reply is None:
            self.process.kill()
            raise ServeProcessError(f"the companion ran past {timeout_s:g} s:\n{self.log_tail()}")
        return int(reply.get("exit_code", 1))

    def stop(self) -> None:
        """A mission's companion still running when its mission ends is killed with its process."""
        if self.process.busy:
            self.process.kill()

    def log_tail(self, lines: int = 30) -> str:
        """The end of this mission's companion output."""
        return log_tail(self.log_path, lines)


class WarmWorker:
    """A warm SITL process and a warm companion process for one SITL instance, started when first needed and
    started again after a mission that failed either (:class:`sitl.harness.mission.MissionProcesses`)."""

    def __init__(self, instance: int, log_dir: Path) -> None:
        self.instance = instance
        self.sitl_process = ServeProcess("sitl", SITL_PRELOAD, log_dir / f"warm-sitl-{instance}.log")
        self.companion_process = ServeProcess(
            "companion", COMPANION_PRELOAD, log_dir / f"warm-companion-{instance}.log"
        )

    def _ready(self, process: ServeProcess) -> ServeProcess:
        if not process.alive:
            process.start()
        return process

    def sitl(self, instance: int, config_path: Path, log_path: Path) -> WarmSitl:
        """The SITL of one mission (its config), on the warm process."""
        if instance != self.instance:
            raise ServeProcessError(f"this warm worker flies instance {self.instance}, not {instance}")
        return WarmSitl(self._ready(self.sitl_process), instance, config_path, log_path)

    def companion(self, config_path: Path, out_dir: Path, timeout_s: float, log_path: Path) -> WarmCompanion:
        """The companion of one mission, on the warm process."""
        return WarmCompanion(self._ready(self.companion_process), config_path, out_dir, timeout_s, log_path)

    def close(self) -> None:
        """Stop both processes."""
        self.sitl_process.stop()
        self.companion_process.stop()
