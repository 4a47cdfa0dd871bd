"""One object per SITL process: start, a positive readiness check, the control channel, and a clean stop.

Used by tests, benchmarks and the campaign runner. Output goes to a per-process log file; :meth:`SitlProcess.log_tail`
gives the end of it for failure messages.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from companion.errors import SlzError
from companion.vehicle.sim_control import Command, Event
from sitl.config import CONTROL_PORT

logger = logging.getLogger(__name__)

REPO_ROOT = Path(__file__).resolve().parents[2]
"""The repository's root, where the harness's child processes run (their configs' relative paths start there)."""

# A mission's processes compute on one thread each: a campaign flies one mission per CPU, and the libraries' idle
# worker threads spin-wait for the next call (OpenCV's parallel_for pool called sched_yield about 30,000 times a second
# in each process: docs/results/campaign_throughput.md). Mesa's llvmpipe rasterizes in the rendering thread itself
# (LP_NUM_THREADS=0: no hand-off to its own threads; the same pixels, each tile is drawn alike on any thread). Set in
# the environment by hand, a variable wins.
SINGLE_THREAD_ENV = {"OPENCV_FOR_THREADS_NUM": "1", "OPENBLAS_NUM_THREADS": "1", "LP_NUM_THREADS": "0"}


def child_env() -> dict[str, str]:
    """The environment of a SITL or companion process started for a mission (unbuffered output, one thread)."""
    return {**SINGLE_THREAD_ENV, **os.environ, "PYTHONUNBUFFERED": "1"}


def _load_prctl() -> Any:
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _load_prctl()  # resolved here, so that a forked child only calls it
_PR_SET_PDEATHSIG = 1


def die_with_parent() -> None:
    """In a child between fork and exec (``preexec_fn``): receive SIGTERM when the parent dies, however it dies
    (Linux; elsewhere nothing). A SITL or companion is then never left running without the process that owns it."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, signal.SIGTERM)


def terminate_then_kill(proc: subprocess.Popen[bytes], timeout_s: float) -> None:
    """SIGTERM, wait up to ``timeout_s``, then SIGKILL and reap."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def log_tail(path: Path, lines: int) -> str:
    """The last ``lines`` lines of a process's log file."""
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return "(no log)"


class SitlProcessError(SlzError):
    """The SITL process failed to start, answer or stop (what, and the end of its log)."""


class ControlClient:
    """Requests to one SITL instance's control channel (UDP on loopback), each answered by its own reply."""

    def __init__(self, instance: int) -> None:
        self.control_addr = ("127.0.0.1", CONTROL_PORT + instance)
        self.instance = instance
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        self._request_id = 0

    def request(self, request: dict[str, Any], timeout_s: float = 2.0) -> dict[str, Any]:
        """Send a control request and wait for its own reply (``TimeoutError`` after ``timeout_s``).

        Each request carries an id that the SITL echoes, so a late reply to an earlier request is never taken for
        this one's.
        """
        self._request_id += 1
        request = {**request, "id": self._request_id}
        self._sock.sendto(json.dumps(request).encode(), self.control_addr)
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"no reply to {request['cmd']} within {timeout_s} s")
            self._sock.settimeout(remaining)
            try:
                data, _ = self._sock.recvfrom(65535)
            except TimeoutError:
                continue
            except ConnectionRefusedError:
                raise TimeoutError(f"control port {self.control_addr[1]} refused") from None
            reply: dict[str, Any] = json.loads(data)
            if reply.get("id") == self._request_id:
                return reply

    def wait_ready(
        self, pid: int, exit_code: Callable[[], int | None], timeout_s: float, log_tail: Callable[[], str]
    ) -> None:
        """Ping until the SITL of process ``pid`` answers (a positive readiness check).

        Raises
        ------
        SitlProcessError
            The process exited (``exit_code()`` is not None), another process answers on this instance's port, or
            nothing answered within ``timeout_s``; with the end of its log (``log_tail()``).
        """
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            code = exit_code()
            if code is not None:
                raise SitlProcessError(f"SITL exited with {code} at start:\n{log_tail()}")
            try:
                reply = self.request({"cmd": Command.PING.value}, timeout_s=0.25)
            except TimeoutError:
                continue
            if reply.get("event") == Event.PONG:
                if reply.get("pid") not in (None, pid):  # another SITL holds this instance's ports
                    raise SitlProcessError(
                        f"instance {self.instance}: its control port is answered by another SITL (pid "
                        f"{reply.get('pid')}); stop it or choose another instance"
                    )
                return
        raise SitlProcessError(f"SITL not ready within {timeout_s} s:\n{log_tail()}")

    def close(self) -> None:
        """Close the socket."""
        self._sock.close()


