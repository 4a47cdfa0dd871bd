"""The two ways a flight is driven: by a simulator's lockstep ticks, or by the wall clock (a real vehicle, a SITL
running free). Both hand frames to :meth:`FlightApp.on_frame` and vehicle states to :meth:`FlightApp.on_tick`; the
supervision (takeover, touchdown, perception silence, lost link and camera, the stall watchdog) is the app's.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import time
from typing import TYPE_CHECKING

from companion.camera.frames import CameraError, Frame
from companion.vehicle.link import VehicleError
from companion.vehicle.lockstep import LockstepClient
from companion.vehicle.sim_control import Tick

if TYPE_CHECKING:
    from companion.app.flight import FlightApp

TICK_PERIOD_S = 0.1  # free running: how often the supervision looks at the vehicle (wall time)


class LockstepDriver:
    """One tick at a time with a simulator in lockstep: the same seed gives the same flight at any speed."""

    def __init__(self, app: FlightApp, lockstep: LockstepClient) -> None:
        self.app = app
        self.lockstep = lockstep
        self._early_frame: Frame | None = None

    async def _read_frames(self, queue: asyncio.Queue[Frame | None]) -> None:
        """Frames into ``queue`` (None once the camera is gone)."""
        app = self.app
        frames = app.source.frames()
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
                    if not app.outcome.camera_lost:
                        queue.put_nowait(None)
                    app.outcome.frames_missing += 1
                    return None
            if frame.seq == tick.frame_seq:
                return frame
            if frame.seq > tick.frame_seq:  # ours never came
                self._early_frame = frame
                app.outcome.frames_missing += 1
                return None

    async def run(self) -> None:
        """Tick by tick until the flight is done: the tick's pose, its frame, the decisions, the acknowledgement."""
        app = self.app
        queue: asyncio.Queue[Frame | None] = asyncio.Queue()
        reader = asyncio.create_task(self._read_frames(queue), name="frames")
        link_lost_after_s = app.config.vehicle.link_lost_after_s
        try:
            while not app.done.is_set():
                tick = await self.lockstep.next_tick()
                try:
                    await app.link.wait_for(
                        functools.partial(app.pose_reaches, tick.t_s),
                        time.monotonic() + link_lost_after_s,
                        "the tick's pose",
                    )
                except VehicleError:
                    app.link_lost(link_lost_after_s)
                    return
                if tick.frame_seq is not None and not app.outcome.camera_lost:
                    frame = await self._frame_of(tick, queue)
                    if frame is not None:
                        await app.on_frame(frame)
                state = app.vehicle_state()
                if state is not None and not app.done.is_set():
                    await app.on_tick(state)
                self.lockstep.ack(tick, app.tick_setpoint)
                app.tick_setpoint = None
        finally:
            reader.cancel()
            await asyncio.gather(reader, return_exceptions=True)


class FreeRunningDriver:
    """Frames as they arrive and ticks on the wall clock (a real vehicle, or a SITL that runs free)."""

    def __init__(self, app: FlightApp) -> None:
        self.app = app

    async def frames(self) -> None:
        """Every frame as it comes, until the flight is done or the camera is gone."""
        app = self.app
        frames = app.source.frames()
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
        link_lost_after_s = app.config.vehicle.link_lost_after_s
        while not app.done.is_set():
            last_telemetry = app.link.status.last_telemetry_wall_s
            if last_telemetry is not None and time.monotonic() - last_telemetry > link_lost_after_s:
                app.link_lost(time.monotonic() - last_telemetry)
                return
            state = app.vehicle_state()
            if state is not None:
                await app.on_tick(state)
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(app.done.wait(), TICK_PERIOD_S)
