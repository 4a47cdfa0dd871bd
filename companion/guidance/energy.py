"""The energy budget: how long the search may go on, from the battery the autopilot reports.

A fixed time limit is the wrong budget for a vehicle whose pack may be half used when the search begins. Here the
budget is the charge above a reserve the companion never plans against (``reserve_fraction``, set above the
autopilot's own critical threshold), at the current the vehicle draws (smoothed over ``current_smoothing_s`` of
vehicle time), less what getting home and down costs at ``return_speed_mps`` and ``descent_speed_mps`` with a
``margin``. When what is left no longer covers that, the search ends with ``action`` (return, by default): the
vehicle comes home on the companion's word while it still can, before the autopilot's low-battery failsafe must act.

Everything here reads telemetry and the vehicle clock only; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.guidance.config import EnergyConfig
from companion.guidance.vehicle_state import VehicleState
from companion.vehicle.link import VehicleStatus


@dataclass(frozen=True)
class EnergyEstimate:
    """What the budget says at one instant.

    Attributes
    ----------
    remaining : float
        The pack's remaining fraction, as reported.
    current_a : float
        The smoothed current draw.
    seconds_left : float
        Vehicle seconds of flight above the reserve at that current.
    needed_s : float
        Seconds home and down, with the margin.
    home_m : float
        Horizontal distance home (a fallback site no farther costs no more than the return the budget keeps).
    """

    remaining: float
    current_a: float
    seconds_left: float
    needed_s: float
    home_m: float

    @property
    def used_up(self) -> bool:
        """What is left no longer covers getting home and down."""
        return self.seconds_left <= self.needed_s

    def reason(self) -> str:
        """In words, for the decision and the ground station."""
        return (
            f"energy budget used up: {100 * self.remaining:.0f} % left, {self.seconds_left:.0f} s above the reserve "
            f"at {self.current_a:.1f} A, {self.needed_s:.0f} s needed home and down"
        )


class EnergyBudget:
    """The budget of one flight (see the module docstring).

    Parameters
    ----------
    config : EnergyConfig
        Enabled, with its capacity.
    """

    def __init__(self, config: EnergyConfig) -> None:
        if config.capacity_mah is None:
            raise ValueError("the energy budget needs capacity_mah")
        self.config = config
        self._capacity_mah = config.capacity_mah
        self._current_a: float | None = None
        self._t_s: float | None = None

    def observe(self, t_s: float, current_a: float) -> None:
        """One current reading at vehicle time ``t_s`` (amperes; a non-finite or negative one is ignored)."""
        if not math.isfinite(current_a) or current_a < 0.0:
            return
        if self._current_a is None or self._t_s is None:
            self._current_a, self._t_s = current_a, t_s
            return
        dt_s = max(0.0, t_s - self._t_s)
        weight = 1.0 - math.exp(-dt_s / self.config.current_smoothing_s)
        self._current_a += weight * (current_a - self._current_a)
        self._t_s = t_s

    def check(self, state: VehicleState, status: VehicleStatus) -> EnergyEstimate | None:
        """At a tick: read the status's current, and the estimate when the budget is used up (else None)."""
        if status.battery_current_a is not None:
            self.observe(state.t_s, status.battery_current_a)
        if status.battery_remaining is None:
            return None
        estimate = self.estimate(state, status.battery_remaining, status.home_ne_m or (0.0, 0.0))
        return estimate if estimate is not None and estimate.used_up else None

    def estimate(self, state: VehicleState, remaining: float, home_ne_m: tuple[float, float]) -> EnergyEstimate | None:
        """The budget at ``state`` with ``remaining`` (a fraction) reported and home at ``home_ne_m`` (local NED);
        None before a current has been read."""
        if self._current_a is None or not math.isfinite(remaining):
            return None
        c = self.config
        current_a = max(self._current_a, 0.1)
        seconds_left = (remaining - c.reserve_fraction) * self._capacity_mah * 3.6 / current_a
        home_m = math.hypot(state.north_m - home_ne_m[0], state.east_m - home_ne_m[1])
        needed_s = c.margin * (home_m / c.return_speed_mps + max(0.0, state.altitude_m) / c.descent_speed_mps)
        return EnergyEstimate(remaining, current_a, seconds_left, needed_s, home_m)
