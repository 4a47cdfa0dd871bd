"""The flight loop of ``slz fly``: frames and telemetry in, decisions out, everything recorded.

Two drivers, one logic. Each camera frame goes through :meth:`FlightApp.on_frame` (pose pairing at its capture time,
the pipeline in a one-thread executor so the event loop never blocks: :class:`~companion.app.frame_intake.FrameIntake`;
then the state machine, whose commands :class:`~companion.app.commands.VehicleCommands` sends); each *tick* goes
through :meth:`FlightApp.on_tick` (the start sequence, pilot takeover, touchdown, perception silence). Times are the
vehicle's clock throughout.

- **Free running** (a real vehicle, or a SITL outside lockstep): frames are handled as they arrive; ticks come from
  a 10 Hz wall-clock timer, which also watches the link (no telemetry for ``link_lost_after_s``: stop commanding,
  let the autopilot's own failsafe act).
- **Lockstep** (``simulator.lockstep_url``, the bundled SITL stepping with us): the simulator stops at every tick
  with the tick's frame and pose already sent; the app handles the frame, then the tick, then acknowledges, naming
  the setpoint the simulator must have received first. The same seed gives the same flight at any speed.

Tasks are created together, kept, and cancelled together when one ends or fails (structured concurrency that also
runs on Python 3.10: :func:`~companion.app.task_group.run_until_first_ends`). The start (takeoff or the pilot's
handover, climb, transit) is decided by :class:`~companion.app.start_sequence.StartSequence`, which does no I/O;
this module sends what it asks for. A
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
import functools
import logging
import math
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

from companion.app.commands import VehicleCommands
from companion.app.drivers import FreeRunningDriver, LockstepDriver
from companion.app.fallback_sites import with_rally_sites
from companion.app.flight_log import RecordKind
from companion.app.frame_intake import FrameIntake
from companion.app.ground_report import GroundReport
from companion.app.journal import FlightJournal
from companion.app.mission import MissionConfig, OperatingMode, with_fence_ne_m
from companion.app.operator_desk import OperatorDesk
from companion.app.outcome import FlightOutcome
from companion.app.recorder import FlightRecorder
from companion.app.run_end import RunEnd
from companion.app.stall_watchdog import StallWatchdog
from companion.app.start_sequence import StartAction, StartSequence, StartStage, StartStep
from companion.app.supervision import Supervision
from companion.app.task_group import run_until_first_ends, unless_done
from companion.app.warning_device import WarningDevice
from companion.camera.frames import CameraError, Frame, FrameSource
from companion.camera.waiting import open_when_up
from companion.geometry import Pose, polygon_centroid_ne_m
from companion.guidance.energy import EnergyBudget
from companion.guidance.footprint import nearest_occupied_m
from companion.guidance.geofence import Geofence, latlon_to_ne_m
from companion.guidance.landing import CommandKind, Decision, LandingGuidance, LandingPhase
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent, DecisionSource
from companion.perception.pipeline import FrameResult, SlzPipeline
from companion.perception.selection import SelectionPolicy
from companion.perception.zones import ZoneFinder
from companion.vehicle.link import LinkResult, MissionStore, VehicleError, VehicleLink
from companion.vehicle.lockstep import LockstepClient
from companion.vehicle.sim_control import SetpointNedYaw

logger = logging.getLogger(__name__)

TERMINAL = frozenset({LandingPhase.DONE, LandingPhase.YIELDED, LandingPhase.FAILSAFE})
# Phases in which no decision reads a frame: the flight is over, or the landing is the autopilot's (the guidance
# ignores frames in LAND, which leads only to DONE or YIELDED). A simulator in lockstep is not asked to draw them.
FRAMES_UNREAD = TERMINAL | {LandingPhase.LAND}
CANCEL_GRACE_S = 5.0  # wall time for the flight's tasks to stop once cancelled


def yaw_deg_of(pose: Pose) -> float:
    """Heading of the body x axis in the world NED frame, degrees."""
    R = pose.T_world_body
    return math.degrees(math.atan2(R[1, 0], R[0, 0]))


def state_of(t_s: float, pose: Pose) -> VehicleState:
    """The landing logic's view of a pose at vehicle time ``t_s``."""
    n, e, d = (float(v) for v in pose.position_ned_m)
    return VehicleState(t_s, n, e, d, yaw_deg_of(pose))


