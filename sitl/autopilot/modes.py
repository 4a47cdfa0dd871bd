"""PX4 flight modes and their MAVLink encoding (``custom_mode = main << 16 | sub << 24``)."""

from __future__ import annotations

import enum


class MainMode(enum.IntEnum):
    """PX4 main modes."""

    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7


class PosctlSubMode(enum.IntEnum):
    """PX4 POSCTL sub-modes."""

    POSCTL = 0
    ORBIT = 1


class AutoSubMode(enum.IntEnum):
    """PX4 AUTO sub-modes."""

    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6


class FlightMode(enum.Enum):
    """The modes this autopilot flies, with their (main, sub) PX4 encoding."""

    POSCTL = (MainMode.POSCTL, PosctlSubMode.POSCTL)
    ORBIT = (MainMode.POSCTL, PosctlSubMode.ORBIT)
    OFFBOARD = (MainMode.OFFBOARD, 0)
    AUTO_MISSION = (MainMode.AUTO, AutoSubMode.MISSION)
    AUTO_TAKEOFF = (MainMode.AUTO, AutoSubMode.TAKEOFF)
    AUTO_LOITER = (MainMode.AUTO, AutoSubMode.LOITER)
    AUTO_LAND = (MainMode.AUTO, AutoSubMode.LAND)
    AUTO_RTL = (MainMode.AUTO, AutoSubMode.RTL)

    @property
    def custom_mode(self) -> int:
        """HEARTBEAT ``custom_mode`` field."""
        main, sub = self.value
        return int(main) << 16 | int(sub) << 24

    @classmethod
    def from_px4(cls, main: int, sub: int) -> FlightMode | None:
        """The mode for a (main, sub) pair, or None if this autopilot does not fly it."""
        for mode in cls:
            m, s = mode.value
            if int(m) == main and (int(s) == sub or (main != MainMode.AUTO and sub == 0)):
                return mode
        return None

    @classmethod
    def from_custom_mode(cls, custom_mode: int) -> FlightMode | None:
        """Decode a HEARTBEAT ``custom_mode``."""
        return cls.from_px4((custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF)

    @classmethod
    def from_name(cls, name: str) -> FlightMode:
        """Parse ``"POSCTL"``, ``"AUTO.LAND"``, ``"auto_loiter"``, ``"hold"``..."""
        key = name.strip().upper().replace(".", "_")
        aliases = {
            "HOLD": "AUTO_LOITER",
            "LAND": "AUTO_LAND",
            "TAKEOFF": "AUTO_TAKEOFF",
            "RTL": "AUTO_RTL",
            "MISSION": "AUTO_MISSION",
            "POSCTL_ORBIT": "ORBIT",
        }
        try:
            return cls[aliases.get(key, key)]
        except KeyError:
            raise ValueError(f"unknown flight mode {name!r}; known: {', '.join(m.name for m in cls)}") from None

    @property
    def px4_name(self) -> str:
        """PX4's name, e.g. ``AUTO.LAND``."""
        if self is FlightMode.ORBIT:
            return "POSCTL.ORBIT"
        return self.name.replace("_", ".", 1) if self.name.startswith("AUTO_") else self.name
