"""The warning for the people below: a siren or strobe on an autopilot output, sounded during the landing (issue 53).

After each decision the flight asks :meth:`WarningDevice.follow` whether the device should sound
(``guidance.warning.when``: the whole final descent, to the touchdown; or only while the descent waits at the walker
gate) and, when that changes, sets the output with ``MAV_CMD_DO_SET_ACTUATOR`` (MAVSDK's ``set_actuator``) and records
it. The paper argues that people who notice the vehicle step aside; the SITL's ``scenario.reaction`` models them, and
``docs/results/warning_walkers.md`` measures what it buys.

Like every command, nothing is sent in a dry run or once the pilot has taken over (the record says ``sent: false``):
the device then stays as it was. A refused or unanswered command is recorded and logged, and the landing goes on: the
warning helps the people below, it is not a condition of the landing.
"""

from __future__ import annotations

import logging

from companion.app.commands import VehicleCommands
from companion.flightlog.flight_log import RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.guidance.config import WarningConfig, WarnWhen
from companion.guidance.landing import Decision, LandingPhase
from companion.guidance.vocabulary import DecisionEvent
from companion.vehicle.link import VehicleError

logger = logging.getLogger(__name__)


def warning_wanted(config: WarningConfig, decision: Decision) -> bool:
    """Whether the warning should sound once ``decision`` is taken: in a final descent (to its touchdown, the
    autopilot's landing included) or, with ``when: walker_gate``, only while it waits at the gate."""
    if not config.enabled:
        return False
    if config.when is WarnWhen.WALKER_GATE:
        return decision.phase is LandingPhase.DESCENT and decision.event is DecisionEvent.WAIT_AT_GATE
    return decision.phase in (LandingPhase.DESCENT, LandingPhase.LAND)


class WarningDevice:
    """The flight's warning device.

    Parameters
    ----------
    config : WarningConfig
        Which output, its values, when it sounds.
    commands : VehicleCommands
        The flight's command channel: its action part sends, its ``commanding`` says whether anything may go out.
    recorder : FlightRecorder
        Every switch is recorded (``warning``: ``on``, ``sent``, the decision's phase and event).
    """

    def __init__(self, config: WarningConfig, commands: VehicleCommands, recorder: FlightRecorder) -> None:
        self.config = config
        self.commands = commands
        self.recorder = recorder
        self.on = False
        """Whether the device sounds, as far as this flight asked it."""
        self.switches = 0
        """Switches sent to the autopilot (on and off)."""

    async def follow(self, decision: Decision) -> None:
        """Switch the device on or off when ``decision`` changes whether it should sound."""
        wanted = warning_wanted(self.config, decision)
        if wanted == self.on:
            return
        self.on = wanted
        sent = self.commands.commanding
        self.recorder.write(
            RecordKind.WARNING,
            decision.t_s,
            on=wanted,
            sent=sent,
            phase=decision.phase.value,
            event=decision.event.value,
            actuator=self.config.actuator,
        )
        logger.info(
            "warning device %s (%s, output %d)%s",
            "on" if wanted else "off",
            decision.event.value,
            self.config.actuator,
            "" if sent else ": not sent (a dry run, or the pilot has the vehicle)",
        )
        if not sent:
            return
        value = self.config.on_value if wanted else self.config.off_value
        try:
            await self.commands.action.set_actuator(self.config.actuator, value)
        except VehicleError as exc:  # the landing goes on without it
            logger.warning("warning device %s not switched: %s", "on" if wanted else "off", exc)
            self.recorder.write(RecordKind.ERROR, decision.t_s, where="warning", error=str(exc))
            return
        self.switches += 1
