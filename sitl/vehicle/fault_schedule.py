"""The faults a SITL run injects (``faults:`` of its config), handed out as simulated time reaches them."""

from __future__ import annotations

from collections.abc import Sequence

from sitl.config import FaultConfig


class FaultSchedule:
    """Faults in the order of their times; each is due once.

    Parameters
    ----------
    faults : sequence of FaultConfig
        The config's faults, in any order (two at one instant keep the config's order).
    """

    def __init__(self, faults: Sequence[FaultConfig]) -> None:
        self._pending = sorted(faults, key=lambda f: f.at_s)

    def __bool__(self) -> bool:
        """Whether a fault is still to come."""
        return bool(self._pending)

    def due(self, t_s: float) -> list[FaultConfig]:
        """The faults whose time has come at simulated ``t_s`` (s) and were not handed out before."""
        due = []
        while self._pending and t_s >= self._pending[0].at_s - 1e-9:
            due.append(self._pending.pop(0))
        return due
