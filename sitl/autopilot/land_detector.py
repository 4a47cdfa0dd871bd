"""The autopilot's land detector, PX4's simplified: on the ground, taking off, in the air, landing, and on the ground
again after touching down with little thrust for a moment; then the disarm after landing (``COM_DISARM_LAND``).

The commander says when a takeoff starts (a setpoint asks to climb) and acts on what the detector reports.
"""

from __future__ import annotations

import enum
import math

from sitl.autopilot.status import LandedState

IN_AIR_ABOVE_M = 0.5  # above home: a takeoff is in the air
TOUCHING_BELOW_MPS = 0.3  # on the ground and slower than this: touching down
LOW_THRUST_SHARE = 0.9  # of the hover thrust: a vehicle touching down with less is landing
LANDED_AFTER_S = 0.5  # touching down this long: landed


class LandEvent(enum.Enum):
    """What an update of the detector reports."""

    LANDED = "landed"
    """Landing detected at this update."""
    DISARM_DUE = "disarm_due"
    """Landed and armed for ``COM_DISARM_LAND`` since: disarm."""


class LandDetector:
    """The landed state and how long the vehicle has been touching down (see the module docstring)."""

    def __init__(self) -> None:
        self.state = LandedState.ON_GROUND
        self.landed_since_s = math.nan
        """Since when (simulated s) the vehicle touches down, or has landed and is still armed; NaN otherwise."""

    def reset_landed_time(self) -> None:
        """Forget since when the vehicle touched down (armed again: the disarm after landing starts over)."""
        self.landed_since_s = math.nan

    def take_off(self) -> None:
        """A takeoff starts (the commander's word: armed on the ground, a setpoint asks to climb)."""
        self.state = LandedState.TAKEOFF
        self.landed_since_s = math.nan

    def update(
        self,
        t_s: float,
        altitude_m: float,
        touching: bool,
        low_thrust: bool,
        armed: bool,
        landing: bool,
        disarm_delay_s: float,
    ) -> LandEvent | None:
        """Advance to ``t_s``.

        Parameters
        ----------
        altitude_m : float
            Above home.
        touching : bool
            On the ground and slower than ``TOUCHING_BELOW_MPS``.
        low_thrust : bool
            Thrust below ``LOW_THRUST_SHARE`` of the hover thrust.
        armed : bool
            Armed (a disarmed vehicle touching down has landed at once).
        landing : bool
            The mode lands (LAND, or a mission's land item).
        disarm_delay_s : float
            ``COM_DISARM_LAND``: seconds after landing to disarm (negative: never).
        """
        if self.state in (LandedState.TAKEOFF, LandedState.IN_AIR, LandedState.LANDING):
            if self.state is LandedState.TAKEOFF and altitude_m > IN_AIR_ABOVE_M:
                self.state = LandedState.IN_AIR
            if self.state is LandedState.IN_AIR and landing:
                self.state = LandedState.LANDING
            if self.state is LandedState.LANDING and not landing:
                self.state = LandedState.IN_AIR
            if touching and (not armed or low_thrust):
                if math.isnan(self.landed_since_s):
                    self.landed_since_s = t_s
                elif t_s - self.landed_since_s >= LANDED_AFTER_S or not armed:
                    self.state = LandedState.ON_GROUND
                    return LandEvent.LANDED
            else:
                self.landed_since_s = math.nan
        elif armed and disarm_delay_s >= 0 and t_s - self.landed_since_s >= LANDED_AFTER_S + disarm_delay_s:
            self.landed_since_s = math.nan  # (NaN since: the comparison is False)
            return LandEvent.DISARM_DUE
        return None
