"""The flight loop of ``slz fly``: frames and telemetry in, decisions out, everything recorded.

Two drivers, one logic. Each camera frame goes through :meth:`FlightApp.on_frame` (pose pairing at its capture time,
the pipeline in a one-thread executor so the event loop never blocks, then the state machine); each *tick* goes
through :meth:`FlightApp.on_tick` (the start sequence, pilot takeover, touchdown, perception silence). Times are the
vehicle's clock throughout.

- **Free running** (a real vehicle, or a SITL outside lockstep): frames are handled as they arrive; ticks come from
  a 10 Hz wall-clock timer, which also watches the link (no telemetry for ``link_lost_after_s``: stop commanding,
  let the autopilot's own failsafe act).
- **Lockstep** (``simulator.lockstep_url``, the bundled SITL stepping with us): the simulator stops at every tick
  with the tick's frame and pose already sent; the app handles the frame, then the tick, then acknowledges, naming
  the setpoint the simulator must have received first. The same seed gives the same flight at any speed.

Tasks are created together, kept, and cancelled together when one ends or fails (structured concurrency that also
runs on Python 3.10). The start (takeoff or the pilot's handover, climb, transit) is decided by
:class:`~companion.app.start_sequence.StartSequence`, which does no I/O; this module sends what it asks for. A
**stall watchdog** (:class:`~companion.app.stall_watchdog.StallWatchdog`) stops offboard from outside the event loop
when the loop stops beating for ``decision_watchdog_s``, since MAVSDK keeps re-sending the last setpoint on its own
thread. In lockstep it is off: simulated time waits for the loop, so a stall cannot move the vehicle, and a wall-clock
watchdog would make the flight depend on the machine's load.

In a dry run the same perception and decisions run and are recorded, but nothing is sent: no arming, no mode
change, no setpoint. Every decision is recorded with what produced it (``source``) and its inputs, so ``slz replay``
can re-run a flight from its log.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import functools
import logging
import math
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

from companion.app.drivers import FreeRunningDriver, LockstepDriver
from companion.app.flight_log import RecordKind
from companion.app.ground_report import GroundReport
from companion.app.mission import MissionConfig, OperatingMode, with_fence_ne_m
from companion.app.recorder import FlightRecorder
from companion.app.stall_watchdog import StallWatchdog
from companion.app.start_sequence import StartAction, StartSequence, StartStage, StartStep
from companion.app.supervision import COMPANION_MODES, Supervision
from companion.camera.frames import CameraError, Frame, FrameSource
from companion.geometry import GeometryError, Pose, polygon_centroid_ne_m
from companion.guidance.footprint import nearest_occupied_m
from companion.guidance.geofence import Geofence, latlon_to_ne_m
from companion.guidance.landing import CommandKind, Decision, LandingGuidance, LandingPhase
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent
from companion.perception.errors import PerceptionError
from companion.perception.pipeline import FrameResult, SlzPipeline
from companion.perception.zones import ZoneFinder
from companion.vehicle.link import FlightMode, VehicleError, VehicleLink
from companion.vehicle.lockstep import LockstepClient
from companion.vehicle.sim_control import SetpointNedYaw

logger = logging.getLogger(__name__)

TERMINAL = frozenset({LandingPhase.DONE, LandingPhase.YIELDED, LandingPhase.FAILSAFE})
# Phases in which no decision reads a frame: the flight is over, or the landing is the autopilot's (the guidance
# ignores frames in LAND, which leads only to DONE or YIELDED). A simulator in lockstep is not asked to draw them.
FRAMES_UNREAD = TERMINAL | {LandingPhase.LAND}
CLOCK_RESOLUTION_S = 1e-3  # MAVLink time_boot_ms
CANCEL_GRACE_S = 5.0  # wall time for the flight's tasks to stop once cancelled
STOP_UNHEARD_S = 3.0  # wall time a stop waits for a tick to send the last resort in; then it ends without one
POSE_RECORD_PERIOD_S = 1.0  # vehicle time between two `pose` records: the flight's path in the log


@dataclass
class FlightOutcome:
    """How a flight ended."""

    phase: str = LandingPhase.IDLE.value
    reason: str = ""
    touchdown_ne_m: tuple[float, float] | None = None
    touchdown_t_s: float | None = None
    ticks: int = 0
    lockstep: bool = False
    frames_processed: int = 0
    frames_before_start: int = 0
    frames_dropped_old: int = 0
    frames_dropped_no_pose: int = 0
    frames_missing: int = 0
    frames_failed: int = 0
    takeoff_refusals: int = 0
    commands_sent: int = 0
    camera_lost: bool = False
    camera_fault: str | None = None
    """Why the camera stopped (a :class:`~companion.camera.frames.CameraFault` value), when it did."""
    link_lost: bool = False
    failsafes: list[str] = field(default_factory=list)
    wall_s: float = 0.0
    cpu_s: float = 0.0
    """Process CPU time (all threads) over the flight: ``cpu_s / wall_s`` is the companion's CPU share."""


