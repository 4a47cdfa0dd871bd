"""Small least-recently-used caches of built values, for values that are pure functions of their key.

The key must hold *everything* that feeds the value, so that a hit hands out what the build would make and the caller
sees the same arrays, cached or not. Used by the zone finder (the bounds mask of each snapped grid) and by the SITL
(what a scene's seed determines: :data:`sitl.render.camera.LIT_GROUNDS` and its neighbours). Per process; nothing is
shared between processes.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

logger = logging.getLogger(__name__)

T = TypeVar("T")


class KeyedCache(Generic[T]):
    """A least-recently-used cache of built values.

    Parameters
    ----------
    name : str
        For the log and the counters.
    capacity : int
        Entries kept; the least recently used goes first.
    """

    def __init__(self, name: str, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"{name}: capacity must be >= 1, got {capacity}")
        self.name = name
        self.capacity = capacity
        self.hits = 0
        self.misses = 0
        self._entries: OrderedDict[Hashable, T] = OrderedDict()

    def get(self, key: Hashable, build: Callable[[], T]) -> T:
        """The value kept under ``key``, or ``build()`` kept there (the caller must not change what it gets)."""
        if key in self._entries:
            self.hits += 1
            self._entries.move_to_end(key)
            return self._entries[key]
        self.misses += 1
        value = build()
        self._entries[key] = value
        while len(self._entries) > self.capacity:
            self._entries.popitem(last=False)
        return value

    def clear(self) -> None:
        """Forget everything (counters kept)."""
        self._entries.clear()

    def __len__(self) -> int:
        return len(self._entries)
