"""A writer of PX4's ULog format, the file PX4 logs every flight to (and its SITL too), so the tools people read PX4
flights with (Flight Review, pyulog, PlotJuggler) read the SITL's.

The format (PX4's "ULog File Format" page): a 16-byte header (magic, version 1, the start's timestamp in
microseconds), then messages of a 3-byte header (``uint16`` payload size, ``uint8`` type) and their payload, little
endian. The definitions come first: flag bits (``B``), formats (``F``: ``name:type field;...``), information (``I``)
and the initial parameters (``P``); the first subscription (``A``) starts the data, where data (``D``), logged strings
(``L``) and changed parameters (``P``) follow in time order. Every topic's first field is ``uint64_t timestamp`` in
microseconds of the vehicle's boot clock, the clock MAVLink's ``time_boot_ms`` counts.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from companion.errors import SlzError

MAGIC = b"ULog\x01\x12\x35"
VERSION = 1

# Field types and their struct codes (little endian, no implicit padding: a topic's fields are packed in order).
TYPE_CODES = {
    "int8_t": "b",
    "uint8_t": "B",
    "int16_t": "h",
    "uint16_t": "H",
    "int32_t": "i",
    "uint32_t": "I",
    "int64_t": "q",
    "uint64_t": "Q",
    "float": "f",
    "double": "d",
    "bool": "?",
    "char": "c",
}


class ULogError(SlzError):
    """A ULog could not be written as asked: an unknown type, a topic not defined, a value of the wrong shape."""


@dataclass(frozen=True)
class Topic:
    """A topic's format: its name and its fields as ``(type, name)``; a type may be an array, ``float[4]``."""

    name: str
    fields: tuple[tuple[str, str], ...]

    def __post_init__(self) -> None:
        if not self.fields or self.fields[0] != ("uint64_t", "timestamp"):
            raise ULogError(f"topic {self.name}: the first field must be uint64_t timestamp")
        for kind, _ in self.fields:
            base = kind.split("[")[0]
            if base not in TYPE_CODES:
                raise ULogError(f"topic {self.name}: unknown field type {kind!r}")

    @property
    def format_text(self) -> str:
        """The ``F`` message's text: ``name:type field;type field;...``."""
        return self.name + ":" + "".join(f"{kind} {field};" for kind, field in self.fields)

    @property
    def struct(self) -> struct.Struct:
        """The payload's layout."""
        codes = []
        for kind, _ in self.fields:
            base, _, rest = kind.partition("[")
            count = int(rest.rstrip("]")) if rest else 1
            codes.append(f"{count}{TYPE_CODES[base]}" if count > 1 else TYPE_CODES[base])
        return struct.Struct("<" + "".join(codes))


def _message(kind: bytes, payload: bytes) -> bytes:
    if len(payload) > 0xFFFF:
        raise ULogError(f"a {kind.decode()} message of {len(payload)} bytes is over ULog's 65535")
    return struct.pack("<HB", len(payload), kind[0]) + payload


def _key_value(key: str, value: bytes) -> bytes:
    encoded = key.encode()
    return struct.pack("<B", len(encoded)) + encoded + value


def _parameter(name: str, value: float, is_int: bool) -> bytes:
    if is_int:
        return _key_value(f"int32_t {name}", struct.pack("<i", int(value)))
    return _key_value(f"float {name}", struct.pack("<f", float(value)))


class ULogWriter:
    """Writes one ULog file: definitions at :meth:`start`, then data, strings and parameter changes in time order.

    Parameters
    ----------
    path : Path
        The file (its folder is created; an existing file is replaced).
    start_us : int
        The log's start on the vehicle's boot clock, microseconds.
    """

    def __init__(self, path: Path, start_us: int) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._file: BinaryIO = open(path, "wb")  # noqa: SIM115 - closed in close()
        self._file.write(MAGIC + struct.pack("<BQ", VERSION, start_us))
        self._file.write(_message(b"B", bytes(16) + bytes(24)))  # no compat/incompat flags, no appended data
        self._ids: dict[str, tuple[int, struct.Struct]] = {}
        self._started = False

    def start(self, topics: list[Topic], info: dict[str, str], parameters: dict[str, tuple[float, bool]]) -> None:
        """The definitions: each topic's format, ``info`` (strings: ``sys_name``, ``ver_sw_release``...), the
        initial ``parameters`` (name: (value, is_int)); then one subscription per topic, which starts the data."""
        if self._started:
            raise ULogError("the definitions were written already")
        for topic in topics:
            self._file.write(_message(b"F", topic.format_text.encode()))
        for key, text in info.items():
            encoded = text.encode()
            self._file.write(_message(b"I", _key_value(f"char[{len(encoded)}] {key}", encoded)))
        for name, (value, is_int) in parameters.items():
            self._file.write(_message(b"P", _parameter(name, value, is_int)))
        for msg_id, topic in enumerate(topics):
            self._file.write(_message(b"A", struct.pack("<BH", 0, msg_id) + topic.name.encode()))
            self._ids[topic.name] = (msg_id, topic.struct)
        self._started = True

    def data(self, topic: str, *values: object) -> None:
        """One sample of ``topic``: its fields' values in order (the timestamp first, arrays flattened)."""
        try:
            msg_id, layout = self._ids[topic]
        except KeyError:
            raise ULogError(f"topic {topic!r} was not defined at start()") from None
        try:
            payload = layout.pack(*values)
        except struct.error as exc:
            raise ULogError(f"topic {topic}: {exc}") from None
        self._file.write(_message(b"D", struct.pack("<H", msg_id) + payload))

    def log(self, timestamp_us: int, level: int, text: str) -> None:
        """A logged string at ``level`` (syslog's: 0 emergency ... 7 debug; MAV_SEVERITY has the same values)."""
        level = min(max(int(level), 0), 7)
        payload = struct.pack("<BQ", ord(str(level)), timestamp_us) + text.encode()[:60000]
        self._file.write(_message(b"L", payload))

    def parameter(self, name: str, value: float, is_int: bool) -> None:
        """A parameter changed in flight."""
        self._file.write(_message(b"P", _parameter(name, value, is_int)))

    def flush(self) -> None:
        """Hand what was written to the operating system (a phase change, the end)."""
        self._file.flush()

    def close(self) -> None:
        """Close the file."""
        if not self._file.closed:
            self._file.close()