async def fence_in_local_ned(config: MissionConfig, mission: MissionStore, recorder: FlightRecorder) -> MissionConfig:
    """The config with its fence in latitude and longitude projected into local NED from the autopilot's EKF origin,
    as PX4 does, then every cross-check of the config again (ConfigError before anything is commanded)."""
    assert config.geofence.polygon_latlon_deg is not None
    lat0, lon0 = await mission.global_origin(config.vehicle.connect_timeout_s)
    polygon_ne_m = [latlon_to_ne_m(lat, lon, lat0, lon0) for lat, lon in config.geofence.polygon_latlon_deg]
    recorder.write(RecordKind.FENCE, None, polygon_ne_m=polygon_ne_m, origin_lat_deg=lat0, origin_lon_deg=lon0)
    logger.info("geofence: %d vertices from latitude and longitude around the EKF origin", len(polygon_ne_m))
    return with_fence_ne_m(config, polygon_ne_m)


def observed_at_target(
    result: FrameResult, decision: Decision, state: VehicleState, min_altitude_m: float
) -> dict[str, Any] | None:
    """What a map that decides (taken at or above ``min_altitude_m``) showed around the landing point of a descent or a
    landing: the landing report's "nearest person seen" (m; None: nobody on the map). None for other decisions."""
    target = decision.target
    if (
        target is None
        or decision.phase not in (LandingPhase.DESCENT, LandingPhase.LAND)
        or state.altitude_m < min_altitude_m
    ):
        return None
    nearest = nearest_occupied_m(result.head_plane, target.north_m, target.east_m)
    return {"nearest_occupied_m": None if nearest is None else round(nearest, 3)}


