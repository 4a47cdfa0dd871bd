"""The landing logic's side of a flight: each stimulus in, each decision out.

:class:`LandingLoop` hands the landing logic (:class:`~companion.guidance.landing.LandingGuidance`) its typed stimuli
(:mod:`companion.guidance.stimulus`) through its one entry point, and each decision it makes goes one way: recorded with
its stimulus (:class:`~companion.app.journal.FlightJournal`), its phase change reported to the ground station
(:class:`~companion.app.ground_report.GroundReport`), sent when flying
(:class:`~companion.app.commands.VehicleCommands`), the warning device switched, and a terminal one handed to the run's
end (:class:`~companion.app.run_end.RunEnd`).

A frame is a :class:`~companion.guidance.stimulus.FrameSeen` once the intake has paired it with its pose and the
pipeline has seen it; a vehicle tick looks for its stimuli in the order of
:data:`~companion.guidance.stimulus.TICK_PRIORITY`, until one decides. The start (takeoff or the pilot's handover,
climb, transit) is asked by :class:`~companion.app.start_sequence.StartSequence` before the mission's first decision.
Times are the vehicle's clock throughout. :class:`~companion.app.flight.FlightApp` wires this loop to the vehicle, the
camera and the drivers.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Awaitable, Callable

from companion.app.commands import VehicleCommands
from companion.app.fallback_sites import with_rally_sites
from companion.app.frame_intake import FrameIntake
from companion.app.ground_report import GroundReport
from companion.app.journal import FlightJournal
from companion.app.mission import MissionConfig, OperatingMode, with_fence_ne_m
from companion.app.operator_desk import OperatorDesk
from companion.app.outcome import FlightOutcome
from companion.app.run_end import RunEnd
from companion.app.start_sequence import StartAction, StartSequence, StartStage
from companion.app.supervision import Supervision
from companion.app.warning_device import WarningDevice
from companion.camera.frames import Frame
from companion.flightlog.flight_log import RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.geometry import Pose, polygon_centroid_ne_m
from companion.guidance.energy import EnergyBudget
from companion.guidance.footprint import nearest_occupied_m
from companion.guidance.geofence import Geofence, latlon_to_ne_m
from companion.guidance.landing import CommandKind, Decision, LandingGuidance, LandingPhase
from companion.guidance.stimulus import (
    TICK_PRIORITY,
    EnergyLow,
    FrameSeen,
    Landed,
    LimitReached,
    OperatorOrder,
    PilotTookOver,
    Silence,
    Started,
    Stimulus,
    StopAsked,
    TimeUp,
)
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent
from companion.json_value import JsonObject
from companion.perception.pipeline import FrameResult, SlzPipeline
from companion.perception.selection import SelectionPolicy
from companion.perception.zones import ZoneFinder
from companion.vehicle.link import Ground, LinkResult, MissionStore, Telemetry, VehicleError, VehicleStatus

logger = logging.getLogger(__name__)

TERMINAL = frozenset({LandingPhase.DONE, LandingPhase.YIELDED, LandingPhase.FAILSAFE})
# Phases in which no decision reads a frame: the flight is over, or the landing is the autopilot's (the guidance
# ignores frames in LAND, which leads only to DONE or YIELDED). A simulator in lockstep is not asked to draw them.
FRAMES_UNREAD = TERMINAL | {LandingPhase.LAND}


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
) -> JsonObject | None:
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


def vehicle_state(telemetry: Telemetry) -> VehicleState | None:
    """The vehicle at its newest stamped pose (None before the first)."""
    t = telemetry.poses.latest_t_s
    pose = telemetry.poses.pose_at(t) if t is not None else None
    return None if t is None or pose is None else state_of(t, pose)


class LandingLoop:
    """The landing logic's stimuli and decisions in one flight (see the module docstring).

    Parameters
    ----------
    config : MissionConfig
        The validated mission (its fence and fallback sites in local NED after :meth:`localize`).
    telemetry, ground : Telemetry, Ground
        The vehicle link's parts this loop reads (poses, status) and reports to the ground station through.
    pipeline : SlzPipeline
        Perception: its selection policy is the landing logic's.
    recorder : FlightRecorder
        Where every record goes.
    outcome : FlightOutcome
        The flight's counters and ending, updated here.
    commands, intake, desk : VehicleCommands, FrameIntake, OperatorDesk
        What sends decisions, what pairs and perceives frames, what takes the ground station's commands.
    supervision, ending : Supervision, RunEnd
        The pilot, the stop and the wall limit, watched; and how the run ends.
    link_name : str
        The vehicle link, named when the start times out.
    """

    def __init__(
        self,
        config: MissionConfig,
        telemetry: Telemetry,
        ground: Ground,
        pipeline: SlzPipeline,
        recorder: FlightRecorder,
        outcome: FlightOutcome,
        commands: VehicleCommands,
        intake: FrameIntake,
        desk: OperatorDesk,
        supervision: Supervision,
        ending: RunEnd,
        link_name: str,
    ) -> None:
        self.config = config
        self.telemetry = telemetry
        self.pipeline = pipeline
        self.recorder = recorder
        self.outcome = outcome
        self.commands = commands
        self.intake = intake
        self.desk = desk
        self.supervision = supervision
        self.ending = ending
        self.link_name = link_name
        self.dry_run = config.mode is OperatingMode.DRY_RUN
        self.report = GroundReport(ground, self.dry_run)
        self.journal = FlightJournal(recorder, self.dry_run)
        self.warning = WarningDevice(config.guidance.warning, commands, recorder)
        self.energy = EnergyBudget(config.guidance.energy) if config.guidance.energy.enabled else None
        self.guidance = landing_guidance(config, pipeline.policy)
        self.start_sequence = StartSequence(config.start, self.dry_run)
        # The search area's centre for the blind random baseline (the paper's ROI): the geofence's centroid.
        self._area_centre_ne_m = polygon_centroid_ne_m(config.geofence.polygon_ne_m)
        self._last_frame_t_s = -math.inf  # capture time of the newest processed frame (vehicle clock)

    @property
    def wants_frames(self) -> bool:
        """A decision reads frames now (the mission started and is not over or the autopilot's)."""
        return self.start_sequence.started and self.guidance.phase not in FRAMES_UNREAD

    async def apply(self, decision: Decision, stimulus: Stimulus, observed: JsonObject | None = None) -> None:
        """Record a decision with the ``stimulus`` it answered (:meth:`FlightJournal.decision`), report its phase
        change to the ground station and, when flying, send it."""
        previous = self.outcome.phase
        self.outcome.phase = decision.phase.value
        self.outcome.reason = decision.reason
        self.journal.decision(decision, previous, stimulus, observed)
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
                    self.ending.over()  # after its command went out: ending cancels the tasks

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
        state = vehicle_state(self.telemetry)
        if state is None:
            return
        if state.t_s - t_pose_s > self.config.camera.max_frame_age_s:  # fell behind: decide on fresh frames only
            self.outcome.frames_dropped_old += 1
            return
        seen = FrameSeen(state, result, frame.seq)
        decision = self.guidance.on(seen)
        observed = observed_at_target(result, decision, state, self.config.guidance.perception_min_altitude_m)
        await self.apply(decision, seen, observed)
        await self.report.decision_values(result.t_s, len(result.tracks), decision.target, state)
        if self.commands.commanding and decision.kind is not CommandKind.NONE and math.isfinite(frame.arrival_wall_s):
            latency_ms = 1000.0 * (time.monotonic() - frame.arrival_wall_s)
            self.recorder.write(RecordKind.LATENCY, frame.t_capture_s, seq=frame.seq, frame_to_command_ms=latency_ms)

    async def on_tick(self, state: VehicleState) -> None:
        """A vehicle tick at ``state.t_s``: the pose and progress recorded, a watched or ended flight's own end, then
        the tick's stimuli in the order of :data:`~companion.guidance.stimulus.TICK_PRIORITY`, until one decides."""
        self.outcome.ticks += 1
        status = self.telemetry.status
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
                self.ending.over()
            return
        checks: dict[type[Stimulus], Callable[[VehicleState, VehicleStatus], Awaitable[bool]]] = {
            PilotTookOver: self._pilot,
            StopAsked: self._stop,
            LimitReached: self._wall_limit,
            OperatorOrder: self._operator,
            Started: self._start_step,
            Landed: self._touchdown,
            TimeUp: self._budget,
            Silence: self._silence,
        }
        for kind in TICK_PRIORITY:
            if await checks[kind](state, status):
                return

    async def _pilot(self, state: VehicleState, status: VehicleStatus) -> bool:
        """The pilot's mode while this flight flew the vehicle: yield, and never take control back."""
        if not self.commands.pilot_has_it():
            return False
        self.commands.stop()
        await self._decide(PilotTookOver(state, status.mode.value))
        return True

    async def _operator(self, state: VehicleState, status: VehicleStatus) -> bool:
        """The ground station's commands since the last tick, each decided (the tick goes on after them)."""
        for order, decision in self.desk.take(self.guidance, state, self.intake.last_result):
            await self.apply(decision, order)
        return False

    async def _touchdown(self, state: VehicleState, status: VehicleStatus) -> bool:
        """The vehicle on the ground after the landing was commanded."""
        if self.guidance.phase is not LandingPhase.LAND or status.in_air:
            return False
        self.outcome.touchdown_ne_m = (state.north_m, state.east_m)
        self.outcome.touchdown_t_s = state.t_s
        await self._decide(Landed(state))
        return True

    async def _budget(self, state: VehicleState, status: VehicleStatus) -> bool:
        """The search's budget: its time, or the energy budget's word when that is used up."""
        low = self.energy.check(state, status) if self.energy is not None else None
        if low is None:
            return await self._decide(TimeUp(state))
        return await self._decide(EnergyLow(state, low.reason(), low.home_m, low.remaining))

    async def _silence(self, state: VehicleState, status: VehicleStatus) -> bool:
        """Perception silent since the newest frame (or the start)."""
        return await self._decide(Silence(state, state.t_s - self._last_frame_t_s))

    async def _decide(self, stimulus: Stimulus) -> bool:
        """The landing logic's decision on ``stimulus``, applied; whether there was one."""
        decision = self.guidance.on(stimulus)
        if not isinstance(decision, Decision):
            return False
        await self.apply(decision, stimulus)
        return True

    def _rearm(self, state: VehicleState) -> None:
        """A dry run whose decisions ended (a failsafe, a landing) while the pilot flies on: a fresh state machine,
        started again once the vehicle is in the air and sees the head plane."""
        logger.info("[dry run] decisions ended in %s; deciding again once the start holds again", self.outcome.phase)
        self.recorder.write(RecordKind.WAITING, state.t_s, waiting_for="a new start (the last decisions ended)")
        self.guidance = landing_guidance(self.config, self.pipeline.policy)
        self.start_sequence = StartSequence(self.config.start, self.dry_run)
        self.journal.reset()

    async def _wall_limit(self, state: VehicleState, status: VehicleStatus) -> bool:
        """The wall limit of ``slz fly --timeout``, once reached: the vehicle the companion flies gets the last resort
        (hold or return) and the run stays until it is safe; a run that commands nothing (a dry run, a wait for the
        pilot's handover) just ends."""
        limit = self.supervision.wall_limit_reached()
        if limit is None:
            return False
        if self._flying_it():
            await self._decide(LimitReached(state, limit))
        else:
            self.ending.end(state.t_s, "wall_limit", f"{limit}: nothing commanded, the run ends", warn=True)
        return True

    async def _stop(self, state: VehicleState, status: VehicleStatus) -> bool:
        """A stop asked of the program: the last resort for a vehicle it flies, then the end (no watch: a stopping
        service cannot stay); a run that commands nothing just ends."""
        if self.supervision.stop_requested is None:
            return False
        last_resort = self._flying_it() and self.guidance.phase not in TERMINAL
        reason = f"{self.supervision.take_stop(last_resort)}: stopping"
        if last_resort:
            await self._decide(StopAsked(state, reason))
        else:
            self.ending.end(state.t_s, "stopped", f"{reason}, nothing commanded")
        return True

    def _flying_it(self) -> bool:
        """The companion commands the vehicle: it took off with it, or sends it setpoints in OFFBOARD."""
        if not self.commands.commanding:
            return False
        took_off = self.start_sequence.takes_off and self.start_sequence.stage is not StartStage.WAITING
        return self.commands.in_offboard or took_off

    async def localize(self, mission: MissionStore) -> None:
        """The fence in latitude and longitude in local NED (:func:`fence_in_local_ned`), the autopilot's rally points
        as fallback sites (:func:`~companion.app.fallback_sites.with_rally_sites`), and what follows them."""
        before = self.config
        if self.config.geofence.polygon_latlon_deg is not None:
            self.config = await fence_in_local_ned(self.config, mission, self.recorder)
        if self.config.guidance.fallback.rally_points:
            self.config = await with_rally_sites(self.config, mission, self.recorder)
        if self.config is before:
            return
        polygon_ne_m = self.config.geofence.polygon_ne_m
        self.guidance = landing_guidance(self.config, self.pipeline.policy)
        self._area_centre_ne_m = polygon_centroid_ne_m(polygon_ne_m)
        self.pipeline.zone_finder = ZoneFinder(self.config.perception.zones, polygon_ne_m)

    async def _start_step(self, state: VehicleState, status: VehicleStatus) -> bool:
        """Until the mission has started, what the start sequence asks at this tick: record, take off, send a transit
        setpoint, or start (it ends the tick)."""
        if self.start_sequence.started:
            return False
        pose = self.telemetry.poses.pose_at(state.t_s) if self.dry_run else None
        visible = not self.dry_run or (pose is not None and self.pipeline.sees_head_plane(pose))
        step = self.start_sequence.step(state, status, visible)
        if step.action is StartAction.TIMED_OUT:
            raise VehicleError(self.link_name, step.reason, LinkResult.TIMEOUT)
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
            await self._decide(Started(state))
        return True
