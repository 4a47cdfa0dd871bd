"""MAVLink FTP (FILE_TRANSFER_PROTOCOL), the minimal server: every request is answered at once.

This autopilot has no file system to offer: opening, listing, reading, writing or removing anything is answered with a
NAK (``FileNotFound`` for a path, ``UnknownCommand`` for an operation it does not know), and ``ResetSessions`` or
``TerminateSession`` with an ACK. A ground station that tries FTP first (MAVProxy downloads ``@PARAM/param.pck``,
QGroundControl component metadata) learns in one round trip that it must use the message protocols instead, rather
than waiting for its FTP timeout (MAVProxy's is about 7 s). The payload layout is MAVLink FTP's: a 12-byte header
(``seq`` u16, ``session`` u8, ``opcode`` u8, ``size`` u8, ``req_opcode`` u8, ``burst_complete`` u8, padding,
``offset`` u32), then up to 239 bytes of data.
"""

from __future__ import annotations

import enum
import struct
from typing import Any

HEADER = struct.Struct("<HBBBBBBI")
PAYLOAD_BYTES = 251


class Opcode(enum.IntEnum):
    """MAVLink FTP opcodes."""

    NONE = 0
    TERMINATE_SESSION = 1
    RESET_SESSIONS = 2
    LIST_DIRECTORY = 3
    OPEN_FILE_RO = 4
    READ_FILE = 5
    CREATE_FILE = 6
    WRITE_FILE = 7
    REMOVE_FILE = 8
    CREATE_DIRECTORY = 9
    REMOVE_DIRECTORY = 10
    OPEN_FILE_WO = 11
    TRUNCATE_FILE = 12
    RENAME = 13
    CALC_FILE_CRC32 = 14
    BURST_READ_FILE = 15
    ACK = 128
    NAK = 129


class FtpError(enum.IntEnum):
    """The error code a NAK carries in its first data byte."""

    FAIL = 1
    INVALID_SESSION = 4
    UNKNOWN_COMMAND = 7
    FILE_NOT_FOUND = 10


PATH_OPERATIONS = {
    Opcode.LIST_DIRECTORY,
    Opcode.OPEN_FILE_RO,
    Opcode.CREATE_FILE,
    Opcode.REMOVE_FILE,
    Opcode.CREATE_DIRECTORY,
    Opcode.REMOVE_DIRECTORY,
    Opcode.OPEN_FILE_WO,
    Opcode.TRUNCATE_FILE,
    Opcode.RENAME,
    Opcode.CALC_FILE_CRC32,
}
SESSION_OPERATIONS = {Opcode.READ_FILE, Opcode.WRITE_FILE, Opcode.BURST_READ_FILE}


class FtpServer:
    """Answers FILE_TRANSFER_PROTOCOL requests (see the module docstring); counts what it refused."""

    def __init__(self) -> None:
        self.requests = 0
        self.naks = 0

    def handle(self, msg: Any) -> list[int] | None:
        """The reply payload (251 bytes) to one request, or None for something that is not a request."""
        payload = bytes(msg.payload)
        if len(payload) < HEADER.size:
            return None
        seq, session, opcode, _size, _req, _burst, _pad, _offset = HEADER.unpack_from(payload)
        if opcode in (Opcode.ACK, Opcode.NAK):
            return None  # a reply, not a request
        self.requests += 1
        if opcode in (Opcode.TERMINATE_SESSION, Opcode.RESET_SESSIONS):
            return self._reply(seq, session, Opcode.ACK, opcode, b"")
        self.naks += 1
        if opcode in PATH_OPERATIONS:
            error = FtpError.FILE_NOT_FOUND
        elif opcode in SESSION_OPERATIONS:
            error = FtpError.INVALID_SESSION  # no file is ever open
        else:
            error = FtpError.UNKNOWN_COMMAND
        return self._reply(seq, session, Opcode.NAK, opcode, bytes([int(error)]))

    @staticmethod
    def _reply(seq: int, session: int, opcode: Opcode, request: int, data: bytes) -> list[int]:
        header = HEADER.pack((seq + 1) % 65536, session, int(opcode), len(data), request, 0, 0, 0)
        body = header + data
        return list(body + bytes(PAYLOAD_BYTES - len(body)))
