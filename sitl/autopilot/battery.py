"""The simulated battery and PX4's battery failsafe.

A pack drained by the motors' thrust (current from the collective command), its remaining fraction read against
PX4's thresholds (``BAT_LOW_THR``, ``BAT_CRIT_THR``, ``BAT_EMERGEN_THR``) as levels that only get worse in a flight,
and the action ``COM_LOW_BAT_ACT`` asks at each: 0 a warning, 1 return at critical, 2 land at critical, 3 return at
critical and land at emergency (PX4's values; a warning is sent at every new level whatever the action).
"""

from __future__ import annotations

import enum

from sitl.autopilot.params import ParameterStore


class Battery:
    """A 4S pack drained by thrust: voltage and remaining fraction.

    Parameters
    ----------
    capacity_mah : float
        Full capacity.
    initial_fraction : float
        Charge at the start, a fraction of the capacity in (0, 1].
    """

    def __init__(self, capacity_mah: float = 5000.0, initial_fraction: float = 1.0) -> None:
        self.capacity_mah = capacity_mah
        self.used_mah = (1.0 - initial_fraction) * capacity_mah
        self.current_a = 0.0

    def update(self, collective: float, dt_s: float, armed: bool) -> None:
        """Draw current for ``dt_s`` at a collective thrust in [0, 1]."""
        self.current_a = (0.5 + 40.0 * collective**1.5) if armed else 0.3
        self.used_mah += self.current_a * dt_s / 3.6

    @property
    def remaining(self) -> float:
        """Fraction of capacity left, [0, 1]."""
        return max(0.0, 1.0 - self.used_mah / self.capacity_mah)

    @property
    def voltage_v(self) -> float:
        """Pack voltage under load."""
        return 4 * (3.5 + 0.7 * self.remaining) - 0.01 * self.current_a

    @property
    def time_remaining_s(self) -> float:
        """Seconds to empty at the present current (PX4's estimate: what BATTERY_STATUS reports)."""
        return (self.capacity_mah - self.used_mah) * 3.6 / max(self.current_a, 0.1)


class BatteryLevel(enum.IntEnum):
    """PX4's battery warning levels, worse upwards (MAV_BATTERY_CHARGE_STATE's order)."""

    OK = 1
    LOW = 2
    CRITICAL = 3
    EMERGENCY = 4


def level_of(remaining: float, params: ParameterStore) -> BatteryLevel:
    """The warning level of a remaining fraction under the live thresholds."""
    if remaining <= params["BAT_EMERGEN_THR"]:
        return BatteryLevel.EMERGENCY
    if remaining <= params["BAT_CRIT_THR"]:
        return BatteryLevel.CRITICAL
    if remaining <= params["BAT_LOW_THR"]:
        return BatteryLevel.LOW
    return BatteryLevel.OK


def failsafe_action(level: BatteryLevel, low_battery_action: int) -> str | None:
    """The failsafe (``rtl`` or ``land``) ``COM_LOW_BAT_ACT`` asks at a level; None: a warning only."""
    if level < BatteryLevel.CRITICAL or low_battery_action == 0:
        return None
    if low_battery_action == 2 or (low_battery_action == 3 and level is BatteryLevel.EMERGENCY):
        return "land"
    return "rtl"


class BatteryMonitor:
    """The worst level reached in this flight: each new, worse level is reported once (PX4 never lifts a battery
    warning in the air, even when the voltage recovers off load)."""

    def __init__(self) -> None:
        self.level = BatteryLevel.OK

    def update(self, remaining: float, params: ParameterStore) -> BatteryLevel | None:
        """The new level when ``remaining`` reaches a worse one, else None."""
        level = level_of(remaining, params)
        if level <= self.level:
            return None
        self.level = level
        return level
