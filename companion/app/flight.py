"""The flight loop of ``slz fly``: frames and telemetry in, decisions out, everything recorded.

Concurrency (structured, Python 3.10-compatible: tasks are created together, kept, and cancelled together when
one ends or fails):

- **perception**: each frame is paired with the pose interpolated at its capture time (frames too old, or with no
  pose, are dropped and counted), the pipeline runs in a one-thread executor (onnxruntime releases the GIL; the
  event loop never blocks), and the state machine decides;
- **supervisor** (wall clock, liveness only): perception silence (T1 hold, T2 failsafe action), pilot takeover
  (mode left OFFBOARD: yield at once, for the rest of the flight), link loss (stop commanding, let the autopilot's
  own failsafe act), touchdown;
- **stall watchdog** (a thread): if the event loop stops beating for ``decision_watchdog_s``, it stops offboard
  from outside the loop, since MAVSDK keeps re-sending the last setpoint on its own thread.

In a dry run the same perception and decisions run and are recorded, but nothing is sent: no arming, no mode
change, no setpoint.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from companion.app.mission import MissionConfig, OperatingMode
from companion.app.recorder import FlightRecorder
from companion.camera.frames import Frame, FrameSource
from companion.guidance.geofence import Geofence
from companion.guidance.landing import CommandKind, Decision, LandingGuidance, LandingPhase, VehicleState
from companion.perception.errors import PerceptionError
from companion.perception.geometry import Pose
from companion.perception.pipeline import FrameResult, SlzPipeline
from companion.vehicle.link import FlightMode, VehicleError, VehicleLink

logger = logging.getLogger(__name__)

TERMINAL = frozenset({LandingPhase.DONE, LandingPhase.YIELDED, LandingPhase.FAILSAFE})


@dataclass
class FlightOutcome:
    """How a flight ended."""

    phase: str = LandingPhase.IDLE.value
    reason: str = ""
    touchdown_ne_m: tuple[float, float] | None = None
    frames_processed: int = 0
    frames_dropped_old: int = 0
    frames_dropped_no_pose: int = 0
    frames_failed: int = 0
    commands_sent: int = 0
    link_lost: bool = False
    failsafes: list[str] = field(default_factory=list)


def yaw_deg_of(pose: Pose) -> float:
    """Heading of the body x axis in the world NED frame, degrees."""
    R = pose.T_world_body
    return math.degrees(math.atan2(R[1, 0], R[0, 0]))


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
    """

    def __init__(
        self,
        config: MissionConfig,
        link: VehicleLink,
        source: FrameSource,
        pipeline: SlzPipeline,
        recorder: FlightRecorder,
    ) -> None:
        self.config = config
        self.link = link
        self.source = source
        self.pipeline = pipeline
        self.recorder = recorder
        self.dry_run = config.mode is OperatingMode.DRY_RUN
        zones = config.perception.zones
        self.guidance = LandingGuidance(
            config.guidance, Geofence(config.geofence), zones.min_radius_m, zones.min_radius_m
        )
        self.outcome = FlightOutcome()
        self._executor = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="perception")
        self._last_frame_wall = time.monotonic()
        self._beat_wall = time.monotonic()
        self._offboard = False
        self._commanding = not self.dry_run
        self._stop = threading.Event()
        self._done = asyncio.Event()

    # -- vehicle state ------------------------------------------------------------------------------------------
    def vehicle_state(self) -> VehicleState | None:
        """The vehicle at its newest stamped pose."""
        t = self.link.poses.latest_t_s
        pose = self.link.poses.pose_at(t) if t is not None else None
        if t is None or pose is None:
            return None
        n, e, d = (float(v) for v in pose.position_ned_m)
        return VehicleState(t, n, e, d, yaw_deg_of(pose))

    # -- applying decisions --------------------------------------------------------------------------------------
    async def apply(self, decision: Decision) -> None:
        """Record a decision and, when flying, send it."""
        previous = self.outcome.phase
        self.outcome.phase = decision.phase.value
        self.outcome.reason = decision.reason
        self.recorder.write("decision", decision.t_s, decision=decision)
        if decision.phase.value != previous:
            self.recorder.write("phase", decision.t_s, phase=decision.phase, previous=previous, reason=decision.reason)
            await self.link.status_text(f"SLZ {decision.phase.value}: {decision.reason}")
        if decision.phase is LandingPhase.FAILSAFE:
            self.outcome.failsafes.append(decision.reason)
            self.recorder.write("failsafe", decision.t_s, reason=decision.reason, action=decision.kind)
        if not self._commanding or decision.kind is CommandKind.NONE:
            return
        try:
            if decision.kind is CommandKind.SETPOINT:
                assert decision.setpoint is not None
                if not self._offboard:
                    await self.link.start_offboard(decision.setpoint)
                    # Takeover detection starts only once the autopilot reports OFFBOARD (telemetry lags the ack).
                    await self.link.wait_for(
                        lambda: self.link.status.mode is FlightMode.OFFBOARD, time.monotonic() + 3.0, "OFFBOARD"
                    )
                    self._offboard = True
                else:
                    await self.link.set_setpoint(decision.setpoint)
            elif decision.kind is CommandKind.LAND:
                await self.link.land()
            elif decision.kind is CommandKind.HOLD:
                await self.link.hold()
            elif decision.kind is CommandKind.RETURN:
                await self.link.return_to_launch()
        except VehicleError as exc:
            self.recorder.write("error", decision.t_s, where="command", error=str(exc))
            raise
        self.outcome.commands_sent += 1
        self.recorder.write("command", decision.t_s, command=decision.kind, setpoint=decision.setpoint)
        if decision.kind is not CommandKind.SETPOINT:
            self._offboard = False  # the autopilot's own mode now

    # -- tasks ---------------------------------------------------------------------------------------------------
    async def _perception(self) -> None:
        loop = asyncio.get_running_loop()
        max_age = self.config.camera.max_frame_age_s
        frames = self.source.frames()
        try:
            async for frame in frames:
                self._beat_wall = time.monotonic()
                pose = await self._pose_for(frame)
                if pose is None:
                    continue
                try:
                    result: FrameResult = await loop.run_in_executor(
                        self._executor, self.pipeline.process, frame.image_bgr, pose, frame.t_capture_s
                    )
                except PerceptionError as exc:  # one bad frame or pose; a lasting failure trips the silence failsafe
                    self.outcome.frames_failed += 1
                    self.recorder.write("frame_error", frame.t_capture_s, seq=frame.seq, error=str(exc))
                    continue
                self._last_frame_wall = time.monotonic()
                self.outcome.frames_processed += 1
                self.recorder.frame(frame.seq, frame.t_capture_s, frame.image_bgr)
                self.recorder.write(
                    "frame_result",
                    frame.t_capture_s,
                    seq=frame.seq,
                    T_world_body=pose.T_world_body,
                    tracks=result.tracks,
                    target=result.target,
                    timings_ms=result.timings_ms,
                )
                state = self.vehicle_state()
                if state is None or self.guidance.phase in TERMINAL:
                    continue
                latest = self.link.poses.latest_t_s or frame.t_capture_s
                if latest - frame.t_capture_s > max_age:  # processing fell behind: decide on fresh frames only
                    self.outcome.frames_dropped_old += 1
                    continue
                await self.apply(self.guidance.on_frame(result, state))
                if self.guidance.phase in TERMINAL:
                    self._done.set()
        finally:
            await frames.aclose()  # type: ignore[attr-defined]

    async def _pose_for(self, frame: Frame) -> Pose | None:
        """The pose at the frame's capture time, waiting briefly for telemetry to catch up; None drops the frame."""
        max_age = self.config.camera.max_frame_age_s

        def caught_up() -> bool:
            latest = self.link.poses.latest_t_s
            return latest is not None and latest >= frame.t_capture_s

        try:
            await self.link.wait_for(caught_up, time.monotonic() + max_age, "telemetry at the frame's capture time")
        except VehicleError:
            self.outcome.frames_dropped_no_pose += 1
            return None
        latest = self.link.poses.latest_t_s
        assert latest is not None
        if latest - frame.t_capture_s > max_age:
            self.outcome.frames_dropped_old += 1
            return None
        pose = self.link.poses.pose_at(frame.t_capture_s)
        if pose is None:
            self.outcome.frames_dropped_no_pose += 1
        return pose

    async def _supervise(self) -> None:
        cfg = self.config
        while not self._done.is_set():
            self._beat_wall = time.monotonic()
            now = time.monotonic()
            status = self.link.status
            state = self.vehicle_state()
            phase = self.guidance.phase
            last_telemetry = status.last_telemetry_wall_s
            if last_telemetry is not None and now - last_telemetry > cfg.vehicle.link_lost_after_s:
                self.outcome.link_lost = True
                self._commanding = False
                self.recorder.write("failsafe", state.t_s if state else None, reason="link lost: stop commanding")
                logger.error("link lost: no telemetry for %.1f s; the autopilot's failsafe acts", now - last_telemetry)
                self._done.set()
                return
            if state is not None:
                if self._offboard and status.mode not in (FlightMode.OFFBOARD, FlightMode.UNKNOWN) and not self.dry_run:
                    self._offboard = False
                    self._commanding = False  # never take control back in this flight
                    await self.apply(self.guidance.pilot_took_over(state.t_s, status.mode.value))
                    self._done.set()
                    return
                if phase is LandingPhase.LAND and not status.in_air:
                    self.outcome.touchdown_ne_m = (state.north_m, state.east_m)
                    await self.apply(self.guidance.landed(state.t_s))
                    self._done.set()
                    return
                decision = self.guidance.perception_silent(state, now - self._last_frame_wall)
                if decision is not None:
                    await self.apply(decision)
                    if self.guidance.phase in TERMINAL:
                        self._done.set()
                        return
            with contextlib.suppress(asyncio.TimeoutError):  # the supervisor's 10 Hz tick
                await asyncio.wait_for(self._done.wait(), 0.1)

    def _stall_watchdog(self) -> None:
        limit = self.config.vehicle.decision_watchdog_s
        while not self._stop.wait(limit / 4):
            if self._offboard and self._commanding and time.monotonic() - self._beat_wall > limit:
                logger.error("decision loop stalled for %.2f s: stopping offboard", time.monotonic() - self._beat_wall)
                self.link.stop_offboard_blocking()
                self._offboard = False
                self._commanding = False

    # -- the flight ------------------------------------------------------------------------------------------------
    async def run(self, timeout_s: float) -> FlightOutcome:
        """Connect, (take off,) land safely or end in a defined failsafe, within ``timeout_s`` of wall time."""
        cfg = self.config
        self.recorder.write("start", None, mode=cfg.mode, vehicle=cfg.vehicle.url, camera=cfg.camera.url)
        await self.link.connect(cfg.vehicle.connect_timeout_s)
        if cfg.start.arm_and_takeoff and not self.dry_run:
            await self.link.arm_and_takeoff(cfg.start.takeoff_altitude_m, timeout_s=60.0)
        await self.link.wait_for(lambda: self.vehicle_state() is not None, time.monotonic() + 10.0, "a stamped pose")
        state = self.vehicle_state()
        assert state is not None
        self._last_frame_wall = time.monotonic()
        await self.apply(self.guidance.start(state))
        watchdog = threading.Thread(target=self._stall_watchdog, name="stall-watchdog", daemon=True)
        watchdog.start()
        tasks: list[asyncio.Task[Any]] = [
            asyncio.create_task(self._perception(), name="perception"),
            asyncio.create_task(self._supervise(), name="supervisor"),
            asyncio.create_task(self._done.wait(), name="done"),
        ]
        try:
            done, _ = await asyncio.wait(tasks, timeout=timeout_s, return_when=asyncio.FIRST_COMPLETED)
            if not done:
                self.outcome.reason = f"mission timed out after {timeout_s:g} s"
            for task in done:
                if not task.cancelled() and task.exception() is not None:
                    raise task.exception()  # type: ignore[misc]
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self._stop.set()
            watchdog.join(timeout=2.0)
            self._executor.shutdown(wait=True)
            self.recorder.write("end", None, outcome=self.outcome)
        return self.outcome
