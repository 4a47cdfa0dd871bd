"""A frame source from its URL: the SITL's stream or anything OpenCV opens (V4L2, RTSP, UDP, a file).

The one place that knows every source; the sources import :mod:`companion.camera.frames` (the frame, the interface,
the error), never this module.
"""

from __future__ import annotations

from collections.abc import Callable
from urllib.parse import urlparse

from companion.camera.frames import CameraError, FrameSource, SitlFrameSource


def open_frame_source(
    url: str, timeout_s: float = 10.0, vehicle_time_s: Callable[[], float] | None = None, latency_s: float = 0.0
) -> FrameSource:
    """A frame source from its URL.

    ``sitl://HOST:PORT`` (frames carry their own capture times); ``v4l2:///dev/videoN``, ``rtsp://``, ``udp://``,
    ``file:///path`` or a plain path go through OpenCV and need ``vehicle_time_s`` to stamp frames.
    """
    parsed = urlparse(url)
    if parsed.scheme == "sitl":
        if not parsed.hostname or not parsed.port:
            raise CameraError(url, "expected sitl://HOST:PORT")
        return SitlFrameSource(parsed.hostname, parsed.port, timeout_s)
    if parsed.scheme in ("v4l2", "rtsp", "rtsps", "udp", "http", "https", "file", ""):
        if vehicle_time_s is None:
            raise CameraError(url, "this source needs the vehicle clock to stamp its frames")
        from companion.camera.opencv_source import OpenCvFrameSource  # OpenCV loads only for these sources

        return OpenCvFrameSource(url, vehicle_time_s, latency_s, timeout_s)
    raise CameraError(
        url, f"unsupported frame source scheme {parsed.scheme!r} (supported: sitl, v4l2, rtsp, udp, file)"
    )
