"""The SITL's one simulated clock and how it is paced against the wall clock.

Simulated time advances in fixed physics steps. Pacing:

- ``speed_factor > 0``: at most that many simulated seconds per wall second (1 = real time);
- ``speed_factor == 0``: as fast as the CPU allows;
- lockstep (either pacing): at each tick (every ``lockstep_period_s``) simulated time stops until the client has
  acknowledged the tick, and has sent everything it said it sent before the ack.

The simulated trajectory depends only on the inputs applied at each step, never on the wall clock: in lockstep,
client inputs are applied at tick boundaries, so the same seed and inputs give the same run at any speed.
"""

from __future__ import annotations

import time


class SimClock:
    """Simulated time in whole physics steps, with wall-clock pacing.

    Parameters
    ----------
    step_s : float
        Physics step.
    speed_factor : float
        Simulated seconds per wall second; 0 for as fast as possible.
    """

    def __init__(self, step_s: float, speed_factor: float) -> None:
        self.step_s = step_s
        self.speed_factor = speed_factor
        self.steps = 0
        self._wall_origin = time.monotonic()
        self._sim_origin = 0.0

    @property
    def now_s(self) -> float:
        """Simulated seconds since boot (exact multiple of the step)."""
        return self.steps * self.step_s

    def advance(self) -> None:
        """One physics step."""
        self.steps += 1

    def wall_time_until_next_step(self) -> float:
        """Wall seconds to wait before the next step may run (0 when it may run now)."""
        if self.speed_factor <= 0:
            return 0.0
        due = self._wall_origin + (self.now_s + self.step_s - self._sim_origin) / self.speed_factor
        return max(0.0, due - time.monotonic())

    def resync(self) -> None:
        """Forget lost wall time (after a lockstep wait), so pacing does not race to catch up."""
        self._wall_origin = time.monotonic()
        self._sim_origin = self.now_s
