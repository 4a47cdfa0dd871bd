"""The vehicle's generic actuator outputs, as ``MAV_CMD_DO_SET_ACTUATOR`` sets them, and the warning device on one.

PX4 maps the command's params 1-6 to its "Offboard Actuator Set 1-6" output functions (param 7, the actuator set, is
0: PX4 has one set); each value is in [-1, 1], NaN leaving that output as it is. A payload such as a siren or a strobe
wired to one of those outputs is on while its value is above 0. MAVSDK's ``Action.set_actuator(index, value)`` sends
this command with ``index`` 1-6 choosing the param.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence

from sitl.autopilot.status import MavResult

logger = logging.getLogger(__name__)

OUTPUTS = 6
"""Offboard actuator outputs in PX4's one set."""

WarningListener = Callable[[float, float, float, bool], None]
"""Told of each change of the warning device: simulated time (s), the vehicle's north and east (m, local NED), on."""


class ActuatorOutputs:
    """Six outputs, all 0 at start, and a warning device wired to output ``warning_output`` (1-6).

    Parameters
    ----------
    warning_output : int
        The output the warning device is wired to.
    """

    def __init__(self, warning_output: int) -> None:
        if not 1 <= warning_output <= OUTPUTS:
            raise ValueError(f"warning_output must lie in [1, {OUTPUTS}], got {warning_output}")
        self.warning_output = warning_output
        self.values = [0.0] * OUTPUTS
        self.listeners: list[WarningListener] = []
        self.warnings = 0
        """How many times the warning device was switched on."""

    @property
    def warning_on(self) -> bool:
        """Whether the warning device sounds now."""
        return self.values[self.warning_output - 1] > 0.0

    def command(
        self, params: Sequence[float], actuator_set: float, t_s: float, north_m: float, east_m: float
    ) -> MavResult:
        """``MAV_CMD_DO_SET_ACTUATOR`` with ``params`` 1-6 and param 7 (``actuator_set``), received at simulated ``t_s``
        with the vehicle at (``north_m``, ``east_m``): DENIED for a set other than 0 or a value outside [-1, 1], every
        output unchanged then; the warning's listeners are told when it switches."""
        if len(params) != OUTPUTS:
            raise ValueError(f"expected {OUTPUTS} params, got {len(params)}")
        if not (math.isnan(actuator_set) or actuator_set == 0.0):
            return MavResult.DENIED
        if any(math.isinf(v) or (math.isfinite(v) and not -1.0 <= v <= 1.0) for v in params):
            return MavResult.DENIED
        was_on = self.warning_on
        self.values = [old if math.isnan(new) else float(new) for old, new in zip(self.values, params, strict=True)]
        if self.warning_on != was_on:
            self.warnings += self.warning_on
            logger.info(
                "warning device %s at %.3f s over (%.1f, %.1f)",
                "on" if self.warning_on else "off",
                t_s,
                north_m,
                east_m,
            )
            for listener in self.listeners:
                listener(t_s, north_m, east_m, self.warning_on)
        return MavResult.ACCEPTED
