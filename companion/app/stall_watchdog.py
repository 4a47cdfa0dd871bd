"""The decision loop's stall watchdog: a thread that acts when the event loop stops beating.

MAVSDK keeps re-sending the last offboard setpoint on its own thread, so a decision loop that hangs (a blocked call,
a starved process) would leave the vehicle flying to a stale target with nobody deciding. The event loop beats
(:meth:`StallWatchdog.heartbeat`); a thread checks the beat every quarter of the limit and, while the watchdog is
*engaged* (the companion holds offboard control), calls ``on_stall`` once the beat is older than the limit. Wall
time, on purpose: a stall is a property of this machine, not of the vehicle. The flight loop runs it only when free
running; in lockstep simulated time waits for the loop, so a stall cannot move the vehicle.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Callable

JOIN_TIMEOUT_S = 2.0  # wall time for the thread to end once stopped


class StallWatchdog:
    """Beat from the event loop, watch from a thread.

    Parameters
    ----------
    limit_s : float
        Wall time without a beat after which the loop counts as stalled.
    engaged : callable
        ``() -> bool``: whether a stall matters now (the companion holds offboard control). Read from the thread.
    on_stall : callable
        ``(stalled_s) -> None``, called from the watchdog's thread with how long the loop has been silent; it must
        disengage the watchdog (it is called again at the next check otherwise).
    clock : callable
        Wall clock in seconds (``time.monotonic``; tests pass their own).
    """

    def __init__(
        self,
        limit_s: float,
        engaged: Callable[[], bool],
        on_stall: Callable[[float], None],
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.limit_s = limit_s
        self._engaged = engaged
        self._on_stall = on_stall
        self.clock = clock
        self._beat_s = clock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def beat(self) -> None:
        """The event loop is alive now."""
        self._beat_s = self.clock()

    def stalled_for_s(self) -> float | None:
        """How long the loop has been silent, when that is past the limit and the watchdog is engaged; else None."""
        silent_s = self.clock() - self._beat_s
        return silent_s if silent_s > self.limit_s and self._engaged() else None

    def check(self) -> bool:
        """One check (the thread makes one every ``limit_s / 4``): call ``on_stall`` when stalled. True if it did."""
        silent_s = self.stalled_for_s()
        if silent_s is None:
            return False
        self._on_stall(silent_s)
        return True

    def start(self) -> None:
        """Start the watching thread (a daemon: it never keeps the process alive)."""
        self._thread = threading.Thread(target=self._watch, name="stall-watchdog", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread, if started, and wait for it within ``JOIN_TIMEOUT_S``."""
        self._stop.set()
        if self._thread is not None and self._thread.is_alive():
            self._thread.join(timeout=JOIN_TIMEOUT_S)

    def _watch(self) -> None:
        while not self._stop.wait(self.limit_s / 4):
            self.check()

    async def heartbeat(self, done: asyncio.Event) -> None:
        """Beat every fifth of the limit until ``done`` is set (a task of the flight)."""
        while not done.is_set():
            self.beat()
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(done.wait(), self.limit_s / 5)
