"""The flight loop of ``slz fly``: frames and telemetry in, decisions out, everything recorded.

Two drivers, one logic. Each camera frame and each vehicle *tick* go to the flight's
:class:`~companion.app.landing_loop.LandingLoop`: a frame is paired with its pose at its capture time and perceived (the
pipeline in a one-thread executor so the event loop never blocks: :class:`~companion.app.frame_intake.FrameIntake`); a
tick looks for its stimuli in the order of :data:`~companion.guidance.stimulus.TICK_PRIORITY` (pilot takeover, a stop,
the wall limit, the ground station, the start sequence, touchdown, the budget, perception silence). The landing logic
sees each as a typed stimulus through its one entry point, :meth:`~companion.guidance.landing.LandingGuidance.on`, and
:class:`~companion.app.commands.VehicleCommands` sends its decisions. Times are the vehicle's clock throughout.

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
change, no setpoint. Every decision is recorded with the stimulus that produced it, so ``slz replay`` can hand the
same stimuli to a fresh state machine.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import time
from collections.abc import AsyncIterator, Callable

from companion.app.commands import VehicleCommands
from companion.app.drivers import FreeRunningDriver, LockstepDriver
from companion.app.frame_intake import FrameIntake
from companion.app.landing_loop import LandingLoop, vehicle_state
from companion.app.mission import MissionConfig, OperatingMode
from companion.app.operator_desk import OperatorDesk
from companion.app.outcome import FlightOutcome
from companion.app.run_end import RunEnd
from companion.app.stall_watchdog import StallWatchdog
from companion.app.supervision import Supervision
from companion.app.task_group import run_until_first_ends, unless_done
from companion.camera.frames import CameraError, Frame, FrameSource
from companion.camera.waiting import open_when_up
from companion.flightlog.flight_log import RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.guidance.vehicle_state import VehicleState
from companion.perception.pipeline import SlzPipeline
from companion.vehicle.link import VehicleLink
from companion.vehicle.lockstep import LockstepClient
from companion.vehicle.sim_control import SetpointNedYaw

logger = logging.getLogger(__name__)

CANCEL_GRACE_S = 5.0  # wall time for the flight's tasks to stop once cancelled


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
        self.link = link
        self.source = source
        self.pipeline = pipeline
        self.recorder = recorder
        self.lockstep = lockstep
        self.outcome = FlightOutcome()
        self.done = asyncio.Event()
        dry_run = config.mode is OperatingMode.DRY_RUN
        self.commands = VehicleCommands(link.telemetry, link.action, link.offboard, recorder, self.outcome, dry_run)
        self.intake = FrameIntake(link.telemetry, pipeline, recorder, self.outcome, config.camera.max_frame_age_s)
        self.watchdog = StallWatchdog(
            config.vehicle.decision_watchdog_s, lambda: self.commands.flying_offboard, self.commands.stalled
        )
        self.supervision = Supervision(config.supervision.stay_after_failsafe, wall_limit_s, wall_clock)
        self.ending = RunEnd(self.supervision, recorder, self.outcome, self.done)
        self.desk = OperatorDesk.from_config(config, recorder)
        self.landing = LandingLoop(
            config,
            link.telemetry,
            link.ground,
            pipeline,
            recorder,
            self.outcome,
            self.commands,
            self.intake,
            self.desk,
            self.supervision,
            self.ending,
            link.name,
        )

    @property
    def config(self) -> MissionConfig:
        """The mission (its fence and fallback sites in local NED once connected)."""
        return self.landing.config

    def vehicle_state(self) -> VehicleState | None:
        """The vehicle at its newest stamped pose."""
        return vehicle_state(self.link.telemetry)

    async def on_frame(self, frame: Frame) -> None:
        """One camera frame to the landing loop (:meth:`LandingLoop.on_frame`)."""
        await self.landing.on_frame(frame)

    async def on_tick(self, state: VehicleState) -> None:
        """One vehicle tick to the landing loop (:meth:`LandingLoop.on_tick`)."""
        await self.landing.on_tick(state)

    def request_stop(self, why: str) -> None:
        """Ask the program to stop (``slz fly`` on SIGINT or SIGTERM: the service stopped, Ctrl-C): at the next tick
        a vehicle it flies gets ``guidance.last_resort`` before it ends, instead of an offboard-loss failsafe later.
        Asked twice, it ends at once (:class:`~companion.app.run_end.RunEnd`)."""
        self.ending.request_stop(why)

    # -- what the drivers see (companion.app.drivers.FlightLoop) ----------------------------------------------------
    @property
    def link_lost_after_s(self) -> float:
        return self.config.vehicle.link_lost_after_s

    @property
    def camera_is_lost(self) -> bool:
        return self.outcome.camera_lost

    @property
    def wants_frames(self) -> bool:
        return self.landing.wants_frames

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
        self.landing.journal.camera_fault(self.link.telemetry.poses.latest_t_s, exc.fault.value, str(exc))

    def link_lost(self, silent_s: float) -> None:
        self.outcome.link_lost = True
        self.commands.stop()
        state = self.vehicle_state()
        self.landing.journal.link_lost(state.t_s if state else None, silent_s, self.link.telemetry.status.port_shared)
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
        await self.landing.localize(self.link.mission)
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
