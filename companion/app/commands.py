"""What a flight sends to its vehicle: one decision's command at a time.

OFFBOARD is entered once, with the first setpoint, and counts only once the autopilot reports it. Nothing more goes
out once the pilot's mode is reported (this flight never takes control back), after the link is lost or the decision
loop stalled (:meth:`VehicleCommands.stop`), or in a dry run.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time

from companion.app.outcome import FlightOutcome
from companion.app.supervision import COMPANION_MODES
from companion.flightlog.flight_log import RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.guidance.landing import CommandKind, Decision
from companion.vehicle.link import Action, FlightMode, LinkResult, Offboard, Telemetry, VehicleError
from companion.vehicle.sim_control import SetpointNedYaw

logger = logging.getLogger(__name__)

OFFBOARD_CONFIRM_S = 3.0  # wall time for the autopilot to report OFFBOARD after accepting it


class VehicleCommands:
    """The flight's command channel to the vehicle.

    Parameters
    ----------
    telemetry, action, offboard : Telemetry, Action, Offboard
        The connected vehicle's parts this channel uses: the mode it reports, its commands and its setpoints.
    recorder : FlightRecorder
        Each command, and each one that failed, is recorded.
    outcome : FlightOutcome
        ``commands_sent`` is counted here.
    dry_run : bool
        Nothing is ever sent.
    """

    def __init__(
        self,
        telemetry: Telemetry,
        action: Action,
        offboard: Offboard,
        recorder: FlightRecorder,
        outcome: FlightOutcome,
        dry_run: bool,
    ) -> None:
        self.telemetry = telemetry
        self.action = action
        self.offboard = offboard
        self.recorder = recorder
        self.outcome = outcome
        self.in_offboard = False
        """The vehicle flies this flight's setpoints in OFFBOARD (as far as this flight knows)."""
        self.commanding = not dry_run
        """Commands may go out: False in a dry run, and for good after the pilot took over, a lost link or a stall."""
        self.tick_setpoint: SetpointNedYaw | None = None
        """The setpoint sent during this lockstep tick (the simulator checks it arrived)."""
        self._lock = asyncio.Lock()

    @property
    def flying_offboard(self) -> bool:
        """Setpoints are being flown and may still be sent (what the stall watchdog guards)."""
        return self.in_offboard and self.commanding

    async def send(self, decision: Decision) -> bool:
        """Send one decision's command; whether it went out. One at a time: the frame and tick loops both decide,
        and a second command must not start OFFBOARD again while the first waits for the autopilot to report it (the
        pilot may have taken over in between: this flight never takes control back)."""
        async with self._lock:
            if not self.commanding or decision.kind is CommandKind.NONE:
                return False
            if self.pilot_has_it():
                return False  # the pilot's mode since the last tick: nothing more goes out (no setpoint, no land, no
                # hold or return either: that would take the vehicle back), and the next tick yields
            await self._send_one(decision)
            return True

    async def _send_one(self, decision: Decision) -> None:
        try:
            if decision.kind is CommandKind.SETPOINT:
                sp = decision.setpoint
                assert sp is not None
                if not self.in_offboard:
                    status = self.telemetry.status
                    entries = status.offboard_entries
                    await self.offboard.start(sp)
                    # Takeover detection starts only once the autopilot reports OFFBOARD (telemetry lags the ack).
                    # An entry reported since the request confirms it too, though the pilot may have switched away
                    # already: then the next tick sees the pilot's mode and yields.
                    await self.telemetry.wait_for(
                        lambda: status.mode is FlightMode.OFFBOARD or status.offboard_entries > entries,
                        time.monotonic() + OFFBOARD_CONFIRM_S,
                        "OFFBOARD",
                    )
                    self.in_offboard = True
                else:
                    await self.offboard.set_setpoint(sp)
                self.tick_setpoint = SetpointNedYaw(sp.north_m, sp.east_m, sp.down_m, math.radians(sp.yaw_deg))
            elif decision.kind is CommandKind.LAND:
                await self.action.land()
            elif decision.kind is CommandKind.HOLD:
                await self.action.hold()
            elif decision.kind is CommandKind.RETURN:
                await self.action.return_to_launch()
        except VehicleError as exc:
            self.recorder.write(RecordKind.ERROR, decision.t_s, where="command", error=str(exc), result=exc.result)
            raise
        self.outcome.commands_sent += 1
        self.recorder.write(RecordKind.COMMAND, decision.t_s, command=decision.kind, setpoint=decision.setpoint)
        if decision.kind is not CommandKind.SETPOINT:
            self.in_offboard = False  # the autopilot's own mode now

    async def take_off(self, t_s: float, altitude_m: float) -> bool:
        """Arm and take off to ``altitude_m`` above home; whether the autopilot accepted it (a refusal, pre-arm
        checks not passed yet, or no answer, is counted and logged: the start sequence asks again later, on vehicle
        time); any other link error is raised."""
        try:
            await self.action.take_off(altitude_m)
        except VehicleError as exc:
            if exc.result not in (LinkResult.REFUSED, LinkResult.TIMEOUT):
                raise
            self.outcome.takeoff_refusals += 1
            logger.info("takeoff not accepted yet: %s", exc)
            return False
        self.recorder.write(RecordKind.TAKEOFF, t_s, altitude_m=altitude_m)
        return True

    def take_tick_setpoint(self) -> SetpointNedYaw | None:
        """The setpoint sent during this tick, once (None when none was)."""
        setpoint, self.tick_setpoint = self.tick_setpoint, None
        return setpoint

    def pilot_has_it(self) -> bool:
        """This flight's setpoints were flown and the autopilot now reports a mode of the pilot's."""
        return self.flying_offboard and self.telemetry.status.mode not in COMPANION_MODES

    def stop(self) -> None:
        """Command nothing more in this flight (the pilot took over, the link is lost)."""
        self.in_offboard = False
        self.commanding = False

    def stalled(self, stalled_s: float) -> None:
        """The stall watchdog's action, on its thread: stop offboard, and command nothing more in this flight."""
        logger.error("decision loop stalled for %.2f s: stopping offboard", stalled_s)
        self.offboard.stop_blocking()
        self.stop()
