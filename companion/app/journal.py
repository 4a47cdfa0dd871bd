"""What a flight writes about its decisions and its path: each decision with its source and inputs, each phase change,
each target switch and failsafe (in the flight log and on the console), and the vehicle's pose once a second."""

from __future__ import annotations

import logging
import math

from companion.app.start_sequence import StartStep
from companion.flightlog.flight_log import RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.guidance.landing import Decision, LandingPhase
from companion.guidance.stimulus import Stimulus, to_json
from companion.guidance.vehicle_state import VehicleState
from companion.json_value import JsonObject
from companion.vehicle.link import VehicleStatus

logger = logging.getLogger(__name__)

POSE_RECORD_PERIOD_S = 1.0  # vehicle time between two `pose` records: the flight's path in the log
PROGRESS_PERIOD_S = 5.0  # vehicle time between two progress lines on the console (and the journal)


class FlightJournal:
    """The flight's decisions and path, as records and log lines.

    Parameters
    ----------
    recorder : FlightRecorder
        Where the records go.
    dry_run : bool
        Log lines say so.
    """

    def __init__(self, recorder: FlightRecorder, dry_run: bool) -> None:
        self.recorder = recorder
        self.prefix = "[dry run] " if dry_run else ""
        self._target_id: int | None = None  # the last decision's target (console and log report switches)
        self._pose_recorded_s = -math.inf  # vehicle time of the last `pose` record
        self._progress_said_s = -math.inf  # vehicle time of the last progress line
        self._last_decision: Decision | None = None

    def reset(self) -> None:
        """A fresh state machine decides (a dry run started again): no target yet."""
        self._target_id = None

    def decision(
        self,
        decision: Decision,
        previous_phase: str,
        stimulus: Stimulus,
        observed: JsonObject | None,
    ) -> None:
        """Record a decision (with the stimulus it answered: its source, the vehicle state and its inputs; and what the
        map showed around its target: ``observed``), the phase change from ``previous_phase`` it makes, its target
        switch and its failsafe."""
        self._last_decision = decision
        extra = {} if observed is None else {"observed": observed}
        source, state = stimulus.source, stimulus.state
        self.recorder.write(
            RecordKind.DECISION,
            decision.t_s,
            decision=decision,
            source=source,
            state=state,
            stimulus=to_json(stimulus),
            **extra,
        )
        if decision.phase.value != previous_phase:
            self.recorder.write(
                RecordKind.PHASE, decision.t_s, phase=decision.phase, previous=previous_phase, reason=decision.reason
            )
            logger.info("%sphase %s -> %s: %s", self.prefix, previous_phase, decision.phase.value, decision.reason)
        target = decision.target
        if target is not None:
            if target.track_id != self._target_id:  # a switch (slz report lists them too)
                logger.info(
                    "%starget: zone %s at north %.1f m, east %.1f m, r = %.2f m (was %s): %s",
                    self.prefix,
                    target.track_id,
                    target.north_m,
                    target.east_m,
                    target.radius_m,
                    "none" if self._target_id is None else f"zone {self._target_id}",
                    decision.reason,
                )
            self._target_id = target.track_id
        if decision.phase is LandingPhase.FAILSAFE and decision.phase.value != previous_phase:  # entering it
            self.recorder.write(RecordKind.FAILSAFE, decision.t_s, reason=decision.reason, action=decision.kind)
            logger.warning("%sfailsafe: %s (%s)", self.prefix, decision.reason, decision.kind.value)

    def start_step(self, state: VehicleState, step: StartStep) -> None:
        """What the start sequence waits for, or the pilot's handover, at this tick."""
        if step.waiting_for is not None:
            logger.info("[dry run] waiting for %s", step.waiting_for)
            self.recorder.write(RecordKind.WAITING, state.t_s, waiting_for=step.waiting_for)
        if step.waiting_for_modes is not None:
            logger.info("waiting for the pilot's handover: armed, in the air and in %s", step.waiting_for_modes)
            self.recorder.write(RecordKind.WAITING_FOR_HANDOVER, state.t_s, modes=step.waiting_for_modes)
        if step.handed_over is not None:
            mode = step.handed_over.value
            self.recorder.write(RecordKind.HANDOVER, state.t_s, mode=mode, altitude_m=state.altitude_m)

    def progress(self, state: VehicleState, status: VehicleStatus, watching: bool = False) -> str | None:
        """A calm progress line (at most every ``PROGRESS_PERIOD_S`` of vehicle time) while flying or watching: the
        phase (or the watch), altitude, the vehicle's mode, the target and how far it is, and what the last decision
        said (a wait at the walker gate says how long). Logged (the console, the journal); returned for tests."""
        if state.t_s - self._progress_said_s < PROGRESS_PERIOD_S:
            return None
        self._progress_said_s = state.t_s
        last = self._last_decision
        parts = [
            "watching after the failsafe" if watching else (last.phase.value if last is not None else "starting"),
            f"altitude {state.altitude_m:.1f} m",
            f"mode {status.mode.value}",
        ]
        if status.in_air is False and watching:
            parts.append("on the ground")
        if last is not None and last.target is not None and not watching:
            away = math.hypot(last.target.north_m - state.north_m, last.target.east_m - state.east_m)
            parts.append(f"target zone {last.target.track_id} (r {last.target.radius_m:.1f} m, {away:.1f} m away)")
        if last is not None and not watching:
            parts.append(last.reason if len(last.reason) <= 80 else last.reason[:77] + "...")
        line = f"{self.prefix}t {state.t_s:.1f} s: " + ", ".join(parts)
        logger.info("%s", line)
        return line

    def camera_fault(self, t_s: float | None, fault: str, error: str) -> None:
        """The camera failed in flight (the perception-silence failsafe acts): logged and recorded."""
        logger.error("camera fault %s: %s (the perception-silence failsafe acts)", fault, error)
        self.recorder.write(RecordKind.ERROR, t_s, where="camera", fault=fault, error=error)

    def link_lost(self, t_s: float | None, silent_s: float, shared: str | None) -> None:
        """The vehicle's telemetry stopped for ``silent_s``: the companion stops commanding, the autopilot's failsafe
        acts (``shared``: a second program on the vehicle's port, when one was seen)."""
        why = "link lost: stop commanding" + ("" if shared is None else f" ({shared})")
        self.recorder.write(RecordKind.FAILSAFE, t_s, reason=why, action="autopilot")
        also = "" if shared is None else f"; {shared}"
        logger.error("link lost: no telemetry for %.1f s; the autopilot's failsafe acts%s", silent_s, also)

    def pose(self, state: VehicleState, status: VehicleStatus) -> None:
        """The vehicle's pose and status, at most once per ``POSE_RECORD_PERIOD_S`` of vehicle time."""
        if state.t_s - self._pose_recorded_s < POSE_RECORD_PERIOD_S:
            return
        self._pose_recorded_s = state.t_s
        self.recorder.write(
            RecordKind.POSE,
            state.t_s,
            north_m=state.north_m,
            east_m=state.east_m,
            down_m=state.down_m,
            yaw_deg=state.yaw_deg,
            mode=status.mode,
            armed=status.armed,
            in_air=status.in_air,
        )
