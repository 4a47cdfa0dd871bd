"""Opening a camera that may not be up yet: on a drone the camera service and the companion start in any order
(issue 65). :func:`open_when_up` retries within a bound and says what it waits for."""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable

from companion.camera.frames import CameraError, FrameSource

logger = logging.getLogger(__name__)

CAMERA_RETRY_S = 0.5
"""Between two tries to open a camera that is not up yet (wall seconds)."""
CAMERA_SAY_EVERY_S = 5.0
"""How often the wait for the camera is said again (wall seconds)."""


async def open_when_up(
    source: FrameSource, url: str, wait_for_s: float, on_waiting: Callable[[str], None] | None = None
) -> None:
    """Open ``source``, waiting up to ``wait_for_s`` (wall time) for a camera that is not up yet: retried every
    ``CAMERA_RETRY_S``, said once and then every ``CAMERA_SAY_EVERY_S`` (a warning, and ``on_waiting`` with the
    error's words); the last :class:`CameraError` after the bound."""
    deadline = time.monotonic() + wait_for_s
    said_at = -math.inf
    while True:
        try:
            await source.open()
        except CameraError as exc:
            now = time.monotonic()
            if now >= deadline:
                raise
            if now - said_at >= CAMERA_SAY_EVERY_S:
                logger.warning("waiting for the camera at %s (%.0f s left): %s", url, deadline - now, exc)
                if on_waiting is not None:
                    on_waiting(str(exc))
                said_at = now
            await asyncio.sleep(min(CAMERA_RETRY_S, max(0.0, deadline - now)))
            continue
        if said_at > -math.inf:
            logger.info("the camera at %s is up", url)
        return
