"""The autopilot's parameters read, set and listed over MAVLink, from PX4's table (:mod:`sitl.px4_params`).

PX4 sends INT32 parameters "bytewise": the float field of PARAM_VALUE carries the integer's four bytes.
"""

from __future__ import annotations

import math
import struct
import zlib

from companion.errors import SlzError
from sitl.px4_params import PARAMS, ParamSpec, ParamType


class ParamError(SlzError):
    """A parameter operation failed: unknown name or value out of range."""

    def __init__(self, name: str, what: str) -> None:
        super().__init__(f"parameter {name}: {what}")
        self.name = name


def encode_value(spec: ParamSpec, value: float) -> float:
    """The float to put in PARAM_VALUE (bytewise for INT32, as PX4 does)."""
    if spec.param_type is ParamType.INT32:
        return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])
    return float(value)


def decode_value(spec: ParamSpec, wire_value: float, wire_type: int) -> float:
    """The parameter value from a PARAM_SET's float and type."""
    if spec.param_type is ParamType.INT32 and wire_type == ParamType.INT32:
        return float(struct.unpack("<i", struct.pack("<f", wire_value))[0])
    return float(wire_value)


class ParameterStore:
    """Current values of every parameter.

    As PX4: a value set over MAVLink is stored as sent when it is a finite number of the parameter's type, even outside
    its documented range (:meth:`set_from_wire` says so in its return value), and whoever flies with it constrains it:
    ``store[name]`` is the value within [minimum, maximum], :meth:`raw` the stored one (what PARAM_VALUE reports).
    Configuration overrides (:meth:`set`) must be in range.
    """

    def __init__(self, overrides: dict[str, float] | None = None) -> None:
        self._specs = {spec.name: spec for spec in PARAMS}
        self._values = {spec.name: float(spec.default) for spec in PARAMS}
        self._names = [spec.name for spec in PARAMS]
        self._index = {name: i for i, name in enumerate(self._names)}
        for name, value in (overrides or {}).items():
            self.set(name, value)

    def __getitem__(self, name: str) -> float:
        spec = self._specs[name]
        return min(max(self._values[name], spec.minimum), spec.maximum)

    def __contains__(self, name: object) -> bool:
        return name in self._specs

    def raw(self, name: str) -> float:
        """The stored value of ``name``, as reported over MAVLink (it may lie outside the range)."""
        return self._values[name]

    def spec(self, name: str) -> ParamSpec:
        """The definition of ``name``; :class:`ParamError` if unknown."""
        try:
            return self._specs[name]
        except KeyError:
            raise ParamError(name, "unknown parameter") from None

    def set(self, name: str, value: float) -> float:
        """Set a value after checking its range; returns the stored value."""
        spec = self.spec(name)
        if not math.isfinite(value) or not spec.minimum <= value <= spec.maximum:
            raise ParamError(name, f"value {value} outside [{spec.minimum}, {spec.maximum}]")
        return self._store(spec, value)

    def set_from_wire(self, name: str, value: float) -> bool:
        """A PARAM_SET's value, stored as PX4 stores it; returns whether it lies within the range.

        Raises
        ------
        ParamError
            Unknown name, or a value that is not a finite number (NaN or infinity is never stored).
        """
        spec = self.spec(name)
        if not math.isfinite(value) or (spec.param_type is ParamType.INT32 and abs(value) >= 2**31):
            raise ParamError(name, f"value {value} is not a {spec.param_type.name.lower()}")
        stored = self._store(spec, value)
        return spec.minimum <= stored <= spec.maximum

    def _store(self, spec: ParamSpec, value: float) -> float:
        if spec.param_type is ParamType.INT32:
            value = float(round(value))
        else:
            value = float(struct.unpack("<f", struct.pack("<f", value))[0])  # what a float32 parameter holds
        self._values[spec.name] = value
        return value

    def names(self) -> list[str]:
        """All names, in index order (alphabetical, as PX4's)."""
        return list(self._names)

    def __len__(self) -> int:
        return len(self._names)

    def index(self, name: str) -> int:
        """The index of ``name`` in the list."""
        return self._index[name]

    def hash_check(self) -> int:
        """PX4's ``_HASH_CHECK``: a CRC-32 (no pre- or post-inversion, as PX4's ``crc32part``) over each parameter's
        name and its four value bytes, in index order. A ground station that cached the list compares it with the hash
        of its cache, and reuses the cache when they agree."""
        crc = 0
        for name in self._names:
            spec = self._specs[name]
            value = self._values[name]
            data = struct.pack("<i", int(value)) if spec.param_type is ParamType.INT32 else struct.pack("<f", value)
            for chunk in (name.encode("ascii"), data):
                crc = ~zlib.crc32(chunk, ~crc & 0xFFFFFFFF) & 0xFFFFFFFF
        return crc
