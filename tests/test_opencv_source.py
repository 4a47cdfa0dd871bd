"""OpenCV frame sources: a video file plays back with capture times on the vehicle clock; bad URLs are named."""

from __future__ import annotations

import asyncio
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.camera.frames import CameraError, Frame
from companion.camera.sources import open_frame_source

pytestmark = pytest.mark.unit


def _write_video(path: Path, frames: int, fps: float) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (64, 48))
    assert writer.isOpened()
    for k in range(frames):
        image = np.full((48, 64, 3), 10 * k, np.uint8)
        writer.write(image)
    writer.release()


async def test_a_video_file_yields_every_frame_stamped_on_the_vehicle_clock(tmp_path: Path) -> None:
    video = tmp_path / "flight.avi"
    _write_video(video, 12, fps=10.0)
    source = open_frame_source(f"file://{video}", timeout_s=5.0, vehicle_time_s=lambda: 500.0)

    async def read_all() -> list[Frame]:
        return [f async for f in source.frames()]

    frames = await asyncio.wait_for(read_all(), 30.0)
    assert [f.seq for f in frames] == list(range(12))
    assert frames[0].image_bgr.shape == (48, 64, 3)
    gaps = np.diff([f.t_capture_s for f in frames])
    assert np.allclose(gaps, 0.1, atol=1e-6)  # the file's own timing
    assert frames[0].t_capture_s == pytest.approx(500.0)  # playback started at vehicle time 500 s
    assert frames[-1].t_capture_s == pytest.approx(501.1)
    assert int(frames[5].image_bgr.mean()) == pytest.approx(50, abs=3)


def test_missing_files_and_unknown_schemes_are_named(tmp_path: Path) -> None:
    with pytest.raises(CameraError, match="video file not found"):
        open_frame_source(str(tmp_path / "nope.mp4"), vehicle_time_s=lambda: 0.0)
    with pytest.raises(CameraError, match="unsupported frame source scheme 'ftp'"):
        open_frame_source("ftp://x/y", vehicle_time_s=lambda: 0.0)


async def test_a_missing_device_fails_when_opened() -> None:
    source = open_frame_source("v4l2:///dev/video_does_not_exist", timeout_s=5.0, vehicle_time_s=lambda: 0.0)

    async def first() -> Frame:
        return await source.frames().__anext__()

    with pytest.raises(CameraError, match="cannot open"):
        await asyncio.wait_for(first(), 30.0)
