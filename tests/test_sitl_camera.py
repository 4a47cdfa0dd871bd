"""The SITL camera stream: frames with sequence numbers and simulated capture times, lockstep, seeded determinism."""

from __future__ import annotations

import asyncio
import functools
import hashlib
import itertools
import math
from collections.abc import AsyncGenerator, Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.camera.frames import CameraError, SitlFrameSource
from companion.camera.sources import open_frame_source
from sitl.harness.process import SitlProcess
from sitl.testing.helpers import LockstepClient, state_when

pytestmark = pytest.mark.sitl

SMALL_CAMERA = "sitl:\n  camera:\n    enabled: true\n    width_px: 320\n    height_px: 240\n  seed: {seed}\n{extra}"


def start(tmp_path: Path, instance: int, seed: int, args: list[str], extra: str = "") -> SitlProcess:
    config = tmp_path / f"camera-{instance}.yaml"
    config.write_text(SMALL_CAMERA.format(seed=seed, extra=extra))
    return SitlProcess(["--config", str(config), *args], instance, tmp_path).start()


async def lockstep_frames(
    instance: int, count: int, take_off: bool = False, before_last_ack: Callable[[], Any] | None = None
) -> list[tuple[int, float, str]]:
    """Receive ``count`` frames in lockstep, acknowledging each tick; (seq, capture time, image hash) of each.

    With ``take_off``, the client arms and takes off at the first ticks, so the camera rises over the crowd.
    ``before_last_ack`` runs (in a thread) while the simulator waits at the last tick: its time stands still there.
    """
    client = LockstepClient(instance)
    out = []
    frames = SitlFrameSource("127.0.0.1", 5600 + instance, timeout_s=10).frames()
    try:
        client.subscribe()
        for k in range(count):
            frame = await frames.__anext__()
            tick = await asyncio.to_thread(client.next_tick)
            assert frame.seq == k == tick["seq"]
            assert frame.t_capture_s == pytest.approx(tick["t_s"], abs=1e-9)
            assert frame.image_bgr.shape == (240, 320, 3)
            out.append((frame.seq, frame.t_capture_s, hashlib.sha1(frame.image_bgr.tobytes()).hexdigest()))
            if take_off and k in (1, 2):
                peer, sysid = client.peer, client.peer.vehicle_sysid
                command = mavlink.MAV_CMD_COMPONENT_ARM_DISARM if k == 1 else mavlink.MAV_CMD_NAV_TAKEOFF
                params = [1.0, 0, 0, 0, 0, 0, 0] if k == 1 else [0, 0, 0, math.nan, math.nan, math.nan, math.nan]
                peer.send(peer.mav.command_long_encode(sysid, 1, command, 0, *params))
            if k == count - 1 and before_last_ack is not None:
                await asyncio.to_thread(before_last_ack)
            client.ack(k)
    finally:
        await frames.aclose()  # type: ignore[attr-defined]
        client.close()
    return out


def _ask_people(sitl: SitlProcess, into: dict[str, Any]) -> None:
    into.update(sitl.request({"cmd": "people"}))


async def test_lockstep_frames_are_seeded_and_timed_on_the_vehicle_clock(
    tmp_path: Path, instances: Callable[[], int]
) -> None:
    runs: list[Any] = []
    for instance in (instances(), instances()):
        sitl = start(
            tmp_path,
            instance,
            seed=5,
            args=["--lockstep", "--speed", "0"],
            extra="  scenario:\n    moving_fraction: 0.2\n",
        )
        try:
            # The people are asked for at the last tick, where the simulator waits for the ack: after it, the
            # simulator moves on to the next tick and may draw one more frame (walks one step further) before it
            # sees that the frame client left, sooner or later with the machine's load.
            people: dict[str, Any] = {}
            ask = functools.partial(_ask_people, sitl, people)
            frames = await lockstep_frames(instance, 30, take_off=True, before_last_ack=ask)
            assert people["t_s"] == pytest.approx(2.9, abs=1e-9)
            runs.append((frames, people["positions_ne_m"]))
        finally:
            sitl.stop()
    (frames_a, people_a), (frames_b, people_b) = runs
    assert [t for _, t, _ in frames_a] == pytest.approx([0.1 * k for k in range(30)])
    assert frames_a == frames_b  # bit-identical frames from the same seed
    assert people_a == people_b  # and the same walks
    assert len({h for _, _, h in frames_a}) > 20  # the camera rises over walking people: frames differ


async def test_free_running_frames_and_a_client_that_leaves(tmp_path: Path, instance: int) -> None:
    sitl = start(tmp_path, instance, seed=1, args=["--speed", "1"])
    try:

        async def read(n: int) -> list[float]:
            source = open_frame_source(f"sitl://127.0.0.1:{5600 + instance}")
            times = []
            frames = source.frames()
            assert isinstance(frames, AsyncGenerator)  # a stream that closes when asked (its finally runs)
            try:
                async for frame in frames:
                    times.append(frame.t_capture_s)
                    if len(times) == n:
                        break
            finally:
                await frames.aclose()  # the client leaves now, not when the loop ends
            return times

        times = await read(8)
        gaps = [b - a for a, b in itertools.pairwise(times)]
        assert gaps == pytest.approx([0.1] * 7, abs=1e-9)  # 10 Hz of simulated time
        # The client has gone: the SITL goes on (and counts the frames nobody took).
        t0 = sitl.state()["t_s"]
        # Waited for in a thread: the event loop runs meanwhile and closes the client's socket.
        went_on = functools.partial(state_when, sitl, lambda s: s["t_s"] > t0 + 1.0, 5, "time to go on")
        later = await asyncio.get_running_loop().run_in_executor(None, went_on)
        assert later["frames"]["dropped"] >= 5
    finally:
        sitl.stop()


async def test_in_lockstep_a_frame_client_that_leaves_stops_the_sitl_loudly(tmp_path: Path, instance: int) -> None:
    sitl = start(tmp_path, instance, seed=1, args=["--lockstep", "--speed", "0"], extra="  lockstep_timeout_s: 2.0\n")
    await lockstep_frames(instance, 3)  # then the client disconnects without acknowledging more
    assert sitl.wait(timeout_s=15) == 3
    assert "frame client" in sitl.log_tail() or "no acknowledgement" in sitl.log_tail()
    sitl.stop()


async def test_frame_source_errors() -> None:
    with pytest.raises(CameraError, match="unsupported frame source scheme 'gopher'"):
        open_frame_source("gopher://camera/stream")
    with pytest.raises(CameraError, match="needs the vehicle clock"):
        open_frame_source("rtsp://camera/stream")

    with pytest.raises(CameraError, match="cannot connect"):
        await SitlFrameSource("127.0.0.1", 5699, timeout_s=1).frames().__anext__()
