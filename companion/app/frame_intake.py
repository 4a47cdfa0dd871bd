"""A camera frame's way into the decisions: paired with the vehicle's pose at its capture time (waiting briefly for
telemetry to catch up), then through the perception pipeline in a one-thread executor, so the event loop never blocks.
Frames that cannot be paired, are too old or fail perception are dropped and counted, and each result is recorded.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import functools
import time
from collections.abc import Callable

from companion.app.outcome import FlightOutcome
from companion.camera.frames import Frame
from companion.flightlog.flight_log import RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.geometry import GeometryError, Pose
from companion.perception.errors import PerceptionError
from companion.perception.pipeline import FrameResult, SlzPipeline
from companion.vehicle.link import Telemetry, VehicleError

CLOCK_RESOLUTION_S = 1e-3  # MAVLink time_boot_ms


class FrameIntake:
    """Pairs frames with poses and runs perception on them.

    Parameters
    ----------
    telemetry : Telemetry
        The vehicle's telemetry: its pose buffer (vehicle-clock stamps).
    pipeline : SlzPipeline
        Perception.
    recorder : FlightRecorder
        Each frame, result and failure.
    outcome : FlightOutcome
        The frame counters.
    max_frame_age_s : float
        A frame older than this (vehicle time) next to the newest pose is dropped.
    """

    def __init__(
        self,
        telemetry: Telemetry,
        pipeline: SlzPipeline,
        recorder: FlightRecorder,
        outcome: FlightOutcome,
        max_frame_age_s: float,
    ) -> None:
        self.telemetry = telemetry
        self.pipeline = pipeline
        self.recorder = recorder
        self.outcome = outcome
        self.max_frame_age_s = max_frame_age_s
        self.last_result: FrameResult | None = None
        """The newest frame perceived (None: none yet)."""
        self._executor = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="perception")
        self.viewers: list[Callable[[Frame, FrameResult], None]] = []
        """Also given each perceived frame and its result (the live view); they must not raise."""

    def pose_reaches(self, t_s: float) -> bool:
        """The pose buffer holds a pose stamped at ``t_s`` or later (to the vehicle clock's resolution)."""
        latest = self.telemetry.poses.latest_t_s
        return latest is not None and latest >= t_s - CLOCK_RESOLUTION_S

    async def wait_for_pose(self, t_s: float, timeout_s: float, what: str) -> None:
        """Until a pose stamped at ``t_s`` or later has arrived; VehicleError after ``timeout_s`` wall seconds."""
        await self.telemetry.wait_for(functools.partial(self.pose_reaches, t_s), time.monotonic() + timeout_s, what)

    async def pose_for(self, frame: Frame) -> tuple[float, Pose] | None:
        """The pose at the frame's capture time and the vehicle time it is stamped with; None drops the frame
        (counted)."""
        t_s = frame.t_capture_s
        try:
            await self.wait_for_pose(t_s, self.max_frame_age_s, "telemetry at the frame's capture time")
        except VehicleError:
            self.outcome.frames_dropped_no_pose += 1
            return None
        latest = self.telemetry.poses.latest_t_s
        assert latest is not None
        if latest - t_s > self.max_frame_age_s:
            self.outcome.frames_dropped_old += 1
            return None
        t_s = min(t_s, latest)  # within the vehicle clock's resolution of the newest sample
        pose = self.telemetry.poses.pose_at(t_s)
        if pose is None:
            self.outcome.frames_dropped_no_pose += 1
            return None
        return t_s, pose

    async def perceive(
        self, frame: Frame, pose: Pose, area_centre_ne_m: tuple[float, float] | None
    ) -> FrameResult | None:
        """The pipeline's result for the frame taken at ``pose``, recorded; None when perception failed on it (one bad
        frame or pose, counted and recorded: a lasting failure meets the perception-silence failsafe)."""
        loop = asyncio.get_running_loop()
        try:
            result: FrameResult = await loop.run_in_executor(
                self._executor, self.pipeline.process, frame.image_bgr, pose, frame.t_capture_s, area_centre_ne_m
            )
        except (PerceptionError, GeometryError) as exc:
            self.outcome.frames_failed += 1
            self.recorder.write(RecordKind.FRAME_ERROR, frame.t_capture_s, seq=frame.seq, error=str(exc))
            return None
        self.outcome.frames_processed += 1
        self.last_result = result
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
        for viewer in self.viewers:
            viewer(frame, result)
        return result

    def close(self) -> None:
        """Wait for the frame in the pipeline, if any, and stop the executor."""
        self._executor.shutdown(wait=True)
