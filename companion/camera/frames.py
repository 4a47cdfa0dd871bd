"""Frames and frame sources.

A frame carries its sequence number and its capture time on the vehicle's clock (the clock of MAVLink's
``time_boot_ms``), so the companion pairs it with the pose at that instant. Sources are async generators with
``try/finally`` cleanup and a deadline on every wait.

``sitl://HOST:PORT`` is the bundled SITL's camera stream (TCP, loopback): each message is
``b"SLZF" | u32 header length | JSON header | u32 payload length | payload``, the header
``{"seq", "t_capture_s", "width", "height", "encoding": "bgr8"}`` and the payload the raw image.
"""

from __future__ import annotations

import asyncio
import enum
import json
import math
import struct
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from companion.errors import SlzError

MAGIC = b"SLZF"
U8Image = npt.NDArray[np.uint8]


MAX_HEADER_BYTES = 4096
MAX_PAYLOAD_BYTES = 64 << 20  # 64 MiB: a 4096 x 4096 BGR frame is 48 MiB


class CameraFault(str, enum.Enum):
    """Why a frame source stopped (the flight log names it)."""

    CONNECT_FAILED = "connect_failed"
    """The source could not be opened."""
    CONNECTION_LOST = "connection_lost"
    """The stream ended or was cut (the camera closed it, or refused us as a second client)."""
    SILENT = "silent"
    """No frame within the deadline."""
    BAD_FRAME = "bad_frame"
    """The stream carried something that is not a frame."""
    DEVICE = "device"
    """A device (OpenCV) source failed."""


class CameraError(SlzError):
    """A frame source failed (what, which source, and the kind of fault)."""

    def __init__(self, source: str, what: str, fault: CameraFault = CameraFault.DEVICE) -> None:
        super().__init__(f"{source}: {what}")
        self.source = source
        self.fault = fault


@dataclass(frozen=True)
class Frame:
    """One camera frame: ``image_bgr`` (H, W, 3) uint8, captured at ``t_capture_s`` on the vehicle's clock, and
    ``arrival_wall_s`` (``time.monotonic()``) when the companion had all of it (latency measurements only)."""

    seq: int
    t_capture_s: float
    image_bgr: U8Image
    arrival_wall_s: float = math.nan


class FrameSource(Protocol):
    """Anything that yields frames."""

    async def open(self) -> None:
        """Open the device or connection now (raises :class:`CameraError`), so a missing camera fails the start
        instead of the flight; :meth:`frames` opens it itself when this was not called."""
        ...

    def frames(self) -> AsyncIterator[Frame]:
        """Frames in capture order until the source ends."""
        ...


def encode_frame(seq: int, t_capture_s: float, image_bgr: U8Image) -> bytes:
    """The SITL stream's wire form of a frame."""
    h, w = image_bgr.shape[:2]
    header = json.dumps({"seq": seq, "t_capture_s": t_capture_s, "width": w, "height": h, "encoding": "bgr8"}).encode()
    payload = np.ascontiguousarray(image_bgr, dtype=np.uint8).tobytes()
    return MAGIC + struct.pack("<I", len(header)) + header + struct.pack("<I", len(payload)) + payload


class SitlFrameSource:
    """Frames from the SITL's camera stream (``sitl://127.0.0.1:5600``).

    Parameters
    ----------
    host, port : str, int
        Where the SITL serves frames.
    timeout_s : float
        Longest wait for the connection and for each frame; a silent camera raises :class:`CameraError`.
    """

    def __init__(self, host: str, port: int, timeout_s: float = 10.0) -> None:
        self.host, self.port, self.timeout_s = host, port, timeout_s
        self.name = f"sitl://{host}:{port}"
        self._connection: tuple[asyncio.StreamReader, asyncio.StreamWriter] | None = None

    async def open(self) -> None:
        """Connect to the SITL's frame stream."""
        if self._connection is not None:
            return
        try:
            self._connection = await asyncio.wait_for(asyncio.open_connection(self.host, self.port), self.timeout_s)
        except (OSError, asyncio.TimeoutError) as exc:
            raise CameraError(self.name, f"cannot connect: {exc or 'timed out'}", CameraFault.CONNECT_FAILED) from None

    async def frames(self) -> AsyncIterator[Frame]:
        """Connect (unless :meth:`open` did), then yield frames until the stream ends.

        Raises
        ------
        CameraError
            The stream ended or was cut (``CONNECTION_LOST``: the SITL closes it at its end, or refuses a second
            client), stayed silent past ``timeout_s`` (``SILENT``), or carried something else (``BAD_FRAME``).
        """
        await self.open()
        assert self._connection is not None
        reader, writer = self._connection
        self._connection = None  # one stream per connection
        try:
            while True:
                try:
                    magic = await asyncio.wait_for(reader.readexactly(4), self.timeout_s)
                    frame = await asyncio.wait_for(self._rest_of_frame(reader, magic), self.timeout_s)
                except asyncio.IncompleteReadError as exc:
                    where = "mid-frame" if exc.partial else "at a frame boundary"
                    what = f"the camera closed the connection ({where})"
                    raise CameraError(self.name, what, CameraFault.CONNECTION_LOST) from None
                except ConnectionError as exc:
                    raise CameraError(self.name, f"connection lost: {exc}", CameraFault.CONNECTION_LOST) from None
                except asyncio.TimeoutError:
                    raise CameraError(self.name, f"no frame for {self.timeout_s} s", CameraFault.SILENT) from None
                yield frame
        finally:
            writer.close()

    async def _rest_of_frame(self, reader: asyncio.StreamReader, magic: bytes) -> Frame:
        if magic != MAGIC:
            raise CameraError(self.name, f"bad frame marker {magic!r}", CameraFault.BAD_FRAME)
        (header_len,) = struct.unpack("<I", await reader.readexactly(4))
        if header_len > MAX_HEADER_BYTES:
            raise CameraError(self.name, f"frame header of {header_len} bytes", CameraFault.BAD_FRAME)
        try:
            header = json.loads(await reader.readexactly(header_len))
            h, w = int(header["height"]), int(header["width"])
            seq, t_capture_s = int(header["seq"]), float(header["t_capture_s"])
        except (ValueError, KeyError, TypeError, OverflowError):
            raise CameraError(self.name, "unreadable frame header", CameraFault.BAD_FRAME) from None
        (payload_len,) = struct.unpack("<I", await reader.readexactly(4))
        if payload_len > MAX_PAYLOAD_BYTES:
            raise CameraError(self.name, f"frame payload of {payload_len} bytes", CameraFault.BAD_FRAME)
        payload = await reader.readexactly(payload_len)
        if header.get("encoding") != "bgr8" or payload_len != h * w * 3 or not math.isfinite(t_capture_s):
            raise CameraError(
                self.name, f"unsupported frame {str(header)[:120]} with {payload_len} bytes", CameraFault.BAD_FRAME
            )
        image = np.frombuffer(payload, dtype=np.uint8).reshape(h, w, 3)
        return Frame(seq, t_capture_s, image, time.monotonic())
