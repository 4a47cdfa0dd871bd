"""The autopilot's vocabulary, shared by its parts (commander, navigator, servers, telemetry): MAVLink's command
results, STATUSTEXT severities and landed states, and who asked for a mode change."""

from __future__ import annotations

import enum


class MavResult(enum.IntEnum):
    """MAV_RESULT values."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4


class LandedState(enum.IntEnum):
    """MAV_LANDED_STATE values."""

    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class Severity(enum.IntEnum):
    """MAV_SEVERITY values: PX4 sends refusals and failsafes at CRITICAL (QGroundControl pops those up), progress at
    INFO."""

    EMERGENCY = 0
    ALERT = 1
    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6
    DEBUG = 7


class ControlSource(enum.Enum):
    """Who asked for a mode change."""

    MAVLINK = "mavlink"
    PILOT = "pilot"
    FAILSAFE = "failsafe"
    AUTOPILOT = "autopilot"
