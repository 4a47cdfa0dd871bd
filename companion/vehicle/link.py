"""What the application needs from the vehicle, as a small interface (MAVSDK in flight, fakes in unit tests).

Frames: local NED metres for positions, body FRD to world NED quaternions [w, x, y, z], vehicle-clock seconds.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from companion.errors import SlzError
from companion.vehicle.clock import VehicleClock
from companion.vehicle.ground_messages import GroundMessage
from companion.vehicle.pose_buffer import PoseBuffer


@dataclass(frozen=True)
class Setpoint:
    """A local position setpoint: NED metres, yaw in degrees (MAVSDK's ``PositionNedYaw``); what the landing logic
    asks of the vehicle and the link sends."""

    north_m: float
    east_m: float
    down_m: float
    yaw_deg: float


class LinkResult(str, enum.Enum):
    """Why a vehicle link call failed, as MAVSDK's ``ActionResult`` / ``ConnectionResult`` say it: what a caller
    decides on (the prose of :class:`VehicleError` is for people)."""

    TIMEOUT = "timeout"
    """No answer (or the awaited condition) within the call's deadline."""
    REFUSED = "refused"
    """The autopilot answered no (a denied command, a failed download, an unknown message)."""
    NOT_CONNECTED = "not_connected"
    """The link has no autopilot (not connected yet, or closed)."""
    CONNECTION_ERROR = "connection_error"
    """The connection could not be opened (a busy port, a bad URL, a missing serial device)."""
    INVALID = "invalid"
    """The request itself was wrong (a non-finite setpoint, a system id that is not the autopilot's)."""


class VehicleError(SlzError):
    """The vehicle link failed: which link, what failed and its :class:`LinkResult`."""

    def __init__(self, link: str, what: str, result: LinkResult) -> None:
        super().__init__(f"{link}: {what}")
        self.link = link
        self.what = what
        self.result = result


class FlightMode(str, enum.Enum):
    """Flight modes the companion distinguishes (PX4 names)."""

    UNKNOWN = "UNKNOWN"
    MANUAL = "MANUAL"
    ALTCTL = "ALTCTL"
    POSCTL = "POSCTL"
    HOLD = "HOLD"
    TAKEOFF = "TAKEOFF"
    LAND = "LAND"
    RETURN_TO_LAUNCH = "RETURN_TO_LAUNCH"
    OFFBOARD = "OFFBOARD"
    MISSION = "MISSION"
    OTHER = "OTHER"


@dataclass
class VehicleStatus:
    """The latest non-pose telemetry (updated in place by the link)."""

    mode: FlightMode = FlightMode.UNKNOWN
    armed: bool = False
    in_air: bool = False
    landed_state: str = "UNKNOWN"
    armable: bool = False
    local_position_ok: bool = False
    last_telemetry_wall_s: float | None = None
    offboard_entries: int = 0
    """Times the telemetry reported the autopilot entering OFFBOARD: a stay that the next report already ended (a
    pilot who switched away at once) still counts, where ``mode`` shows only the latest."""
    battery_remaining: float | None = None
    """The pack's remaining charge, a fraction (None until reported)."""
    battery_current_a: float | None = None
    """The current it supplies, amperes (None until reported)."""
    home_ne_m: tuple[float, float] | None = None
    """Home, local NED north and east (m), as the autopilot reports it (None until reported)."""
    port_shared: str | None = None
    """Why the link's port is shared with another program, once seen (``companion.vehicle.port_holders``)."""


class Telemetry(Protocol):
    """What the autopilot reports: stamped poses, its clock and the latest status (MAVSDK's telemetry plugin)."""

    poses: PoseBuffer
    clock: VehicleClock
    status: VehicleStatus

    async def wait_for(self, condition: Callable[[], bool], deadline: float, what: str) -> None:
        """Wait until ``condition()`` holds, re-checked at each telemetry update; :class:`VehicleError`
        (:attr:`LinkResult.TIMEOUT`) at ``deadline`` (monotonic seconds)."""
        ...


class Action(Protocol):
    """Commands the autopilot acknowledges (MAVSDK's action plugin); each raises :class:`VehicleError` when refused
    or unanswered."""

    async def arm_and_takeoff(self, altitude_m: float, timeout_s: float) -> None:
        """Arm and climb to ``altitude_m`` (SITL and benches; never in a dry run)."""
        ...

    async def take_off(self, altitude_m: float) -> None:
        """Arm and command a takeoff to ``altitude_m``; returns once the autopilot accepted both (it does not wait
        for the climb)."""
        ...

    async def land(self) -> None:
        """Land where the vehicle is."""
        ...

    async def hold(self) -> None:
        """Hold position (autopilot hold mode)."""
        ...

    async def return_to_launch(self) -> None:
        """Return to launch."""
        ...

    async def set_actuator(self, index: int, value: float) -> None:
        """Set the autopilot's actuator output ``index`` (1-6: PX4's "Offboard Actuator Set N") to ``value`` in [-1,
        1] (MAV_CMD_DO_SET_ACTUATOR), once it acknowledges."""
        ...


class Offboard(Protocol):
    """Position setpoints in OFFBOARD (MAVSDK's offboard plugin)."""

    async def start(self, setpoint: Setpoint) -> None:
        """Send ``setpoint`` and switch to OFFBOARD."""
        ...

    async def set_setpoint(self, setpoint: Setpoint) -> None:
        """Send a position setpoint (local NED, yaw in degrees)."""
        ...

    async def stop(self) -> None:
        """Stop streaming setpoints (the autopilot falls back to its hold)."""
        ...

    def stop_blocking(self) -> None:
        """Stop offboard from another thread when the event loop is stuck."""
        ...


class MissionStore(Protocol):
    """What the autopilot stores for the mission: its EKF origin and its rally points (MAVSDK's mission_raw)."""

    async def global_origin(self, timeout_s: float) -> tuple[float, float]:
        """The autopilot's EKF origin (GPS_GLOBAL_ORIGIN): latitude and longitude in degrees, where its local NED
        frame starts; :class:`VehicleError` when it gives none within ``timeout_s`` (wall)."""
        ...

    async def rally_points(self, timeout_s: float) -> list[tuple[float, float]]:
        """The autopilot's rally points (uploaded by a ground station with the rally protocol): latitude and longitude
        in degrees each; :class:`VehicleError` when the list does not come within ``timeout_s`` (wall)."""
        ...


class Params(Protocol):
    """The autopilot's parameters (MAVSDK's param plugin)."""

    async def read_all(self, timeout_s: float = 15.0) -> dict[str, float] | None:
        """Every parameter by name (integers as floats); None when the list does not come within ``timeout_s``."""
        ...


class Ground(Protocol):
    """Messages for the ground station, which the autopilot forwards (MAVSDK's MAVLink-direct plugin)."""

    async def send(self, message: GroundMessage) -> None:
        """Send one typed message; :class:`VehicleError` when refused or not sent in time."""
        ...


class VehicleLink(Protocol):
    """The companion's view of the autopilot, in parts as MAVSDK's ``System`` has plugins: each consumer takes the
    part it uses."""

    name: str
    system_id: int
    """The vehicle's MAVLink system id (the autopilot's, once connected): the companion's too."""

    @property
    def telemetry(self) -> Telemetry: ...

    @property
    def action(self) -> Action: ...

    @property
    def offboard(self) -> Offboard: ...

    @property
    def mission(self) -> MissionStore: ...

    @property
    def params(self) -> Params: ...

    @property
    def ground(self) -> Ground: ...

    async def connect(self, timeout_s: float) -> None:
        """Find the autopilot and start the telemetry streams (raises :class:`VehicleError`)."""
        ...

    async def close(self) -> None:
        """Stop the streams and release the connection."""
        ...
