"""The start of a flight, before the landing logic runs: no I/O here.

Each tick, :meth:`StartSequence.step` reads the vehicle's state and status and says what the flight loop must do:
wait, ask the autopilot to take off, send a setpoint towards the start pose, or start the landing logic. The flight
loop (:class:`companion.app.flight.FlightApp`) does the sending and recording and reports back whether the autopilot
accepted the takeoff. Times are the vehicle's clock.

Three starts, by configuration:

- **SITL and test benches** (``start.arm_and_takeoff``): ask for takeoff, again every ``TAKEOFF_RETRY_S`` while the
  autopilot refuses (pre-arm checks not passed yet); climb to within 0.5 m of ``takeoff_altitude_m``; fly to the start
  pose when one is configured; start.
- **The field** (no ``arm_and_takeoff``): wait, as long as the pilot flies, until the vehicle is armed, in the air and
  in one of ``start.handover_modes``; then the same as above from the climb on (nothing to climb). A vehicle on the
  ground is never started.
- **A dry run** (nothing is ever sent): it may be started on the bench. It waits, as long as the pilot flies and
  with no failsafe, until the vehicle is armed, in the air and sees the head plane (the pipeline could read a frame
  from this pose); then it starts deciding. Each change of what it waits for is reported once (``waiting_for``).

The whole start must be done within ``START_TIMEOUT_S`` of vehicle time from the first tick (in the field, from the
pilot's handover).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from companion.app.mission import StartConfig
from companion.guidance.vehicle_state import VehicleState
from companion.vehicle.link import FlightMode, VehicleStatus

TAKEOFF_RETRY_S = 1.0  # vehicle time between takeoff requests while the autopilot refuses
START_TIMEOUT_S = 120.0  # vehicle time from the first tick (or the handover) to the start of the search
START_TOLERANCE_M = 1.0  # horizontal distance to the start pose at which the search begins
CLIMB_TOLERANCE_M = 0.5  # the climb is done this close below the takeoff altitude


class StartStage(str, enum.Enum):
    """Where the start is."""

    WAITING = "waiting"
    """For the autopilot to accept arming and takeoff (SITL), or for the pilot's handover (the field)."""
    CLIMBING = "climbing"
    """Taking off to the start altitude."""
    TRANSIT = "transit"
    """Flying to the start pose (``start.start_north_m``, ``start_east_m``)."""
    STARTED = "started"
    """The landing logic runs."""


class StartAction(str, enum.Enum):
    """What the flight loop does at this tick."""

    WAIT = "wait"
    """Nothing to send."""
    TAKE_OFF = "take_off"
    """Ask the autopilot to arm and take off to ``altitude_m``; report the answer (:meth:`StartSequence.took_off`)."""
    TRANSIT = "transit"
    """Send a setpoint towards the start pose (``north_m``, ``east_m``, ``altitude_m``, ``yaw_deg``)."""
    START = "start"
    """Start the landing logic at this tick."""
    TIMED_OUT = "timed_out"
    """The start took longer than ``START_TIMEOUT_S``: the flight fails (``reason``)."""


@dataclass(frozen=True)
class StartStep:
    """One tick's answer of :meth:`StartSequence.step`.

    ``north_m``, ``east_m`` (NED, metres) and ``yaw_deg`` are set for ``TRANSIT``; ``altitude_m`` (above home) for
    ``TAKE_OFF`` and ``TRANSIT``. ``handed_over`` is the pilot's mode when the handover happened at this tick (record
    it before acting); ``waiting_for_modes`` is set once, at the first tick spent waiting for the pilot.
    """

    action: StartAction
    north_m: float = math.nan
    east_m: float = math.nan
    altitude_m: float = math.nan
    yaw_deg: float = math.nan
    handed_over: FlightMode | None = None
    waiting_for_modes: str | None = None
    waiting_for: str | None = None
    """A dry run: what it now waits for, set at the first tick of each new wait."""
    reason: str = ""


