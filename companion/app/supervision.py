"""What ends a flight besides its decisions: the watch after a failsafe, the end of a dry run, a stop asked of the
program, and the wall limit of ``slz fly --timeout``.

:class:`Supervision` holds their state and says, when asked at a tick, whether one of them has come; the flight loop
(:mod:`companion.app.flight`) acts on it (a last resort through the state machine, a record, the end), as it acts on
the start sequence's steps. Everything here but the wall limit and the unheard stop reads the vehicle's telemetry;
those two are wall time on purpose (a limit of this program, and a tick that may never come).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from companion.guidance.landing import CommandKind, Decision, LandingPhase
from companion.vehicle.link import FlightMode, VehicleStatus

COMPANION_MODES = (FlightMode.OFFBOARD, FlightMode.UNKNOWN)
"""Modes in which offboard setpoints are still the companion's (UNKNOWN: telemetry not yet telling)."""
FAILSAFE_MODES = {
    CommandKind.HOLD: frozenset({FlightMode.HOLD}),
    CommandKind.RETURN: frozenset({FlightMode.RETURN_TO_LAUNCH, FlightMode.LAND, FlightMode.HOLD}),
    CommandKind.LAND: frozenset({FlightMode.LAND}),
}
"""The modes a failsafe command leads to (PX4: a return ends in the autopilot's own landing, then its hold)."""


@dataclass(frozen=True)
class SupervisionEnd:
    """Why supervision ends the run: ``event`` (the ``supervision`` record's: on_ground, pilot_has_it) and words."""

    event: str
    reason: str


class Supervision:
    """The flight's supervision state (see the module docstring).

    Parameters
    ----------
    stay_after_failsafe : bool
        After a failsafe command that went out, stay and watch until the vehicle is on the ground or the pilot has
        it (``supervision.stay_after_failsafe``).
    wall_limit_s : float or None
        Wall seconds from now to the wall limit (None: none).
    wall_clock : callable
        Monotonic wall seconds, for that limit alone.
    """

    def __init__(self, stay_after_failsafe: bool, wall_limit_s: float | None, wall_clock: Callable[[], float]) -> None:
        self.stay_after_failsafe = stay_after_failsafe
        self.wall_limit_s = wall_limit_s
        self._wall_clock = wall_clock
        self._wall_deadline = None if wall_limit_s is None else wall_clock() + wall_limit_s
        self.watching: CommandKind | None = None
        """After a failsafe command: what the autopilot was asked to do (None: no watch)."""
        self.airborne_seen = False
        """The vehicle has been in the air during this run (a dry run ends on the ground)."""
        self.stop_requested: str | None = None
        """Why the program is asked to stop (a signal), taken at the next tick."""
        self._end_after_failsafe = False  # a stop: the last resort goes out, then the program ends (no watch)

    def saw(self, status: VehicleStatus) -> None:
        """The vehicle's telemetry at a tick."""
        if status.in_air:
            self.airborne_seen = True

    # -- after a failsafe ---------------------------------------------------------------------------------------
    def stays_after(self, decision: Decision, sent: bool) -> bool:
        """Whether the run stays and watches after this terminal decision (a failsafe command that went out, unless a
        stop asked for it)."""
        stay = self.stay_after_failsafe and not self._end_after_failsafe
        return sent and decision.phase is LandingPhase.FAILSAFE and stay

    def watch(self, kind: CommandKind) -> None:
        """Watch the vehicle after the failsafe command ``kind``."""
        self.watching = kind

    def watch_ends(self, status: VehicleStatus) -> SupervisionEnd | None:
        """The end of the watch: the vehicle on the ground, or in a mode the pilot chose (not the one the failsafe
        asked for; OFFBOARD still reported is telemetry lagging the command)."""
        asked = FAILSAFE_MODES.get(self.watching or CommandKind.NONE, frozenset())
        if not status.in_air:
            return SupervisionEnd("on_ground", "on the ground")
        if status.mode not in asked and status.mode not in COMPANION_MODES:
            return SupervisionEnd("pilot_has_it", f"the pilot has it (mode {status.mode.value})")
        return None

    def flight_over(self, status: VehicleStatus) -> bool:
        """A dry run's flight is over: the vehicle, having flown, is on the ground and disarmed."""
        return self.airborne_seen and not status.in_air and not status.armed

    # -- a stop asked of the program --------------------------------------------------------------------------
    def ask_stop(self, why: str) -> bool:
        """A stop is asked (``why``); False when one was asked already (the program should end at once)."""
        if self.stop_requested is not None:
            return False
        self.stop_requested = why
        return True

    def take_stop(self, last_resort: bool) -> str | None:
        """The stop asked, taken at a tick (None: none); ``last_resort``: it sends the last resort, after which the
        program ends without a watch."""
        why, self.stop_requested = self.stop_requested, None
        if why is not None and last_resort:
            self._end_after_failsafe = True
        return why

    def stop_unheard(self) -> str | None:
        """The stop no tick has taken (its ``why``), dropped; None when one was taken."""
        why, self.stop_requested = self.stop_requested, None
        return why

    # -- the wall limit -------------------------------------------------------------------------------------------
    def wall_limit_reached(self) -> str | None:
        """The wall limit's words, once, when it has passed (None before, and after it was reported)."""
        if self._wall_deadline is None or self._wall_clock() < self._wall_deadline:
            return None
        self._wall_deadline = None
        return f"wall limit of {self.wall_limit_s:g} s reached (slz fly --timeout)"
