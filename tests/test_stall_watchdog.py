"""The stall watchdog on a clock the test moves: it acts only past its limit and only while engaged, and its
thread acts without the event loop. FlightApp's use of it is in tests/test_flight_supervision.py."""

from __future__ import annotations

import asyncio
import threading

import pytest

from companion.app.stall_watchdog import StallWatchdog

pytestmark = pytest.mark.unit

LIMIT_S = 0.5


class Clock:
    def __init__(self) -> None:
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s


def watchdog(clock: Clock, engaged: list[bool], stalls: list[float]) -> StallWatchdog:
    def on_stall(stalled_s: float) -> None:
        stalls.append(stalled_s)
        engaged[0] = False  # as the flight does: offboard stopped, nothing more commanded

    return StallWatchdog(LIMIT_S, lambda: engaged[0], on_stall, clock)


def test_a_stall_counts_only_past_the_limit_and_acts_once() -> None:
    clock, engaged, stalls = Clock(), [True], list[float]()
    dog = watchdog(clock, engaged, stalls)
    clock.now_s += LIMIT_S  # exactly at the limit: not yet
    assert not dog.check()
    clock.now_s += 0.01
    assert dog.check()
    assert stalls == pytest.approx([LIMIT_S + 0.01])
    clock.now_s += 5.0
    assert not dog.check()  # disengaged by its own action
    assert len(stalls) == 1


def test_beats_keep_it_quiet_and_a_disengaged_watchdog_never_acts() -> None:
    clock, engaged, stalls = Clock(), [True], list[float]()
    dog = watchdog(clock, engaged, stalls)
    for _ in range(100):
        clock.now_s += 0.9 * LIMIT_S
        dog.beat()
        assert not dog.check()
    engaged[0] = False  # not holding offboard (before the search, in a dry run, after the pilot took over)
    clock.now_s += 100.0
    assert dog.stalled_for_s() is None
    assert not dog.check()
    assert stalls == []


async def test_the_heartbeat_task_beats_until_the_flight_is_done() -> None:
    clock, engaged, stalls = Clock(), [True], list[float]()
    dog = watchdog(clock, engaged, stalls)

    done = asyncio.Event()
    task = asyncio.create_task(dog.heartbeat(done))
    clock.now_s += 10.0
    for _ in range(100):  # event-loop turns until the heartbeat has beaten at the new time
        if dog.stalled_for_s() is None:
            break
        await asyncio.sleep(0)
    assert dog.stalled_for_s() is None
    done.set()
    await asyncio.wait_for(task, 5.0)


def test_the_thread_acts_while_the_event_loop_is_blocked() -> None:
    clock, engaged = Clock(), [True]
    fired = threading.Event()

    def on_stall(stalled_s: float) -> None:
        engaged[0] = False
        fired.set()

    dog = StallWatchdog(LIMIT_S, lambda: engaged[0], on_stall, clock)
    dog.start()
    try:
        clock.now_s += 2 * LIMIT_S  # nobody beats
        assert fired.wait(timeout=5.0)  # a check every quarter of the limit
    finally:
        dog.stop()
    assert not engaged[0]
