"""The autopilot's parameters: PX4 names, types, defaults and ranges; read, set, list over MAVLink.

PX4 sends INT32 parameters "bytewise": the float field of PARAM_VALUE carries the integer's four bytes.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass


class ParamType(enum.IntEnum):
    """MAV_PARAM_TYPE values used here."""

    INT32 = 6
    REAL32 = 9


@dataclass(frozen=True)
class ParamSpec:
    """One parameter's definition."""

    name: str
    param_type: ParamType
    default: float
    minimum: float
    maximum: float
    description: str


PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("MIS_TAKEOFF_ALT", ParamType.REAL32, 2.5, 0.0, 100.0, "Takeoff altitude above home, m"),
    ParamSpec("MPC_TKO_SPEED", ParamType.REAL32, 1.5, 0.5, 5.0, "Takeoff climb rate, m/s"),
    ParamSpec("MPC_LAND_SPEED", ParamType.REAL32, 0.7, 0.3, 3.0, "Landing descent rate, m/s"),
    ParamSpec("MPC_XY_VEL_MAX", ParamType.REAL32, 5.0, 0.5, 20.0, "Maximum horizontal speed, m/s"),
    ParamSpec("MPC_Z_VEL_MAX_UP", ParamType.REAL32, 3.0, 0.5, 8.0, "Maximum ascent rate, m/s"),
    ParamSpec("MPC_Z_VEL_MAX_DN", ParamType.REAL32, 1.5, 0.5, 4.0, "Maximum descent rate, m/s"),
    ParamSpec("MPC_TILTMAX_AIR", ParamType.REAL32, 35.0, 20.0, 89.0, "Maximum tilt in the air, deg"),
    ParamSpec("MPC_THR_HOVER", ParamType.REAL32, 0.5, 0.1, 0.8, "Hover thrust, normalized"),
    ParamSpec("COM_OF_LOSS_T", ParamType.REAL32, 1.0, 0.0, 60.0, "Offboard setpoint loss timeout, s"),
    ParamSpec("COM_OBL_ACT", ParamType.INT32, 0, 0, 2, "Offboard loss action: 0 land, 1 hold, 2 return"),
    ParamSpec("NAV_RCL_ACT", ParamType.INT32, 2, 0, 3, "RC loss action: 0 none, 1 hold, 2 return, 3 land"),
    ParamSpec("COM_RCL_EXCEPT", ParamType.INT32, 0, 0, 7, "RC loss exceptions bitmask: 4 = offboard"),
    ParamSpec("COM_RC_LOSS_T", ParamType.REAL32, 0.5, 0.0, 35.0, "RC loss timeout, s"),
    ParamSpec("COM_DISARM_LAND", ParamType.REAL32, 2.0, -1.0, 20.0, "Auto-disarm delay after landing, s (-1 off)"),
    ParamSpec("COM_DISARM_PRFLT", ParamType.REAL32, 10.0, -1.0, 20.0, "Auto-disarm if no takeoff after arming, s"),
    ParamSpec("RTL_RETURN_ALT", ParamType.REAL32, 30.0, 0.0, 150.0, "Return altitude above home, m"),
    ParamSpec("MAV_SYS_ID", ParamType.INT32, 1, 1, 250, "MAVLink system id"),
)


class ParamError(Exception):
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
    """Current values of every parameter, with range checks."""

    def __init__(self, overrides: dict[str, float] | None = None) -> None:
        self._specs = {spec.name: spec for spec in PARAMS}
        self._values = {spec.name: float(spec.default) for spec in PARAMS}
        for name, value in (overrides or {}).items():
            self.set(name, value)

    def __getitem__(self, name: str) -> float:
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
        if spec.param_type is ParamType.INT32:
            value = float(round(value))
        self._values[name] = value
        return value

    def names(self) -> list[str]:
        """All names, in index order."""
        return [spec.name for spec in PARAMS]

    def index(self, name: str) -> int:
        """The index of ``name`` in the list."""
        return self.names().index(name)