def landing_guidance(config: MissionConfig, policy: SelectionPolicy) -> LandingGuidance:
    """The landing logic of a mission: its fence, its footprint (the zones' smallest radius) and selection policy."""
    zones = config.perception.zones
    fence = Geofence(config.geofence)
    return LandingGuidance(config.guidance, fence, zones.min_radius_m, zones.min_radius_m, policy)


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
        self.report = GroundReport(link.ground, self.dry_run)
        self.guidance = landing_guidance(self.config, self.pipeline.policy)
        # The search area's centre for the blind random baseline (the paper's ROI): the geofence's centroid.
        self._area_centre_ne_m = polygon_centroid_ne_m(config.geofence.polygon_ne_m)
        self.outcome = FlightOutcome()
        parts = link.telemetry, link.action, link.offboard
        self.commands = VehicleCommands(*parts, recorder, self.outcome, self.dry_run)
        self.journal = FlightJournal(recorder, self.dry_run)
        self.intake = FrameIntake(link.telemetry, pipeline, recorder, self.outcome, config.camera.max_frame_age_s)
        self.watchdog = StallWatchdog(
            config.vehicle.decision_watchdog_s, lambda: self.commands.flying_offboard, self.commands.stalled
        )
        self.done = asyncio.Event()
        self.start_sequence = StartSequence(config.start, self.dry_run)
        self._last_frame_t_s = -math.inf  # capture time of the newest processed frame (vehicle clock)
        self.supervision = Supervision(config.supervision.stay_after_failsafe, wall_limit_s, wall_clock)
        self.energy = EnergyBudget(config.guidance.energy) if config.guidance.energy.enabled else None
        self.ending = RunEnd(self.supervision, recorder, self.outcome, self.done)
        self.desk = OperatorDesk.from_config(config, recorder)
        self.warning = WarningDevice(config.guidance.warning, self.commands, recorder)

    def vehicle_state(self) -> VehicleState | None:
        """The vehicle at its newest stamped pose."""
        t = self.link.telemetry.poses.latest_t_s
        pose = self.link.telemetry.poses.pose_at(t) if t is not None else None
        return None if t is None or pose is None else state_of(t, pose)

    async def apply(
        self,
        decision: Decision,
        source: DecisionSource,
        state: VehicleState | None,
        observed: dict[str, Any] | None = None,
        **inputs: Any,
    ) -> None:
        """Record a decision (:meth:`FlightJournal.decision`), report its phase change to the ground station and,
        when flying, send it."""
        previous = self.outcome.phase
        self.outcome.phase = decision.phase.value
        self.outcome.reason = decision.reason
        self.journal.decision(decision, previous, source, state, observed, inputs)
        if decision.phase.value != previous or decision.event is DecisionEvent.FALLBACK_SITE:  # every site said
            await self.report.phase(decision.phase, decision.reason)
        if decision.phase is LandingPhase.FAILSAFE and decision.phase.value != previous:
            self.outcome.failsafes.append(decision.reason)
        sent = False
        try:
            sent = await self.commands.send(decision)
            await self.warning.follow(decision)
        finally:
            if decision.phase in TERMINAL and not self.dry_run:  # a dry run decides again while the pilot flies
                if self.supervision.stays_after(decision, sent):
                    self.ending.watch(decision)  # the vehicle is the autopilot's now: watch it until it is safe
                else:
                    self.done.set()  # after its command went out: ending cancels the tasks

    # -- one frame -------------------------------------------------------------------------------------------------
    async def on_frame(self, frame: Frame) -> None:
        """Pair the frame with its pose, run the pipeline and let the landing logic decide."""
        if not self.start_sequence.started:
            self.outcome.frames_before_start += 1
            return
        if self.guidance.phase in FRAMES_UNREAD:  # no decision reads it: the landing is the autopilot's, or over
            return
        paired = await self.intake.pose_for(frame)
        if paired is None:
            return
        t_pose_s, pose = paired
        result = await self.intake.perceive(frame, pose, self._area_centre_ne_m)
        if result is None or self.guidance.phase in TERMINAL:  # a tick may have ended the mission while it perceived
            return
        self._last_frame_t_s = max(self._last_frame_t_s, t_pose_s)
        state = self.vehicle_state()
        if state is None:
            return
        if state.t_s - t_pose_s > self.config.camera.max_frame_age_s:  # fell behind: decide on fresh frames only
            self.outcome.frames_dropped_old += 1
            return
        decision = self.guidance.on_frame(result, state)
        observed = observed_at_target(result, decision, state, self.config.guidance.perception_min_altitude_m)
        await self.apply(decision, DecisionSource.FRAME, state, observed, seq=frame.seq)
        await self.report.decision_values(result.t_s, len(result.tracks), decision.target, state)
        if self.commands.commanding and decision.kind is not CommandKind.NONE and math.isfinite(frame.arrival_wall_s):
            latency_ms = 1000.0 * (time.monotonic() - frame.arrival_wall_s)
            self.recorder.write(RecordKind.LATENCY, frame.t_capture_s, seq=frame.seq, frame_to_command_ms=latency_ms)

    # -- one tick ----------------------------------------------------------------------------------------------------
    async def on_tick(self, state: VehicleState) -> None:
        """The start sequence, then pilot takeover, touchdown and perception silence, at vehicle time ``state.t_s``."""
        self.outcome.ticks += 1
        status = self.link.telemetry.status
        self.supervision.saw(status)
        self.journal.pose(state, status)
        if self.start_sequence.started or self.supervision.watching is not None:
            self.journal.progress(state, status, watching=self.supervision.watching is not None)
        if self.supervision.watching is not None:
            self.ending.watch_tick(state, status)  # a stop asked for ends it at once: the vehicle is the autopilot's
            return
        if self.dry_run and self.ending.flight_over(state, status, self.guidance.phase is not LandingPhase.IDLE):
            return
        if self.guidance.phase in TERMINAL:
            if self.dry_run:  # the pilot still flies: decide again once the start's conditions hold again
                self._rearm(state)
            else:
                self.done.set()
            return
        if self.commands.pilot_has_it():
            self.commands.stop()  # never take control back in this flight
            mode = status.mode.value
            await self.apply(self.guidance.pilot_took_over(state.t_s, mode), DecisionSource.TAKEOVER, state, mode=mode)
            return
        if self.supervision.stop_requested is not None:  # after the pilot's word too
            await self._stop(state)
            return
        limit = self.supervision.wall_limit_reached()  # after the pilot's word too
        if limit is not None:
            await self._wall_limit(state, limit)
            return
        for taken in self.desk.take(self.guidance, state, self.intake.last_result):
            await self.apply(taken.decision, DecisionSource.OPERATOR, state, **taken.inputs)
        if not self.start_sequence.started:
            pose = self.link.telemetry.poses.pose_at(state.t_s) if self.dry_run else None
            visible = not self.dry_run or (pose is not None and self.pipeline.sees_head_plane(pose))
            await self._start_step(state, self.start_sequence.step(state, status, visible))
            return
        if self.guidance.phase is LandingPhase.LAND and not status.in_air:
            self.outcome.touchdown_ne_m = (state.north_m, state.east_m)
            self.outcome.touchdown_t_s = state.t_s
            await self.apply(self.guidance.landed(state.t_s), DecisionSource.LANDED, state)
            return
        low = self.energy.check(state, status) if self.energy is not None else None
        reason = None if low is None else low.reason()
        used_up = self.guidance.time_used_up(state, reason, None if low is None else low.home_m)
        if used_up is not None:
            inputs: dict[str, Any] = {} if low is None else low.inputs()
            await self.apply(used_up, DecisionSource.TIME if low is None else DecisionSource.ENERGY, state, **inputs)
            return
        silent_s = state.t_s - self._last_frame_t_s
        decision = self.guidance.perception_silent(state, silent_s)
        if decision is not None:
            await self.apply(decision, DecisionSource.SILENCE, state, silent_s=silent_s)

    def _rearm(self, state: VehicleState) -> None:
        """A dry run whose decisions ended (a failsafe, a landing) while the pilot flies on: a fresh state machine,
        started again once the vehicle is in the air and sees the head plane."""
        logger.info("[dry run] decisions ended in %s; deciding again once the start holds again", self.outcome.phase)
        self.recorder.write(RecordKind.WAITING, state.t_s, waiting_for="a new start (the last decisions ended)")
        self.guidance = landing_guidance(self.config, self.pipeline.policy)
        self.start_sequence = StartSequence(self.config.start, self.dry_run)
        self.journal.reset()

    async def _wall_limit(self, state: VehicleState, limit: str) -> None:
        """The wall limit of ``slz fly --timeout`` (``limit``, in words): the vehicle the companion flies gets the last
        resort (hold or return) and the run stays until it is safe; a run that commands nothing (a dry run, a wait
        for the pilot's handover) just ends."""
        if self._flying_it():
            await self.apply(self.guidance.give_up(state, limit), DecisionSource.LIMIT, state, reason=limit)
        else:
            self.ending.end(state.t_s, "wall_limit", f"{limit}: nothing commanded, the run ends", warn=True)

    def request_stop(self, why: str) -> None:
        """Ask the program to stop (``slz fly`` on SIGINT or SIGTERM: the service stopped, Ctrl-C): at the next tick
        a vehicle it flies gets ``guidance.last_resort`` before it ends, instead of an offboard-loss failsafe later.
        Asked twice, it ends at once (:class:`~companion.app.run_end.RunEnd`)."""
        self.ending.request_stop(why)

    async def _stop(self, state: VehicleState) -> None:
        """A stop asked of the program: the last resort for a vehicle it flies, then the end (no watch: a stopping
        service cannot stay); a run that commands nothing just ends."""
        last_resort = self._flying_it() and self.guidance.phase not in TERMINAL
        why = self.supervision.take_stop(last_resort)
        reason = f"{why}: stopping"
        if last_resort:
            await self.apply(self.guidance.give_up(state, reason), DecisionSource.STOP, state, reason=reason)
            return
        self.ending.end(state.t_s, "stopped", f"{reason}, nothing commanded")

    def _flying_it(self) -> bool:
        """The companion commands the vehicle: it took off with it, or sends it setpoints in OFFBOARD."""
        if not self.commands.commanding:
            return False
        took_off = self.start_sequence.takes_off and self.start_sequence.stage is not StartStage.WAITING
        return self.commands.in_offboard or took_off

    async def _localize(self) -> None:
        """The fence in latitude and longitude in local NED (:func:`fence_in_local_ned`), the autopilot's rally points
        as fallback sites (:func:`~companion.app.fallback_sites.with_rally_sites`), and what follows them."""
        before = self.config
        if self.config.geofence.polygon_latlon_deg is not None:
            self.config = await fence_in_local_ned(self.config, self.link.mission, self.recorder)
        if self.config.guidance.fallback.rally_points:
            self.config = await with_rally_sites(self.config, self.link.mission, self.recorder)
        if self.config is before:
            return
        polygon_ne_m = self.config.geofence.polygon_ne_m
        self.guidance = landing_guidance(self.config, self.pipeline.policy)
        self._area_centre_ne_m = polygon_centroid_ne_m(polygon_ne_m)
        self.pipeline.zone_finder = ZoneFinder(self.config.perception.zones, polygon_ne_m)

    async def _start_step(self, state: VehicleState, step: StartStep) -> None:
        """Do what the start sequence asks at this tick: record, take off, send a transit setpoint, or start."""
        if step.action is StartAction.TIMED_OUT:
            raise VehicleError(self.link.name, step.reason, LinkResult.TIMEOUT)
        self.journal.start_step(state, step)
        if step.action is StartAction.TAKE_OFF:
            if await self.commands.take_off(state.t_s, step.altitude_m):
                self.start_sequence.took_off()
        elif step.action is StartAction.TRANSIT:
            # Fly to the start pose first (SITL campaigns): through the same safety filter as every setpoint.
            setpoint = self.guidance.safe_setpoint(state, step.north_m, step.east_m, step.altitude_m, step.yaw_deg)
            transit = Decision(
                state.t_s, LandingPhase.IDLE, CommandKind.SETPOINT, setpoint, None, "transit", DecisionEvent.TRANSIT
            )
            await self.commands.send(transit)
        elif step.action is StartAction.START:
            self._last_frame_t_s = state.t_s  # perception silence counts from here
            await self.apply(self.guidance.start(state), DecisionSource.START, state)

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
        await self.intake.wait_for_pose(t_s, timeout_s, "the tick's pose")

    def telemetry_age_s(self) -> float | None:
        last_telemetry = self.link.telemetry.status.last_telemetry_wall_s
        return None if last_telemetry is None else time.monotonic() - last_telemetry

    def take_tick_setpoint(self) -> SetpointNedYaw | None:
        return self.commands.take_tick_setpoint()

    def camera_lost(self, exc: CameraError) -> None:
        self.outcome.camera_lost, self.outcome.camera_fault = True, exc.fault.value
        self.journal.camera_fault(self.link.telemetry.poses.latest_t_s, exc.fault.value, str(exc))

    def link_lost(self, silent_s: float) -> None:
        self.outcome.link_lost = True
        self.commands.stop()
        state = self.vehicle_state()
        self.journal.link_lost(state.t_s if state else None, silent_s, self.link.telemetry.status.port_shared)
        if self.lockstep is not None:
            self.lockstep.release()  # the simulator runs on without us, so its own failsafe can act
        self.done.set()

    # -- the flight ------------------------------------------------------------------------------------------------
    async def _open(self) -> None:
        """The camera (missing: no vehicle touched), the vehicle, the fence, the lockstep; a stop ends it (run)."""
        waiting = functools.partial(self.recorder.write, RecordKind.WAITING, None)  # said as a record too
        url, wait_for_s = self.config.camera.url, self.config.camera.wait_for_s
        await open_when_up(self.source, url, wait_for_s, lambda why: waiting(waiting_for=f"the camera: {why}"))
        await self.link.connect(self.config.vehicle.connect_timeout_s)
        await self._localize()
        if self.lockstep is not None and not await self.lockstep.open(frames=self.wants_frames):
            self.lockstep = None
        await self.desk.open(self.link.system_id)

    async def run(self) -> FlightOutcome:
        """Connect, (take off,) land safely or end in a defined failsafe (and, with ``supervision``, stay until the
        vehicle is on the ground or the pilot has it)."""
        cfg = self.config
        wall0, cpu0 = time.monotonic(), time.process_time()
        self.recorder.write(RecordKind.START, None, mode=cfg.mode, vehicle=cfg.vehicle.url, camera=cfg.camera.url)
        if not await unless_done(self._open(), self.done, CANCEL_GRACE_S):  # stopped before the vehicle was found
            return self._end()
        self.outcome.lockstep = self.lockstep is not None
        self.recorder.write(RecordKind.CLOCK, None, lockstep=self.outcome.lockstep)
        if self.lockstep is None:
            self.watchdog.start()
        if self.lockstep is not None:
            loops = [LockstepDriver(self, self.lockstep).run()]
        else:
            free = FreeRunningDriver(self)
            loops = [free.frames(), free.ticks()]
        try:
            await run_until_first_ends([*loops, self.watchdog.heartbeat(self.done)], self.done, CANCEL_GRACE_S)
        finally:
            self.watchdog.stop()
            self.intake.close()
            if self.lockstep is not None:
                self.lockstep.release()
                self.lockstep.close()
            self.outcome.wall_s, self.outcome.cpu_s = time.monotonic() - wall0, time.process_time() - cpu0
            self._end()
        return self.outcome

    def _end(self) -> FlightOutcome:
        """The ground channel closed and counted, and the end record."""
        self.desk.close()
        self.outcome.ground_channel = self.desk.counts()
        self.recorder.write(RecordKind.END, None, outcome=self.outcome)
        return self.outcome
