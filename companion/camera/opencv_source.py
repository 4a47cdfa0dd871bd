"""Frame sources through OpenCV: V4L2 devices, RTSP/UDP streams and video files.

Each frame gets a capture time on the vehicle's clock: for live sources, the vehicle time at arrival less the
configured latency; for files, the vehicle time when playback started plus the frame's position in the file (so a
file replays at its own timing whatever the machine's speed). Reads block, so they run in a worker thread
(OpenCV releases the GIL); the event loop never waits on a camera.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from urllib.parse import urlparse

import cv2
import numpy as np

from companion.camera.frames import CameraError, CameraFault, Frame

logger = logging.getLogger(__name__)


class OpenCvFrameSource:
    """Frames from ``cv2.VideoCapture``.

    Parameters
    ----------
    url : str
        ``v4l2:///dev/video0``, ``rtsp://...``, ``udp://...``, ``file:///path/video.mp4`` or a plain file path.
    vehicle_time_s : callable
        Returns the current vehicle time (s), e.g. :meth:`companion.vehicle.clock.VehicleClock.now_s`.
    latency_s : float
        Exposure-to-arrival latency of live sources, subtracted from the arrival time.
    timeout_s : float
        Longest wait for a frame; a silent camera raises :class:`CameraError`.
    """

    def __init__(
        self, url: str, vehicle_time_s: Callable[[], float], latency_s: float = 0.0, timeout_s: float = 5.0
    ) -> None:
        self.url, self.vehicle_time_s, self.latency_s, self.timeout_s = url, vehicle_time_s, latency_s, timeout_s
        parsed = urlparse(url)
        self.is_file = parsed.scheme in ("", "file")
        if parsed.scheme == "v4l2":
            self._target: str | int = parsed.path
            self._backend = cv2.CAP_V4L2
        elif self.is_file:
            path = Path(parsed.path if parsed.scheme == "file" else url)
            if not path.is_file():
                raise CameraError(url, f"video file not found: {path}")
            self._target, self._backend = str(path), cv2.CAP_ANY
        elif parsed.scheme in ("rtsp", "rtsps", "udp", "http", "https"):
            self._target, self._backend = url, cv2.CAP_FFMPEG
        else:
            raise CameraError(url, f"unsupported scheme {parsed.scheme!r}")
        self._capture: cv2.VideoCapture | None = None

    async def open(self) -> None:
        """Open the device, stream or file."""
        if self._capture is not None:
            return

        def open_capture() -> cv2.VideoCapture:
            return cv2.VideoCapture(self._target, self._backend)

        try:
            capture = await asyncio.wait_for(asyncio.to_thread(open_capture), self.timeout_s)
        except asyncio.TimeoutError:
            raise CameraError(
                self.url, f"cannot open within {self.timeout_s:g} s", CameraFault.CONNECT_FAILED
            ) from None
        if not capture.isOpened():
            capture.release()
            raise CameraError(self.url, "cannot open", CameraFault.CONNECT_FAILED)
        self._capture = capture

    async def frames(self) -> AsyncIterator[Frame]:
        """Open the source (unless :meth:`open` did) and yield frames until it ends (files) or fails."""
        await self.open()
        capture, self._capture = self._capture, None
        assert capture is not None
        try:
            start_s = self.vehicle_time_s()
            seq = 0
            while True:
                try:
                    ok, image = await asyncio.wait_for(asyncio.to_thread(capture.read), self.timeout_s)
                except asyncio.TimeoutError:
                    raise CameraError(self.url, f"no frame for {self.timeout_s} s", CameraFault.SILENT) from None
                if not ok or image is None:
                    if self.is_file:
                        return
                    raise CameraError(self.url, "the stream ended or the device was lost", CameraFault.CONNECTION_LOST)
                if self.is_file:
                    t_s = start_s + float(capture.get(cv2.CAP_PROP_POS_MSEC)) / 1000.0
                else:
                    t_s = self.vehicle_time_s() - self.latency_s
                if image.ndim == 2:
                    image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
                yield Frame(seq, t_s, np.ascontiguousarray(image, dtype=np.uint8), time.monotonic())
                seq += 1
        finally:
            capture.release()