class StartSequence:
    """The start's state machine (see the module docstring).

    Parameters
    ----------
    start : StartConfig
        Takeoff, handover modes and the start pose.
    dry_run : bool
        Nothing is sent in a dry run, so it starts at once.
    """

    def __init__(self, start: StartConfig, dry_run: bool) -> None:
        self.config = start
        self.dry_run = dry_run
        self.takes_off = start.arm_and_takeoff and not dry_run
        self.stage = StartStage.WAITING
        self._first_tick_t_s: float | None = None
        self._last_takeoff_try_t_s = -math.inf
        self._transit_yaw_deg: float | None = None
        self._waiting_logged = False
        self._waiting_for: str | None = None  # a dry run: what it waits for now (air, view)

    @property
    def started(self) -> bool:
        """The landing logic runs."""
        return self.stage is StartStage.STARTED

    def took_off(self) -> None:
        """The autopilot accepted the takeoff asked for by the last ``TAKE_OFF`` step: the climb begins. (A refusal
        needs no report: the next request goes out ``TAKEOFF_RETRY_S`` after the last.)"""
        self.stage = StartStage.CLIMBING

    def step(self, state: VehicleState, status: VehicleStatus, head_plane_visible: bool = True) -> StartStep:
        """What to do at vehicle time ``state.t_s``, with the autopilot reporting ``status`` (``head_plane_visible``:
        the pipeline could read a frame taken from the vehicle's pose now; a dry run waits for it)."""
        start = self.config
        if self.dry_run and self.stage is StartStage.WAITING:
            if not (status.armed and status.in_air):
                wait, waiting_for = "air", "the vehicle armed and in the air"
            elif not head_plane_visible:
                wait, waiting_for = "view", f"the head plane in view (in the air at {state.altitude_m:.1f} m)"
            else:
                self.stage = StartStage.STARTED
                return StartStep(StartAction.START)
            new_wait, self._waiting_for = wait != self._waiting_for, wait  # each new wait said once
            return StartStep(StartAction.WAIT, waiting_for=waiting_for if new_wait else None)
        if self._first_tick_t_s is None:
            self._first_tick_t_s = state.t_s
        if state.t_s - self._first_tick_t_s > START_TIMEOUT_S:
            reason = f"not ready to search {START_TIMEOUT_S:g} s after the start ({self.stage.value})"
            return StartStep(StartAction.TIMED_OUT, reason=reason)
        handed_over: FlightMode | None = None
        if not self.takes_off and not self.dry_run and self.stage is StartStage.WAITING:
            # The field: no timeout while the pilot flies; the clock starts at the handover.
            self._first_tick_t_s = state.t_s
            if not (status.armed and status.in_air and status.mode in start.handover_modes):
                if self._waiting_logged:
                    return StartStep(StartAction.WAIT)
                self._waiting_logged = True
                modes = ", ".join(m.value for m in start.handover_modes)
                return StartStep(StartAction.WAIT, waiting_for_modes=modes)
            handed_over = status.mode
            self.stage = StartStage.CLIMBING  # past the wait; nothing to climb
        if self.takes_off and self.stage is StartStage.WAITING:
            if state.t_s - self._last_takeoff_try_t_s < TAKEOFF_RETRY_S:
                return StartStep(StartAction.WAIT)
            self._last_takeoff_try_t_s = state.t_s
            return StartStep(StartAction.TAKE_OFF, altitude_m=start.takeoff_altitude_m)
        if self.takes_off and state.altitude_m < start.takeoff_altitude_m - CLIMB_TOLERANCE_M:
            return StartStep(StartAction.WAIT)
        if start.start_north_m is not None and start.start_east_m is not None and not self.dry_run:
            self.stage = StartStage.TRANSIT
            n, e = start.start_north_m, start.start_east_m
            if math.hypot(state.north_m - n, state.east_m - e) > START_TOLERANCE_M:
                if self._transit_yaw_deg is None:
                    self._transit_yaw_deg = state.yaw_deg  # held: see LandingGuidance.safe_setpoint
                return StartStep(
                    StartAction.TRANSIT,
                    north_m=n,
                    east_m=e,
                    altitude_m=start.takeoff_altitude_m,
                    yaw_deg=self._transit_yaw_deg,
                    handed_over=handed_over,
                )
        self.stage = StartStage.STARTED
        return StartStep(StartAction.START, handed_over=handed_over)
