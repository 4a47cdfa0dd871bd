"""The companion's SITL frame source against a hand-made stream: each way a stream can fail is a named camera fault."""

from __future__ import annotations

import asyncio
import struct

import numpy as np
import pytest

from companion.camera.frames import CameraError, CameraFault, Frame, SitlFrameSource, encode_frame

pytestmark = pytest.mark.unit

IMAGE = np.zeros((4, 6, 3), np.uint8)


async def frames_then_fault(
    stream: bytes, close: bool = True, timeout_s: float = 2.0
) -> tuple[list[Frame], CameraError]:
    """Serve ``stream`` on a loopback port (then close, or stay silent); the frames read and the error raised."""
    read_done = asyncio.Event()

    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        writer.write(stream)
        await writer.drain()
        if not close:
            await read_done.wait()  # a camera that stops sending but keeps the connection until the reader gives up
        writer.close()

    server = await asyncio.start_server(serve, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    source = SitlFrameSource("127.0.0.1", port, timeout_s=timeout_s)
    got: list[Frame] = []

    async def read() -> None:
        async for frame in source.frames():
            got.append(frame)

    try:
        with pytest.raises(CameraError) as raised:
            await read()
    finally:
        read_done.set()
        server.close()
    return got, raised.value


async def test_a_stream_the_camera_closes_is_a_lost_connection_after_its_whole_frames() -> None:
    frames, error = await frames_then_fault(encode_frame(0, 0.1, IMAGE) + encode_frame(1, 0.2, IMAGE))
    assert [f.seq for f in frames] == [0, 1]
    assert error.fault is CameraFault.CONNECTION_LOST
    assert "closed the connection" in str(error)


async def test_a_stream_cut_mid_frame_is_a_lost_connection() -> None:
    whole = encode_frame(0, 0.1, IMAGE)
    frames, error = await frames_then_fault(whole + encode_frame(1, 0.2, IMAGE)[:30])
    assert [f.seq for f in frames] == [0]
    assert error.fault is CameraFault.CONNECTION_LOST


async def test_a_silent_camera_is_named_silent() -> None:
    frames, error = await frames_then_fault(encode_frame(0, 0.1, IMAGE), close=False, timeout_s=0.3)
    assert len(frames) == 1
    assert error.fault is CameraFault.SILENT


@pytest.mark.parametrize(
    "stream",
    [
        b"JUNK" + b"\x00" * 20,
        b"SLZF" + struct.pack("<I", 1 << 30),  # a header length no frame has
        b"SLZF" + struct.pack("<I", 2) + b"{]" + struct.pack("<I", 0),
        b"SLZF" + struct.pack("<I", 2) + b"{}" + struct.pack("<I", 0),  # no fields
        encode_frame(0, float("nan"), IMAGE),
        encode_frame(0, 0.1, IMAGE)[: -4 - IMAGE.size] + struct.pack("<I", 0xFFFFFFFF),  # a 4 GiB payload announced
    ],
)
async def test_a_stream_that_is_not_frames_is_a_bad_frame(stream: bytes) -> None:
    frames, error = await frames_then_fault(stream)
    assert frames == []
    assert error.fault is CameraFault.BAD_FRAME
