"""The MAVLink messages the companion sends its ground station, as typed values (field names as in the MAVLink XML).

The link's :class:`~companion.vehicle.link.Ground` part takes these, not a message name and a mapping: a field that
is misspelt or of the wrong type is a type error here, not a refusal from the MAVLink packer in flight.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

FieldValue = int | float | str | tuple[float, ...]
"""One field's value as MAVLink carries it (an array field as a tuple)."""


@dataclass(frozen=True)
class _Message:
    message_name: ClassVar[str]

    def fields(self) -> dict[str, FieldValue]:
        """The fields by their MAVLink names, in the order of the message's definition."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


@dataclass(frozen=True)
class StatusText(_Message):
    """STATUSTEXT (MAVLink 2): ``severity`` (MAV_SEVERITY), at most 50 characters of ``text``; a longer text is sent
    in chunks sharing a non-zero ``id``, numbered by ``chunk_seq`` (:mod:`companion.vehicle.statustext`)."""

    message_name: ClassVar[str] = "STATUSTEXT"
    severity: int
    text: str
    id: int
    chunk_seq: int


@dataclass(frozen=True)
class NamedValueFloat(_Message):
    """NAMED_VALUE_FLOAT: a named value a ground station can plot; ``time_boot_ms`` is the vehicle's clock (ms)."""

    message_name: ClassVar[str] = "NAMED_VALUE_FLOAT"
    time_boot_ms: int
    name: str
    value: float


@dataclass(frozen=True)
class LandingTarget(_Message):
    """LANDING_TARGET in ``frame`` (MAV_FRAME): the target's angles (rad) and slant ``distance`` (m) from the vehicle,
    its angular size (rad), its position ``x, y, z`` (m) and orientation ``q`` [w, x, y, z]; ``position_valid`` 0
    tells an autopilot not to act on it."""

    message_name: ClassVar[str] = "LANDING_TARGET"
    time_usec: int
    target_num: int
    frame: int
    angle_x: float
    angle_y: float
    distance: float
    size_x: float
    size_y: float
    x: float
    y: float
    z: float
    q: tuple[float, ...]
    type: int
    position_valid: int


GroundMessage = StatusText | NamedValueFloat | LandingTarget
"""Every message the companion sends its ground station."""
