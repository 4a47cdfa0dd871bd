"""A MAVSDK client process (:mod:`sitl.testing.mavsdk_flight`) and the JSON events it prints."""

from __future__ import annotations

import json
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from sitl.harness.process import REPO_ROOT
from sitl.testing.helpers import api_port


class Client:
    """A MAVSDK client process and the JSON events it prints."""

    def __init__(self, scenario: str, instance: int) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "sitl.testing.mavsdk_flight", scenario, "--port", str(api_port(instance))],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            cwd=REPO_ROOT,
            text=True,
        )
        self.events: queue.Queue[dict[str, Any]] = queue.Queue()
        self.seen: list[dict[str, Any]] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("{"):
                self.events.put(json.loads(line))

    def expect(self, event: str, timeout_s: float, on_poll: Callable[[], None] | None = None) -> dict[str, Any]:
        """Wait for ``event``; an ``error`` event or a deadline fails the test."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if on_poll is not None:
                on_poll()
            try:
                item = self.events.get(timeout=0.1)
            except queue.Empty:
                continue
            self.seen.append(item)
            if item["event"] == "error":
                raise AssertionError(f"client failed: {item['error']} (events so far: {self.seen})")
            if item["event"] == event:
                return item
        raise AssertionError(f"no '{event}' from the client within {timeout_s} s (events: {self.seen})")

    def kill(self) -> None:
        """SIGKILL: the process and MAVSDK's setpoint thread die at once."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)
