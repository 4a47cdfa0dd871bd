"""How a run ends besides its decisions, acted on: the watch after a failsafe command and its end, the end of a dry
run on the ground, a stop asked of the program that no tick takes, and any end without a command.

:class:`~companion.app.supervision.Supervision` says when one of them has come; :class:`RunEnd` writes what happened
(the outcome's reason, a ``supervision`` record, a log line) and ends the run. A stop or a wall limit that gives the
vehicle its last resort goes through the state machine instead (:mod:`companion.app.flight`).
"""

from __future__ import annotations

import asyncio
import logging

from companion.app.outcome import FlightOutcome
from companion.app.supervision import Supervision
from companion.flightlog.flight_log import RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.guidance.landing import Decision
from companion.guidance.vehicle_state import VehicleState
from companion.vehicle.link import VehicleStatus

logger = logging.getLogger(__name__)

STOP_UNHEARD_S = 3.0  # wall time a stop waits for a tick to send the last resort in; then it ends without one


class RunEnd:
    """Ends the run (sets ``done``) and says why.

    Parameters
    ----------
    supervision : Supervision
        The supervision state it acts on.
    recorder : FlightRecorder
        The ``supervision`` records.
    outcome : FlightOutcome
        Its reason and touchdown.
    done : asyncio.Event
        Set to end the run.
    """

    def __init__(
        self, supervision: Supervision, recorder: FlightRecorder, outcome: FlightOutcome, done: asyncio.Event
    ) -> None:
        self.supervision = supervision
        self.recorder = recorder
        self.outcome = outcome
        self.done = done

    def over(self) -> None:
        """The flight is over, nothing more to record: its last decision went out, or the logic already ended it (the
        run's tasks end)."""
        self.done.set()

    def end(
        self, t_s: float | None, event: str, reason: str, outcome_reason: str | None = None, warn: bool = False
    ) -> None:
        """End the run without a command: ``reason`` in a ``supervision`` record of ``event`` and the outcome's
        reason (``outcome_reason`` where it says more); ``warn``: also a warning in the log."""
        if warn:
            logger.warning("%s", reason)
        self.outcome.reason = reason if outcome_reason is None else outcome_reason
        self.recorder.write(RecordKind.SUPERVISION, t_s, event=event, reason=reason)
        self.done.set()

    def watch(self, decision: Decision) -> None:
        """Stay after a failsafe command: until the vehicle is on the ground or the pilot has it."""
        self.supervision.watch(decision.kind)
        reason = f"{decision.reason}: watching until the vehicle is on the ground or the pilot has it"
        self.recorder.write(RecordKind.SUPERVISION, decision.t_s, event="watching", reason=reason)
        logger.warning("%s", reason)

    def watch_tick(self, state: VehicleState, status: VehicleStatus) -> None:
        """After a failsafe command: end once the vehicle is on the ground, or the pilot has switched it to a mode
        other than the one the failsafe asked for (OFFBOARD still reported is telemetry lagging the command); a stop
        asked for (Ctrl-C, the service stopped) ends it at once: the vehicle is the autopilot's, nothing to give it."""
        if self.supervision.stop_requested is not None:
            asked = self.supervision.take_stop(last_resort=False)
            words = f"{asked} while watching after the failsafe: the vehicle is the autopilot's, the program ends"
            self.end(state.t_s, "stopped", words, f"{self.outcome.reason}; {words}", warn=True)
            return
        end = self.supervision.watch_ends(status)
        if end is None:
            return
        reason = end.reason
        if end.event == "on_ground":
            self.outcome.touchdown_ne_m = (state.north_m, state.east_m)
            self.outcome.touchdown_t_s = state.t_s
            reason = f"{reason} at north {state.north_m:.1f} m, east {state.east_m:.1f} m"
        logger.warning("after the failsafe: %s", reason)
        self.end(state.t_s, end.event, reason, f"{self.outcome.reason}; {reason}")

    def flight_over(self, state: VehicleState, status: VehicleStatus, decided: bool) -> bool:
        """A dry run ends once the vehicle, having flown, is on the ground and disarmed (the whole flight logged);
        ``decided``: decisions were made, whose last reason the outcome keeps."""
        if not self.supervision.flight_over(status):
            return False
        reason = "the flight is over: on the ground and disarmed"
        logger.info("[dry run] %s", reason)
        self.end(state.t_s, "on_ground", reason, f"{self.outcome.reason}; {reason}" if decided else None)
        return True

    def request_stop(self, why: str) -> None:
        """Ask the run to stop (see :meth:`companion.app.flight.FlightApp.request_stop`); asked twice, it ends at
        once; if no tick takes it within ``STOP_UNHEARD_S``, it ends without the last resort."""
        if not self.supervision.ask_stop(why):
            logger.error("%s again: ending now", why)
            self.done.set()
            return
        logger.warning("%s: the vehicle gets the last resort, then the program ends", why)
        # No tick may come again (a SITL stopped with us, a link gone): the stop must not wait on one.
        asyncio.get_running_loop().call_later(STOP_UNHEARD_S, self._stop_unheard, why)

    def _stop_unheard(self, why: str) -> None:
        if self.done.is_set() or self.supervision.stop_unheard() is None:
            return
        reason = f"{why}: no vehicle tick within {STOP_UNHEARD_S:g} s, ending without the last resort"
        logger.error("%s", reason)
        self.end(None, "stopped", reason)
