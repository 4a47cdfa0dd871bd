"""MAVLink 2 frames for the few messages the companion's command channel speaks, with MAVLink 2 message signing.

The drone's install has no pymavlink (it is the SITL's and the tests' dependency), and MAVSDK, which owns the vehicle
link, cannot check a signature. The channel needs four messages (``HEARTBEAT``, ``COMMAND_LONG`` in, ``COMMAND_ACK``
and ``STATUSTEXT`` out), so they are packed here, from the MAVLink ``common.xml`` definitions (field order on the
wire, ``CRC_EXTRA``); tests/test_ground_channel.py checks every one against pymavlink's in both directions.

A frame (MAVLink 2)::

    0xFD len incompat compat seq sysid compid msgid(3, LE) payload(len) crc(2, LE) [link_id timestamp(6) sig(6)]

``payload`` is the message's fields with trailing zero bytes cut (at least one byte kept); the receiver pads it back.
``crc`` is CRC-16/MCRF4XX (X.25) over everything after ``0xFD`` up to the payload's end, then the message's
``CRC_EXTRA``. A signed frame sets incompat flag 0x01 and ends with 13 bytes: the link id, a timestamp in 10 us units
since 2015-01-01 UTC, and the first 6 bytes of SHA-256(key + the frame up to its crc + link id + timestamp)
(MAVLink's message signing; https://mavlink.io/en/guide/message_signing.html).
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass
from typing import TypedDict

from companion.errors import SlzError

STX_V2 = 0xFD
HEADER_LEN = 10  # STX .. msgid
SIGNATURE_LEN = 13
INCOMPAT_SIGNED = 0x01
SIGNING_KEY_BYTES = 32
SIGNING_EPOCH_UNIX_S = 1420070400  # 2015-01-01T00:00:00Z
TIMESTAMP_UNITS_PER_S = 100_000  # 10 us


@dataclass(frozen=True)
class MessageSpec:
    """One message's id, wire layout (struct format of its fields in wire order) and CRC_EXTRA."""

    msg_id: int
    fields: tuple[str, ...]
    layout: str
    crc_extra: int

    @property
    def size(self) -> int:
        """Its full payload length in bytes."""
        return struct.calcsize(self.layout)


HEARTBEAT = MessageSpec(
    0, ("custom_mode", "type", "autopilot", "base_mode", "system_status", "mavlink_version"), "<IBBBBB", 50
)
COMMAND_LONG = MessageSpec(
    76,
    (
        *("param1", "param2", "param3", "param4", "param5", "param6", "param7"),
        *("command", "target_system", "target_component", "confirmation"),
    ),
    "<7fHBBB",
    152,
)
COMMAND_ACK = MessageSpec(
    77, ("command", "result", "progress", "result_param2", "target_system", "target_component"), "<HBBiBB", 143
)
STATUSTEXT = MessageSpec(253, ("severity", "text", "id", "chunk_seq"), "<B50sHB", 83)
MESSAGES = {spec.msg_id: spec for spec in (HEARTBEAT, COMMAND_LONG, COMMAND_ACK, STATUSTEXT)}


class FrameError(SlzError):
    """A datagram that is not a MAVLink 2 frame the channel can read (what is wrong with it)."""


