"""Structured concurrency that also runs on Python 3.10 (no ``asyncio.TaskGroup``): tasks created together, kept,
and ended together when the first one ends or fails."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Coroutine
from typing import Any

logger = logging.getLogger(__name__)


async def run_until_first_ends(coroutines: list[Coroutine[Any, Any, Any]], done: asyncio.Event, grace_s: float) -> None:
    """Run the coroutines as tasks, beside one that waits for ``done``, until the first task ends; then set ``done``,
    cancel every task and wait for them, ``grace_s`` wall seconds at most (the ones still running are logged).

    Each coroutine should also end by itself on ``done``: on Python 3.10 and 3.11 ``asyncio.wait_for`` can lose a
    cancellation that arrives as its timeout fires (gh-86296, seen here under load: a dry run went on deciding after
    its mission timeout).

    Raises
    ------
    Exception
        The first failed task's exception, once every task has ended or the grace has passed.
    """
    tasks: list[asyncio.Task[Any]] = [asyncio.create_task(c) for c in coroutines]
    tasks.append(asyncio.create_task(done.wait(), name="done"))
    try:
        finished, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        for task in finished:
            if not task.cancelled() and task.exception() is not None:
                raise task.exception()  # type: ignore[misc]
    finally:
        done.set()
        for task in tasks:
            task.cancel()
        _, pending = await asyncio.wait(tasks, timeout=grace_s)
        for task in pending:
            logger.error("task %s did not stop within %g s of its cancellation", task.get_name(), grace_s)


async def unless_done(coroutine: Coroutine[Any, Any, Any], done: asyncio.Event, grace_s: float) -> bool:
    """Run ``coroutine`` until it ends, or until ``done`` is set first: then cancel it and wait for it, ``grace_s``
    wall seconds at most. True when it ended by itself (its exception raised here), False when ``done`` came first.

    For a wait that has its own deadline but must not outlive the run: a start sequence looking for a vehicle that
    went away with a stopped SITL would otherwise hold the process for its whole connect timeout."""
    work = asyncio.create_task(coroutine, name="work")
    ended = asyncio.create_task(done.wait(), name="done")
    try:
        await asyncio.wait({work, ended}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        ended.cancel()
        if not work.done():
            work.cancel()
            _, pending = await asyncio.wait({work}, timeout=grace_s)
            if pending:
                logger.error("%s did not stop within %g s of its cancellation", work.get_name(), grace_s)
    if work.cancelled() or not work.done():
        return False
    work.result()
    return True