def yaw_deg_of(pose: Pose) -> float:
    """Heading of the body x axis in the world NED frame, degrees."""
    R = pose.T_world_body
    return math.degrees(math.atan2(R[1, 0], R[0, 0]))


def state_of(t_s: float, pose: Pose) -> VehicleState:
    """The landing logic's view of a pose at vehicle time ``t_s``."""
    n, e, d = (float(v) for v in pose.position_ned_m)
    return VehicleState(t_s, n, e, d, yaw_deg_of(pose))


class FlightApp:
    """One flight (see the module docstring).

    Parameters
    ----------
    config : MissionConfig
        The validated mission.
    link : VehicleLink
        Connected by :meth:`run`.
    source : FrameSource
        Camera frames with vehicle-clock capture times.
    pipeline : SlzPipeline
        Perception.
    recorder : FlightRecorder
        Where every record goes.
    lockstep : LockstepClient or None
        The simulator's lockstep channel; when it agrees to step, the flight is driven by its ticks.
    wall_limit_s : float or None
        Wall seconds from now after which the mission gives up (``slz fly --timeout``; None: no limit). It never ends
        a flight by itself: a vehicle the companion flies then gets ``guidance.last_resort`` (hold or return) and the
        run stays until the vehicle is on the ground or the pilot has it; a run that commands nothing ends.
    wall_clock : callable
        Monotonic wall seconds, for that limit alone (every decision runs on the vehicle's clock).
    """

    def __init__(
        self,
        config: MissionConfig,
        link: VehicleLink,
        source: FrameSource,
        pipeline: SlzPipeline,
        recorder: FlightRecorder,
        lockstep: LockstepClient | None = None,
        wall_limit_s: float | None = None,
        wall_clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config = config
        self.link = link
        self.source = source
        self.pipeline = pipeline
        self.recorder = recorder
        self.lockstep = lockstep
        self.dry_run = config.mode is OperatingMode.DRY_RUN
        self.report = GroundReport(link, self.dry_run)
        self.guidance = self._new_guidance()
        # The search area's centre for the blind random baseline (the paper's ROI): the geofence's centroid.
        self._area_centre_ne_m = polygon_centroid_ne_m(config.geofence.polygon_ne_m)
        self.outcome = FlightOutcome()
        self._executor = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="perception")
        self._offboard = False
        self._commanding = not self.dry_run
        self.watchdog = StallWatchdog(
            config.vehicle.decision_watchdog_s, lambda: self._offboard and self._commanding, self._stalled
        )
        self._send_lock = asyncio.Lock()  # one command at a time (see _send)
        self.done = asyncio.Event()
        self.start_sequence = StartSequence(config.start, self.dry_run)
        self._last_frame_t_s = -math.inf  # capture time of the newest processed frame (vehicle clock)
        self.tick_setpoint: SetpointNedYaw | None = None  # sent during this lockstep tick
        self.supervision = Supervision(config.supervision.stay_after_failsafe, wall_limit_s, wall_clock)
        self._target_id: int | None = None  # the last decision's target (console and log report switches)
        self._pose_recorded_s = -math.inf  # vehicle time of the last `pose` record

    def _new_guidance(self) -> LandingGuidance:
        zones = self.config.perception.zones
        return LandingGuidance(
            self.config.guidance,
            Geofence(self.config.geofence),
            zones.min_radius_m,
            zones.min_radius_m,
            self.pipeline.policy,
        )

    # -- vehicle state ------------------------------------------------------------------------------------------
    def vehicle_state(self) -> VehicleState | None:
        """The vehicle at its newest stamped pose."""
        t = self.link.poses.latest_t_s
        pose = self.link.poses.pose_at(t) if t is not None else None
        return None if t is None or pose is None else state_of(t, pose)

    # -- applying decisions --------------------------------------------------------------------------------------
    async def apply(
        self,
        decision: Decision,
        source: str,
        state: VehicleState | None,
        observed: dict[str, Any] | None = None,
        **inputs: Any,
    ) -> None:
        """Record a decision (with what produced it, from which inputs, and what the map showed around its target:
        ``observed``) and, when flying, send it."""
        previous = self.outcome.phase
        self.outcome.phase = decision.phase.value
        self.outcome.reason = decision.reason
        extra = {} if observed is None else {"observed": observed}
        self.recorder.write(
            RecordKind.DECISION, decision.t_s, decision=decision, source=source, state=state, inputs=inputs, **extra
        )
        prefix = "[dry run] " if self.dry_run else ""
        if decision.phase.value != previous:
            self.recorder.write(
                RecordKind.PHASE, decision.t_s, phase=decision.phase, previous=previous, reason=decision.reason
            )
            logger.info("%sphase %s -> %s: %s", prefix, previous, decision.phase.value, decision.reason)
            await self.report.phase(decision.phase, decision.reason)
        target_id = None if decision.target is None else decision.target.track_id
        if decision.target is not None and target_id != self._target_id:  # a switch (slz report lists them too)
            t = decision.target
            logger.info(
                "%starget: zone %s at north %.1f m, east %.1f m, r = %.2f m (was %s): %s",
                prefix,
                target_id,
                t.north_m,
                t.east_m,
                t.radius_m,
                "none" if self._target_id is None else f"zone {self._target_id}",
                decision.reason,
            )
        if decision.target is not None:
            self._target_id = target_id
        if decision.phase is LandingPhase.FAILSAFE:
            self.outcome.failsafes.append(decision.reason)
            self.recorder.write(RecordKind.FAILSAFE, decision.t_s, reason=decision.reason, action=decision.kind)
            logger.warning("%sfailsafe: %s (%s)", prefix, decision.reason, decision.kind.value)
        sent = False
        try:
            sent = await self._send(decision)
        finally:
            if decision.phase in TERMINAL and not self.dry_run:  # a dry run decides again while the pilot flies
                if self.supervision.stays_after(decision, sent):
                    self._watch(decision)  # the vehicle is the autopilot's now: watch it until it is safe
                else:
                    self.done.set()  # after its command went out: ending cancels the tasks

    def _watch(self, decision: Decision) -> None:
        """Stay after a failsafe command: until the vehicle is on the ground or the pilot has it (see on_tick)."""
        self.supervision.watch(decision.kind)
        reason = f"{decision.reason}: watching until the vehicle is on the ground or the pilot has it"
        self.recorder.write(RecordKind.SUPERVISION, decision.t_s, event="watching", reason=reason)
        logger.warning("%s", reason)

    async def _send(self, decision: Decision) -> bool:
        """Send one decision's command; whether it went out. One at a time: the frame and tick loops both decide,
        and a second command must not start OFFBOARD again while the first waits for the autopilot to report it (the
        pilot may have taken over in between: this flight never takes control back)."""
        async with self._send_lock:
            if not self._commanding or decision.kind is CommandKind.NONE:
                return False
            mode = self.link.status.mode
            if self._offboard and mode not in COMPANION_MODES:
                return False  # the pilot's mode since the last tick: nothing more goes out (no setpoint, no land, no
                # hold or return either: that would take the vehicle back), and the next tick yields
            await self._send_one(decision)
            return True

    async def _send_one(self, decision: Decision) -> None:
        try:
            if decision.kind is CommandKind.SETPOINT:
                sp = decision.setpoint
                assert sp is not None
                if not self._offboard:
                    status = self.link.status
                    entries = status.offboard_entries
                    await self.link.start_offboard(sp)
                    # Takeover detection starts only once the autopilot reports OFFBOARD (telemetry lags the ack).
                    # An entry reported since the request confirms it too, though the pilot may have switched away
                    # already: then the next tick sees the pilot's mode and yields.
                    await self.link.wait_for(
                        lambda: status.mode is FlightMode.OFFBOARD or status.offboard_entries > entries,
                        time.monotonic() + 3.0,
                        "OFFBOARD",
                    )
                    self._offboard = True
                else:
                    await self.link.set_setpoint(sp)
                self.tick_setpoint = SetpointNedYaw(sp.north_m, sp.east_m, sp.down_m, math.radians(sp.yaw_deg))
            elif decision.kind is CommandKind.LAND:
                await self.link.land()
            elif decision.kind is CommandKind.HOLD:
                await self.link.hold()
            elif decision.kind is CommandKind.RETURN:
                await self.link.return_to_launch()
        except VehicleError as exc:
            self.recorder.write(RecordKind.ERROR, decision.t_s, where="command", error=str(exc))
            raise
        self.outcome.commands_sent += 1
        self.recorder.write(RecordKind.COMMAND, decision.t_s, command=decision.kind, setpoint=decision.setpoint)
        if decision.kind is not CommandKind.SETPOINT:
            self._offboard = False  # the autopilot's own mode now

    # -- one frame -------------------------------------------------------------------------------------------------
    async def on_frame(self, frame: Frame) -> None:
        """Pair the frame with its pose, run the pipeline and let the landing logic decide."""
        if not self.start_sequence.started:
            self.outcome.frames_before_start += 1
            return
        if self.guidance.phase in TERMINAL:
            return
        paired = await self._pose_for(frame)
        if paired is None:
            return
        t_pose_s, pose = paired
        loop = asyncio.get_running_loop()
        try:
            result: FrameResult = await loop.run_in_executor(
                self._executor,
                self.pipeline.process,
                frame.image_bgr,
                pose,
                frame.t_capture_s,
                self._area_centre_ne_m,
            )
        except (PerceptionError, GeometryError) as exc:  # one bad frame or pose; a lasting failure: silence failsafe
            self.outcome.frames_failed += 1
            self.recorder.write(RecordKind.FRAME_ERROR, frame.t_capture_s, seq=frame.seq, error=str(exc))
            return
        self._last_frame_t_s = max(self._last_frame_t_s, t_pose_s)
        self.outcome.frames_processed += 1
        self.recorder.frame(frame.seq, frame.t_capture_s, frame.image_bgr)
        self.recorder.write(
            RecordKind.FRAME_RESULT,
            frame.t_capture_s,
            seq=frame.seq,
            T_world_body=pose.T_world_body,
            tracks=result.tracks,
            target=result.target,
            timings_ms=result.timings_ms,
        )
        state = self.vehicle_state()
        if state is None:
            return
        if state.t_s - t_pose_s > self.config.camera.max_frame_age_s:  # fell behind: decide on fresh frames only
            self.outcome.frames_dropped_old += 1
            return
        decision = self.guidance.on_frame(result, state)
        observed = None
        trusted = state.altitude_m >= self.config.guidance.perception_min_altitude_m  # maps that decide
        if decision.target is not None and decision.phase in (LandingPhase.DESCENT, LandingPhase.LAND) and trusted:
            # What the map showed around the landing point: the landing report's "nearest person seen".
            nearest = nearest_occupied_m(result.head_plane, decision.target.north_m, decision.target.east_m)
            observed = {"nearest_occupied_m": None if nearest is None else round(nearest, 3)}
        await self.apply(decision, "frame", state, observed, seq=frame.seq)
        await self.report.decision_values(result.t_s, len(result.tracks), decision.target, state)
        if self._commanding and decision.kind is not CommandKind.NONE and math.isfinite(frame.arrival_wall_s):
            latency_ms = 1000.0 * (time.monotonic() - frame.arrival_wall_s)
            self.recorder.write(RecordKind.LATENCY, frame.t_capture_s, seq=frame.seq, frame_to_command_ms=latency_ms)

    def pose_reaches(self, t_s: float) -> bool:
        """The pose buffer holds a pose stamped at ``t_s`` or later (to the vehicle clock's resolution)."""
        latest = self.link.poses.latest_t_s
        return latest is not None and latest >= t_s - CLOCK_RESOLUTION_S

    async def _pose_for(self, frame: Frame) -> tuple[float, Pose] | None:
        """The pose at the frame's capture time (waiting briefly for telemetry to catch up) and the vehicle time it
        is stamped with; None drops the frame (counted)."""
        max_age = self.config.camera.max_frame_age_s
        t_s = frame.t_capture_s
        try:
            await self.link.wait_for(
                functools.partial(self.pose_reaches, t_s),
                time.monotonic() + max_age,
                "telemetry at the frame's capture time",
            )
        except VehicleError:
            self.outcome.frames_dropped_no_pose += 1
            return None
        latest = self.link.poses.latest_t_s
        assert latest is not None
        if latest - t_s > max_age:
            self.outcome.frames_dropped_old += 1
            return None
        t_s = min(t_s, latest)  # within the vehicle clock's resolution of the newest sample
        pose = self.link.poses.pose_at(t_s)
        if pose is None:
            self.outcome.frames_dropped_no_pose += 1
            return None
        return t_s, pose

    # -- one tick ----------------------------------------------------------------------------------------------------
    async def on_tick(self, state: VehicleState) -> None:
        """The start sequence, then pilot takeover, touchdown and perception silence, at vehicle time ``state.t_s``."""
        self.outcome.ticks += 1
        status = self.link.status
        self.supervision.saw(status)
        if state.t_s - self._pose_recorded_s >= POSE_RECORD_PERIOD_S:
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
        if self.supervision.watching is not None:
            self._watch_tick(state)
            return
        if self.dry_run and self._flight_over(state):
            return
        if self.guidance.phase in TERMINAL:
            if self.dry_run:  # the pilot still flies: decide again once the start's conditions hold again
                self._rearm(state)
            else:
                self.done.set()
            return
        if self._offboard and status.mode not in COMPANION_MODES and not self.dry_run:
            self._offboard = False
            self._commanding = False  # never take control back in this flight
            mode = status.mode.value
            await self.apply(self.guidance.pilot_took_over(state.t_s, mode), "takeover", state, mode=mode)
            return
        if self.supervision.stop_requested is not None:  # after the pilot's word too
            await self._stop(state)
            return
        limit = self.supervision.wall_limit_reached()  # after the pilot's word too
        if limit is not None:
            await self._wall_limit(state, limit)
            return
        if not self.start_sequence.started:
            visible = self.head_plane_visible(state) if self.dry_run else True
            await self._start_step(state, self.start_sequence.step(state, status, visible))
            return
        if self.guidance.phase is LandingPhase.LAND and not status.in_air:
            self.outcome.touchdown_ne_m = (state.north_m, state.east_m)
            self.outcome.touchdown_t_s = state.t_s
            await self.apply(self.guidance.landed(state.t_s), "landed", state)
            return
        used_up = self.guidance.time_used_up(state)
        if used_up is not None:
            await self.apply(used_up, "time", state)
            return
        silent_s = state.t_s - self._last_frame_t_s
        decision = self.guidance.perception_silent(state, silent_s)
        if decision is not None:
            await self.apply(decision, "silence", state, silent_s=silent_s)

    def _watch_tick(self, state: VehicleState) -> None:
        """After a failsafe command: end once the vehicle is on the ground, or the pilot has switched it to a mode
        other than the one the failsafe asked for (OFFBOARD still reported is telemetry lagging the command)."""
        end = self.supervision.watch_ends(self.link.status)
        if end is None:
            return
        reason = end.reason
        if end.event == "on_ground":
            self.outcome.touchdown_ne_m = (state.north_m, state.east_m)
            self.outcome.touchdown_t_s = state.t_s
            reason = f"{reason} at north {state.north_m:.1f} m, east {state.east_m:.1f} m"
        self.outcome.reason = f"{self.outcome.reason}; {reason}"
        self.recorder.write(RecordKind.SUPERVISION, state.t_s, event=end.event, reason=reason)
        logger.warning("after the failsafe: %s", reason)
        self.done.set()

    def _flight_over(self, state: VehicleState) -> bool:
        """A dry run ends once the vehicle, having flown, is on the ground and disarmed (the whole flight logged)."""
        if not self.supervision.flight_over(self.link.status):
            return False
        reason = "the flight is over: on the ground and disarmed"
        self.outcome.reason = reason if self.guidance.phase is LandingPhase.IDLE else f"{self.outcome.reason}; {reason}"
        self.recorder.write(RecordKind.SUPERVISION, state.t_s, event="on_ground", reason=reason)
        logger.info("[dry run] %s", reason)
        self.done.set()
        return True

    def _rearm(self, state: VehicleState) -> None:
        """A dry run whose decisions ended (a failsafe, a landing) while the pilot flies on: a fresh state machine,
        started again once the vehicle is in the air and sees the head plane."""
        logger.info("[dry run] decisions ended in %s; deciding again once the start holds again", self.outcome.phase)
        self.recorder.write(RecordKind.WAITING, state.t_s, waiting_for="a new start (the last decisions ended)")
        self.guidance = self._new_guidance()
        self.start_sequence = StartSequence(self.config.start, self.dry_run)
        self._target_id = None

    async def _wall_limit(self, state: VehicleState, limit: str) -> None:
        """The wall limit of ``slz fly --timeout`` (``limit``, in words): the vehicle the companion flies gets the last
        resort (hold or return) and the run stays until it is safe; a run that commands nothing (a dry run, a wait
        for the pilot's handover) just ends."""
        if self._flying_it():
            await self.apply(self.guidance.give_up(state, limit), "limit", state, reason=limit)
            return
        self.outcome.reason = f"{limit}: nothing commanded, the run ends"
        self.recorder.write(RecordKind.SUPERVISION, state.t_s, event="wall_limit", reason=self.outcome.reason)
        logger.warning("%s", self.outcome.reason)
        self.done.set()

    def request_stop(self, why: str) -> None:
        """Ask the program to stop (``slz fly`` on SIGINT or SIGTERM: the service stopped, Ctrl-C): at the next tick
        a vehicle it flies gets ``guidance.last_resort`` before it ends, instead of an offboard-loss failsafe later.
        Asked twice, it ends at once."""
        if not self.supervision.ask_stop(why):
            logger.error("%s again: ending now", why)
            self.done.set()
            return
        logger.warning("%s: the vehicle gets the last resort, then the program ends", why)
        # No tick may come again (a SITL stopped with us, a link gone): the stop must not wait on one.
        asyncio.get_running_loop().call_later(STOP_UNHEARD_S, self._stop_unheard, why)

    def _stop_unheard(self, why: str) -> None:
        """``STOP_UNHEARD_S`` after a stop: if no tick has taken it yet, end without sending the last resort."""
        if self.done.is_set() or self.supervision.stop_unheard() is None:
            return
        self.outcome.reason = f"{why}: no vehicle tick within {STOP_UNHEARD_S:g} s, ending without the last resort"
        self.recorder.write(RecordKind.SUPERVISION, None, event="stopped", reason=self.outcome.reason)
        logger.error("%s", self.outcome.reason)
        self.done.set()

    async def _stop(self, state: VehicleState) -> None:
        """A stop asked of the program: the last resort for a vehicle it flies, then the end (no watch: a stopping
        service cannot stay); a run that commands nothing just ends."""
        last_resort = self._flying_it() and self.guidance.phase not in TERMINAL
        why = self.supervision.take_stop(last_resort)
        reason = f"{why}: stopping"
        if last_resort:
            await self.apply(self.guidance.give_up(state, reason), "stop", state, reason=reason)
            return
        self.outcome.reason = f"{reason}, nothing commanded"
        self.recorder.write(RecordKind.SUPERVISION, state.t_s, event="stopped", reason=self.outcome.reason)
        self.done.set()

    def _flying_it(self) -> bool:
        """The companion commands the vehicle: it took off with it, or sends it setpoints in OFFBOARD."""
        if not self._commanding:
            return False
        took_off = self.start_sequence.takes_off and self.start_sequence.stage is not StartStage.WAITING
        return self._offboard or took_off

    async def _localize_fence(self, polygon_latlon_deg: list[tuple[float, float]]) -> None:
        """A fence given in latitude and longitude: projected into local NED from the autopilot's EKF origin, as PX4
        does, then every cross-check of the config again (ConfigError before anything is commanded)."""
        lat0, lon0 = await self.link.global_origin(self.config.vehicle.connect_timeout_s)
        polygon_ne_m = [latlon_to_ne_m(lat, lon, lat0, lon0) for lat, lon in polygon_latlon_deg]
        self.config = with_fence_ne_m(self.config, polygon_ne_m)
        self.recorder.write(RecordKind.FENCE, None, polygon_ne_m=polygon_ne_m, origin_lat_deg=lat0, origin_lon_deg=lon0)
        logger.info(
            "geofence: %d vertices projected from latitude and longitude around the EKF origin (%.7f, %.7f)",
            len(polygon_ne_m),
            lat0,
            lon0,
        )
        self.guidance = self._new_guidance()
        self._area_centre_ne_m = polygon_centroid_ne_m(polygon_ne_m)
        self.pipeline.zone_finder = ZoneFinder(self.config.perception.zones, polygon_ne_m)

    def head_plane_visible(self, state: VehicleState) -> bool:
        """The pipeline could read a frame taken from the vehicle's pose at ``state.t_s``."""
        pose = self.link.poses.pose_at(state.t_s)
        if pose is None:
            return False
        try:
            self.pipeline.projector.finest_gsd_m_per_px(pose)
        except (PerceptionError, GeometryError):
            return False
        return True

    async def _start_step(self, state: VehicleState, step: StartStep) -> None:
        """Do what the start sequence asks at this tick: record, take off, send a transit setpoint, or start."""
        if step.action is StartAction.TIMED_OUT:
            raise VehicleError(self.link.name, step.reason)
        if step.waiting_for is not None:
            logger.info("[dry run] waiting for %s", step.waiting_for)
            self.recorder.write(RecordKind.WAITING, state.t_s, waiting_for=step.waiting_for)
        if step.waiting_for_modes is not None:
            logger.info("waiting for the pilot's handover: armed, in the air and in %s", step.waiting_for_modes)
            self.recorder.write(RecordKind.WAITING_FOR_HANDOVER, state.t_s, modes=step.waiting_for_modes)
        if step.handed_over is not None:
            mode = step.handed_over.value
            self.recorder.write(RecordKind.HANDOVER, state.t_s, mode=mode, altitude_m=state.altitude_m)
        if step.action is StartAction.TAKE_OFF:
            try:
                await self.link.take_off(step.altitude_m)
            except VehicleError as exc:  # pre-arm checks not passed yet: the sequence asks again later (vehicle time)
                self.outcome.takeoff_refusals += 1
                logger.info("takeoff not accepted yet: %s", exc)
                return
            self.start_sequence.took_off()
            self.recorder.write(RecordKind.TAKEOFF, state.t_s, altitude_m=step.altitude_m)
        elif step.action is StartAction.TRANSIT:
            # Fly to the start pose first (SITL campaigns): through the same safety filter as every setpoint.
            setpoint = self.guidance.safe_setpoint(state, step.north_m, step.east_m, step.altitude_m, step.yaw_deg)
            transit = Decision(
                state.t_s, LandingPhase.IDLE, CommandKind.SETPOINT, setpoint, None, "transit", DecisionEvent.TRANSIT
            )
            await self._send(transit)
        elif step.action is StartAction.START:
            self._last_frame_t_s = state.t_s  # perception silence counts from here
            await self.apply(self.guidance.start(state), "start", state)

    # -- what the drivers see (companion.app.drivers.FlightLoop) ----------------------------------------------------
    @property
    def link_lost_after_s(self) -> float:
        return self.config.vehicle.link_lost_after_s

    @property
    def camera_is_lost(self) -> bool:
        return self.outcome.camera_lost

    @property
    def wants_frames(self) -> bool:
        return self.start_sequence.started and self.guidance.phase not in FRAMES_UNREAD

    def frames(self) -> AsyncIterator[Frame]:
        return self.source.frames()

    def frame_missing(self) -> None:
        self.outcome.frames_missing += 1

    async def wait_for_pose(self, t_s: float, timeout_s: float) -> None:
        await self.link.wait_for(
            functools.partial(self.pose_reaches, t_s), time.monotonic() + timeout_s, "the tick's pose"
        )

    def telemetry_age_s(self) -> float | None:
        last_telemetry = self.link.status.last_telemetry_wall_s
        return None if last_telemetry is None else time.monotonic() - last_telemetry

    def take_tick_setpoint(self) -> SetpointNedYaw | None:
        setpoint, self.tick_setpoint = self.tick_setpoint, None
        return setpoint

    def camera_lost(self, exc: CameraError) -> None:
        self.outcome.camera_lost = True
        self.outcome.camera_fault = exc.fault.value
        logger.error("camera fault %s: %s (the perception-silence failsafe acts)", exc.fault.value, exc)
        t_s = self.link.poses.latest_t_s
        self.recorder.write(RecordKind.ERROR, t_s, where="camera", fault=exc.fault.value, error=str(exc))

    def link_lost(self, silent_s: float) -> None:
        self.outcome.link_lost = True
        self._commanding = False
        self._offboard = False
        state = self.vehicle_state()
        self.recorder.write(RecordKind.FAILSAFE, state.t_s if state else None, reason="link lost: stop commanding")
        logger.error("link lost: no telemetry for %.1f s; the autopilot's failsafe acts", silent_s)
        if self.lockstep is not None:
            self.lockstep.release()  # the simulator runs on without us, so its own failsafe can act
        self.done.set()

    def _stalled(self, stalled_s: float) -> None:
        """The stall watchdog's action, on its thread: stop offboard, and command nothing more in this flight."""
        logger.error("decision loop stalled for %.2f s: stopping offboard", stalled_s)
        self.link.stop_offboard_blocking()
        self._offboard = False
        self._commanding = False

    # -- the flight ------------------------------------------------------------------------------------------------
    async def run(self) -> FlightOutcome:
        """Connect, (take off,) land safely or end in a defined failsafe (and, with ``supervision``, stay until the
        vehicle is on the ground or the pilot has it)."""
        cfg = self.config
        wall0, cpu0 = time.monotonic(), time.process_time()
        self.recorder.write(RecordKind.START, None, mode=cfg.mode, vehicle=cfg.vehicle.url, camera=cfg.camera.url)
        await self.source.open()  # a missing camera fails the start, before the vehicle is touched
        await self.link.connect(cfg.vehicle.connect_timeout_s)
        if cfg.geofence.polygon_latlon_deg is not None:
            await self._localize_fence(cfg.geofence.polygon_latlon_deg)
        if self.lockstep is not None and not await self.lockstep.open(frames=self.wants_frames):
            self.lockstep = None
        self.outcome.lockstep = self.lockstep is not None
        self.recorder.write(RecordKind.CLOCK, None, lockstep=self.outcome.lockstep)
        if self.lockstep is None:
            self.watchdog.start()
        if self.lockstep is not None:
            drivers = [LockstepDriver(self, self.lockstep).run()]
        else:
            free = FreeRunningDriver(self)
            drivers = [free.frames(), free.ticks()]
        tasks: list[asyncio.Task[Any]] = [
            *(asyncio.create_task(driver) for driver in drivers),
            asyncio.create_task(self.watchdog.heartbeat(self.done), name="beat"),
            asyncio.create_task(self.done.wait(), name="done"),
        ]
        try:
            done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            for task in done:
                if not task.cancelled() and task.exception() is not None:
                    raise task.exception()  # type: ignore[misc]
        finally:
            # The flight is over for every loop. Each one also ends by itself on `done`, because on Python 3.10
            # and 3.11 `asyncio.wait_for` can lose a cancellation that arrives as its timeout fires (gh-86296, seen
            # here under load: a dry run went on deciding after its mission timeout). Then cancel, within a bound.
            self.done.set()
            for task in tasks:
                task.cancel()
            _, pending = await asyncio.wait(tasks, timeout=CANCEL_GRACE_S)
            for task in pending:
                logger.error("task %s did not stop within %g s of its cancellation", task.get_name(), CANCEL_GRACE_S)
            self.watchdog.stop()
            self._executor.shutdown(wait=True)
            if self.lockstep is not None:
                self.lockstep.release()
                self.lockstep.close()
            self.outcome.wall_s = time.monotonic() - wall0
            self.outcome.cpu_s = time.process_time() - cpu0
            self.recorder.write(RecordKind.END, None, outcome=self.outcome)
        return self.outcome
