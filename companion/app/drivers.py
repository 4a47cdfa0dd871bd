"""The two ways a flight is driven: by a simulator's lockstep ticks, or by the wall clock (a real vehicle, a SITL
running free). Both hand frames to :meth:`FlightLoop.on_frame` and vehicle states to :meth:`FlightLoop.on_tick`; the
supervision (takeover, touchdown, perception silence, lost link and camera, the stall watchdog) is the flight's.

A driver sees the flight through :class:`FlightLoop` alone (``companion.app.flight.FlightApp`` is one), so this module
imports nothing of the app that runs it.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from typing import Protocol

from companion.camera.frames import CameraError, Frame
from companion.guidance.vehicle_state import VehicleState
from companion.vehicle.link import VehicleError
from companion.vehicle.lockstep import LockstepClient
from companion.vehicle.sim_control import SetpointNedYaw, Tick

TICK_PERIOD_S = 0.1  # free running: how often the supervision looks at the vehicle (wall time)


class FlightLoop(Protocol):
    """What a driver needs of the flight it drives: its frames and vehicle states go in, its failsafes come out."""

    done: asyncio.Event
    """Set when the flight is over (the driver stops)."""

    @property
    def link_lost_after_s(self) -> float:
        """Telemetry silence (s) after which the link counts as lost."""
        ...

    @property
    def camera_is_lost(self) -> bool:
        """The camera has failed in this flight (no more frames will come)."""
        ...

    @property
    def wants_frames(self) -> bool:
        """Frames are looked at now: from the flight's start until the landing is the autopilot's (before the start
        a flight drops them, in LAND and after it no decision reads one), so a simulator in lockstep need not draw
        them. A camera that runs free sends them all the same, and the flight processes and logs them."""
        ...

    def frames(self) -> AsyncIterator[Frame]:
        """The camera's frames (an async generator: the driver closes it)."""
        ...

    def frame_missing(self) -> None:
        """Count a frame the simulator announced that never came."""
        ...

    def camera_lost(self, exc: CameraError) -> None:
        """The camera failed: record it (the perception-silence failsafe acts)."""
        ...

    def link_lost(self, silent_s: float) -> None:
        """No telemetry for ``silent_s`` seconds: stop commanding and end the flight."""
        ...

    async def wait_for_pose(self, t_s: float, timeout_s: float) -> None:
        """Until a pose stamped at vehicle time ``t_s`` (or later) has arrived; VehicleError after ``timeout_s``
        seconds of wall time."""
        ...

    def telemetry_age_s(self) -> float | None:
        """Wall seconds since the last telemetry arrived (None before the first)."""
        ...

    def vehicle_state(self) -> VehicleState | None:
        """The vehicle at its newest pose (None before the first)."""
        ...

    async def on_frame(self, frame: Frame) -> None:
        """Perceive and decide on one frame."""
        ...

    async def on_tick(self, state: VehicleState) -> None:
        """Supervise at one vehicle state (start sequence, takeover, touchdown, silence)."""
        ...

    def take_tick_setpoint(self) -> SetpointNedYaw | None:
        """The position setpoint sent since the last call, to acknowledge a lockstep tick with; cleared by the call."""
        ...


class LockstepDriver:
    """One tick at a time with a simulator in lockstep: the same seed gives the same flight at any speed."""

    def __init__(self, app: FlightLoop, lockstep: LockstepClient) -> None:
        self.app = app
        self.lockstep = lockstep
        self._early_frame: Frame | None = None

    async def _read_frames(self, queue: asyncio.Queue[Frame | None]) -> None:
        """Frames into ``queue`` (None once the camera is gone)."""
        app = self.app
        frames = app.frames()
        try:
            async for frame in frames:
                queue.put_nowait(frame)
        except CameraError as exc:
            app.camera_lost(exc)
        finally:
            queue.put_nowait(None)
            await frames.aclose()  # type: ignore[attr-defined]

    async def _frame_of(self, tick: Tick, queue: asyncio.Queue[Frame | None]) -> Frame | None:
        """The frame the simulator sent before ``tick`` (None, counted, if it never comes)."""
        app = self.app
        assert tick.frame_seq is not None
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.lockstep.tick_timeout_s
        while True:
            frame, self._early_frame = self._early_frame, None
            if frame is None:
                try:
                    frame = await asyncio.wait_for(queue.get(), max(0.0, deadline - loop.time()))
                except asyncio.TimeoutError:
                    frame = None
                if frame is None:  # the camera is gone (or silent past the deadline)
                    if not app.camera_is_lost:
                        queue.put_nowait(None)
                    app.frame_missing()
                    return None
            if frame.seq == tick.frame_seq:
                return frame
            if frame.seq > tick.frame_seq:  # ours never came
                self._early_frame = frame
                app.frame_missing()
                return None

    async def run(self) -> None:
        """Tick by tick until the flight is done: the tick's pose, its frame, the decisions, the acknowledgement.

        The camera stream is read from the first tick whose acknowledgement asks for frames (the flight's start; the
        lockstep was opened without them), or from the first frame that comes anyway: before that nothing waits on
        it, so a camera that has nothing to send is not a silent one."""
        app = self.app
        queue: asyncio.Queue[Frame | None] = asyncio.Queue()
        reader: asyncio.Task[None] | None = None
        link_lost_after_s = app.link_lost_after_s

        def read_frames() -> asyncio.Task[None]:
            return reader or asyncio.create_task(self._read_frames(queue), name="frames")

        try:
            while not app.done.is_set():
                tick = await self.lockstep.next_tick()
                try:
                    await app.wait_for_pose(tick.t_s, link_lost_after_s)
                except VehicleError:
                    app.link_lost(link_lost_after_s)
                    return
                if tick.frame_seq is not None and not app.camera_is_lost:
                    reader = read_frames()
                    frame = await self._frame_of(tick, queue)
                    if frame is not None:
                        await app.on_frame(frame)
                state = app.vehicle_state()
                if state is not None and not app.done.is_set():
                    await app.on_tick(state)
                frames = app.wants_frames
                if frames:
                    reader = read_frames()
                self.lockstep.ack(tick, app.take_tick_setpoint(), frames)
        finally:
            if reader is not None:
                reader.cancel()
                await asyncio.gather(reader, return_exceptions=True)


class FreeRunningDriver:
    """Frames as they arrive and ticks on the wall clock (a real vehicle, or a SITL that runs free)."""

    def __init__(self, app: FlightLoop) -> None:
        self.app = app

    async def frames(self) -> None:
        """Every frame as it comes, until the flight is done or the camera is gone."""
        app = self.app
        frames = app.frames()
        try:
            async for frame in frames:
                if app.done.is_set():
                    break
                await app.on_frame(frame)
        except CameraError as exc:
            app.camera_lost(exc)
        finally:
            await frames.aclose()  # type: ignore[attr-defined]
        await app.done.wait()  # no more frames: the silence failsafe decides from here

    async def ticks(self) -> None:
        """A decision tick every TICK_PERIOD_S of wall time, and the lost-link check."""
        app = self.app
        link_lost_after_s = app.link_lost_after_s
        while not app.done.is_set():
            silent_s = app.telemetry_age_s()
            if silent_s is not None and silent_s > link_lost_after_s:
                app.link_lost(silent_s)
                return
            state = app.vehicle_state()
            if state is not None:
                await app.on_tick(state)
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(app.done.wait(), TICK_PERIOD_S)
