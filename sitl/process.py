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
from pathlib import Path
from typing import Any

from companion.vehicle.sim_control import Command, Event
from sitl.config import CONTROL_PORT

logger = logging.getLogger(__name__)


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


class SitlProcessError(Exception):
    """The SITL process failed to start, answer or stop (what, and the end of its log)."""


class SitlProcess:
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
        self.args = list(args)
        self.cpu = cpu
        self.instance = instance
        self.log_path = Path(log_dir) / f"sitl-{instance}.log"
        self.control_addr = ("127.0.0.1", CONTROL_PORT + instance)
        self._proc: subprocess.Popen[bytes] | None = None
        self._sock: socket.socket | None = None
        self._request_id = 0

    def start(self, ready_timeout_s: float = 20.0) -> SitlProcess:
        """Start the process and wait until it answers on its control channel."""
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        log = open(self.log_path, "wb")  # noqa: SIM115 - owned by the child
        cmd = [sys.executable, "-m", "sitl", "--instance", str(self.instance), *self.args]
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        cpu = self.cpu

        def pin() -> None:
            die_with_parent()
            if cpu is not None:
                os.sched_setaffinity(0, {cpu})

        self._proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, preexec_fn=pin)
        log.close()
        atexit.register(self.stop)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        deadline = time.monotonic() + ready_timeout_s
        while time.monotonic() < deadline:
            if self._proc.poll() is not None:
                raise SitlProcessError(f"SITL exited with {self._proc.returncode} at start:\n{self.log_tail()}")
            try:
                reply = self.request({"cmd": Command.PING.value}, timeout_s=0.25)
            except TimeoutError:
                continue
            if reply.get("event") == Event.PONG:
                if reply.get("pid") not in (None, self._proc.pid):  # another SITL holds this instance's ports
                    self.stop()
                    raise SitlProcessError(
                        f"instance {self.instance}: its control port is answered by another SITL (pid "
                        f"{reply.get('pid')}); stop it or choose another instance"
                    )
                return self
        self.stop()
        raise SitlProcessError(f"SITL not ready within {ready_timeout_s} s:\n{self.log_tail()}")

    @property
    def pid(self) -> int:
        """The child's process id."""
        assert self._proc is not None
        return self._proc.pid

    def request(self, request: dict[str, Any], timeout_s: float = 2.0) -> dict[str, Any]:
        """Send a control request and wait for its own reply (``TimeoutError`` after ``timeout_s``).

        Each request carries an id that the SITL echoes, so a late reply to an earlier request is never taken for
        this one's.
        """
        assert self._sock is not None
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

    def state(self) -> dict[str, Any]:
        """Ground truth and counters."""
        return self.request({"cmd": Command.STATE.value})

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
        if self._sock is not None:
            self._sock.close()
            self._sock = None
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