class ControlledSitl:
    """A running SITL's control requests, through the :class:`ControlClient` it holds while running."""

    _control: ControlClient | None

    def request(self, request: dict[str, Any], timeout_s: float = 2.0) -> dict[str, Any]:
        """A control request and its own reply (:meth:`ControlClient.request`)."""
        assert self._control is not None
        return self._control.request(request, timeout_s)

    def state(self) -> dict[str, Any]:
        """Ground truth and counters."""
        return self.request({"cmd": Command.STATE.value})


class SitlProcess(ControlledSitl):
    """A ``slz sitl`` child process.

    Parameters
    ----------
    args : list of str
        Extra ``slz sitl`` arguments (``--speed``, ``--lockstep``, ``--log``, ...).
    instance : int
        PX4-style instance index (shifts every port).
    log_dir : Path
        Where the process's output is written (``sitl-<instance>.log``).
    cpu : int, optional
        Pin the process to this CPU (benchmarks "on one core").
    """

    def __init__(self, args: list[str], instance: int, log_dir: Path, cpu: int | None = None) -> None:
        # A SITL started by a program renders only when asked to (--camera, or a config file that says so); by
        # hand `slz sitl` streams its camera.
        camera_said = any(a in ("--config", "--camera", "--no-camera") for a in args)
        self.args = list(args) if camera_said else [*args, "--no-camera"]
        self.cpu = cpu
        self.instance = instance
        self.log_path = Path(log_dir) / f"sitl-{instance}.log"
        self.control_addr = ("127.0.0.1", CONTROL_PORT + instance)
        self._proc: subprocess.Popen[bytes] | None = None
        self._control: ControlClient | None = None

    def start(self, ready_timeout_s: float = 20.0) -> SitlProcess:
        """Start the process and wait until it answers on its control channel."""
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        log = open(self.log_path, "wb")  # noqa: SIM115 - owned by the child
        cmd = [sys.executable, "-m", "sitl", "--instance", str(self.instance), *self.args]
        env = child_env()
        cpu = self.cpu

        def pin() -> None:
            die_with_parent()
            if cpu is not None:
                os.sched_setaffinity(0, {cpu})

        self._proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, preexec_fn=pin)
        log.close()
        atexit.register(self.stop)
        self._control = ControlClient(self.instance)
        proc = self._proc
        try:
            self._control.wait_ready(proc.pid, proc.poll, ready_timeout_s, self.log_tail)
        except SitlProcessError:
            self.stop()
            raise
        return self

    @property
    def pid(self) -> int:
        """The child's process id."""
        assert self._proc is not None
        return self._proc.pid

    @property
    def running(self) -> bool:
        """Started and not exited."""
        return self._proc is not None and self._proc.poll() is None

    def wait(self, timeout_s: float) -> int:
        """Wait for the process to exit by itself; its exit code."""
        assert self._proc is not None
        return self._proc.wait(timeout=timeout_s)

    def stop(self, timeout_s: float = 5.0) -> int | None:
        """Ask it to shut down, then terminate, then kill; returns the exit code."""
        proc = self._proc
        if proc is None:
            return None
        if proc.poll() is None:
            with contextlib.suppress(TimeoutError, OSError):
                self.request({"cmd": Command.SHUTDOWN.value}, timeout_s=0.5)
            try:
                proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                terminate_then_kill(proc, timeout_s)
        if self._control is not None:
            self._control.close()
            self._control = None
        atexit.unregister(self.stop)
        self._proc = None
        return proc.returncode

    def log_tail(self, lines: int = 40) -> str:
        """The last lines of the process's log."""
        return log_tail(self.log_path, lines)

    def __enter__(self) -> SitlProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