def crc_x25(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/MCRF4XX, MAVLink's checksum, over ``data`` from ``crc``."""
    for byte in data:
        tmp = byte ^ (crc & 0xFF)
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


def signing_timestamp(unix_s: float) -> int:
    """MAVLink's signing timestamp (10 us units since 2015-01-01 UTC) of a wall time."""
    return int((unix_s - SIGNING_EPOCH_UNIX_S) * TIMESTAMP_UNITS_PER_S)


def signature(key: bytes, frame_to_crc: bytes, link_id: int, timestamp: int) -> bytes:
    """The 6 signature bytes of a frame (``frame_to_crc``: STX up to and including its crc)."""
    tail = bytes([link_id]) + timestamp.to_bytes(6, "little")
    return hashlib.sha256(key + frame_to_crc + tail).digest()[:6]


@dataclass(frozen=True)
class Frame:
    """One MAVLink 2 frame, read: who sent it, its message's fields, and its signature's parts (None: unsigned)."""

    seq: int
    sys_id: int
    comp_id: int
    msg_id: int
    fields: dict[str, int | float | bytes]
    link_id: int | None = None
    timestamp: int | None = None
    signature_ok: bool | None = None
    """None: unsigned, or signed and no key to check it with."""


class _RequiredHeader(TypedDict):
    seq: int
    sys_id: int
    comp_id: int


class FrameHeader(_RequiredHeader, total=False):
    """:func:`pack`'s header arguments: the sequence number and the sender, and for a signed frame its key, link id
    and timestamp."""

    key: bytes
    link_id: int
    timestamp: int


def pack(
    spec: MessageSpec,
    values: dict[str, int | float | bytes],
    seq: int,
    sys_id: int,
    comp_id: int,
    key: bytes | None = None,
    link_id: int = 0,
    timestamp: int = 0,
) -> bytes:
    """One frame of ``spec`` with ``values`` (a missing field is 0); signed with ``key`` when given."""
    payload = struct.pack(spec.layout, *(values.get(name, 0) for name in spec.fields))
    payload = payload.rstrip(b"\0") or b"\0"
    incompat = INCOMPAT_SIGNED if key is not None else 0
    header = struct.pack("<BBBBBBB", STX_V2, len(payload), incompat, 0, seq & 0xFF, sys_id, comp_id)
    header += spec.msg_id.to_bytes(3, "little")
    crc = crc_x25(bytes([spec.crc_extra]), crc_x25(header[1:] + payload))
    frame = header + payload + crc.to_bytes(2, "little")
    if key is None:
        return frame
    stamp = timestamp.to_bytes(6, "little")
    return frame + bytes([link_id]) + stamp + signature(key, frame, link_id, timestamp)


def unpack(datagram: bytes, key: bytes | None = None) -> Frame:
    """The frame in ``datagram`` (one frame per datagram, as MAVLink over UDP sends them); :class:`FrameError` for
    anything else: another protocol version, a short or long datagram, a bad crc, a message this module does not
    read. A signature is checked when ``key`` is given (``Frame.signature_ok``)."""
    if len(datagram) < HEADER_LEN + 2 or datagram[0] != STX_V2:
        raise FrameError("not a MAVLink 2 frame")
    length, incompat, _, seq, sys_id, comp_id = struct.unpack_from("<BBBBBB", datagram, 1)
    msg_id = int.from_bytes(datagram[7:10], "little")
    signed = bool(incompat & INCOMPAT_SIGNED)
    if incompat & ~INCOMPAT_SIGNED:
        raise FrameError(f"unknown incompatibility flags 0x{incompat:02x}")
    expected = HEADER_LEN + length + 2 + (SIGNATURE_LEN if signed else 0)
    if len(datagram) != expected:
        raise FrameError(f"{len(datagram)} bytes where the header says {expected}")
    spec = MESSAGES.get(msg_id)
    if spec is None:
        raise FrameError(f"message id {msg_id} is not one the command channel reads")
    end = HEADER_LEN + length
    payload = datagram[HEADER_LEN:end]
    crc = crc_x25(bytes([spec.crc_extra]), crc_x25(datagram[1:end]))
    if crc != int.from_bytes(datagram[end : end + 2], "little"):
        raise FrameError(f"bad crc (message id {msg_id})")
    if length > spec.size:
        raise FrameError(f"payload of {length} bytes, longer than message id {msg_id}'s {spec.size}")
    values = struct.unpack(spec.layout, payload + b"\0" * (spec.size - length))
    fields = dict(zip(spec.fields, values, strict=True))
    if not signed:
        return Frame(seq, sys_id, comp_id, msg_id, fields)
    link_id = datagram[end + 2]
    timestamp = int.from_bytes(datagram[end + 3 : end + 9], "little")
    ok = None if key is None else signature(key, datagram[: end + 2], link_id, timestamp) == datagram[end + 9 :]
    return Frame(seq, sys_id, comp_id, msg_id, fields, link_id, timestamp, ok)


def key_from_hex(text: str) -> bytes:
    """A signing key written as 64 hex digits (32 bytes, as MAVProxy's ``signing setup`` derives from a passphrase and
    QGroundControl stores); ValueError naming what is wrong."""
    try:
        key = bytes.fromhex(text)
    except ValueError:
        raise ValueError("a signing key is 64 hexadecimal digits") from None
    if len(key) != SIGNING_KEY_BYTES:
        raise ValueError(f"a signing key is {SIGNING_KEY_BYTES} bytes (64 hex digits), got {len(key)}")
    return key


def key_from_passphrase(passphrase: str) -> bytes:
    """The 32-byte key MAVProxy's ``signing setup PASSPHRASE`` uses: SHA-256 of the passphrase."""
    return hashlib.sha256(passphrase.encode()).digest()
