"""MAVProxy, a real ground station from the package registry, driven as a person at its console would: one process,
commands on its stdin, its console output read line by line."""

from __future__ import annotations

import queue
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

# The modules a user's session needs here: parameters (with the FTP attempt first), missions, fence and rally, modes
# and arming. The map, console and log modules would need a display or a disk of their own.
MODULES = "ftp,param,wp,rally,fence,arm,mode,cmdlong,misc,signing"


class MavProxy:
    """A MAVProxy process listening for a vehicle on ``udpin:127.0.0.1:<port>`` (or on the link ``link_args`` give:
    its ``--master`` and target options as a user types them).

    Use as a context manager; :meth:`expect` waits for a console line matching a pattern.
    """

    def __init__(self, port: int, workdir: Path, link_args: list[str] | None = None) -> None:
        executable = shutil.which("mavproxy.py", path=str(Path(sys.executable).parent))
        if executable is None:
            raise FileNotFoundError("mavproxy.py is not installed (the `dev` extra brings it)")
        self.command = [
            sys.executable,
            executable,
            *(link_args if link_args is not None else [f"--master=udpin:127.0.0.1:{port}"]),
            "--no-state",
            "--dialect=common",
            f"--default-modules={MODULES}",
        ]
        self.workdir = workdir
        self.lines: list[tuple[float, str]] = []  # (monotonic time, line), everything it printed
        self._queue: queue.Queue[tuple[float, str]] = queue.Queue()
        self._read = 0  # lines already looked at by expect()
        self._proc: subprocess.Popen[str] | None = None
        self._reader: threading.Thread | None = None

    def __enter__(self) -> MavProxy:
        return self.start()

    def start(self) -> MavProxy:
        """Start the process and its console reader."""
        self._proc = subprocess.Popen(
            self.command,
            cwd=self.workdir,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
        )
        stdout = self._proc.stdout
        assert stdout is not None

        def read() -> None:
            for line in stdout:
                self._queue.put((time.monotonic(), line.rstrip("\n")))

        self._reader = threading.Thread(target=read, name="mavproxy-stdout", daemon=True)
        self._reader.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def send(self, line: str) -> float:
        """Type one command; returns the monotonic time it was sent."""
        assert self._proc is not None
        assert self._proc.stdin is not None
        self._proc.stdin.write(line + "\n")
        self._proc.stdin.flush()
        return time.monotonic()

    def expect(self, pattern: str, timeout_s: float) -> tuple[float, re.Match[str]]:
        """The first line printed after the last match that matches ``pattern``, with the time it was read.

        Raises
        ------
        AssertionError
            Nothing matched within ``timeout_s`` (the message quotes the last lines).
        """
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout_s
        while True:
            while self._read < len(self.lines):
                stamp, line = self.lines[self._read]
                self._read += 1
                match = regex.search(line)
                if match:
                    return stamp, match
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                tail = "\n".join(line for _, line in self.lines[-15:])
                raise AssertionError(f"MAVProxy printed no line matching {pattern!r} in {timeout_s} s; last:\n{tail}")
            try:
                self.lines.append(self._queue.get(timeout=min(remaining, 0.2)))
            except queue.Empty:
                if self._proc is not None and self._proc.poll() is not None and self._queue.empty():
                    raise AssertionError(f"MAVProxy exited ({self._proc.returncode}) waiting for {pattern!r}") from None

    def close(self) -> None:
        """Ask it to exit, then terminate, then kill."""
        proc = self._proc
        if proc is None:
            return
        self._proc = None
        if proc.poll() is None:
            try:
                assert proc.stdin is not None
                proc.stdin.write("exit\n")
                proc.stdin.flush()
                proc.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                proc.terminate()
                try:
                    proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        for stream in (proc.stdin, proc.stdout):
            if stream is not None:
                stream.close()
