"""The command parts of the MAVSDK link, one per MAVSDK plugin: action, offboard, mission (origin and rally points),
params and ground (:mod:`companion.vehicle.link` names what each offers).

Every part reaches the autopilot through one :class:`MavsdkSession`, which holds the connected MAVSDK system and one
instance of each plugin for it. Every call is bounded in wall time and fails with a :class:`VehicleError` that names
the link, what failed and its :class:`LinkResult` (a MAVSDK error's own result, ``COMMAND_DENIED`` and such, is in its
text).
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from companion.vehicle.ground_messages import GroundMessage
from companion.vehicle.link import LinkResult, Setpoint, Telemetry, VehicleError

logger = logging.getLogger(__name__)

P = TypeVar("P")
T = TypeVar("T")


class MavsdkSession:
    """The connected MAVSDK system of one link and its plugins, one instance of each per system.

    Parameters
    ----------
    url : str
        The link's connection URL, named in every error.
    """

    def __init__(self, url: str) -> None:
        self.url = url
        self._system: Any = None
        self._plugins: dict[type, Any] = {}

    def attach(self, system: Any) -> None:
        """The MAVSDK ``System`` the parts talk to from now on (None: not connected); plugins of an earlier system
        are dropped."""
        self._system = system
        self._plugins = {}

    @property
    def system(self) -> Any:
        """The MAVSDK system; :class:`VehicleError` (:attr:`LinkResult.NOT_CONNECTED`) when there is none."""
        if self._system is None:
            raise VehicleError(self.url, "not connected", LinkResult.NOT_CONNECTED)
        return self._system

    def plugin(self, kind: type[P]) -> P:
        """The system's one ``kind`` plugin (``ActionAsync``, ``OffboardAsync``...), made at its first use."""
        system = self.system
        if kind not in self._plugins:
            self._plugins[kind] = kind(system)  # type: ignore[call-arg]
        return self._plugins[kind]  # type: ignore[no-any-return]

    def existing(self, kind: type[P]) -> P | None:
        """The ``kind`` plugin if one was made, else None (for a caller that must not make one)."""
        return self._plugins.get(kind)

    async def call(self, what: str, action: Callable[[], Awaitable[T]], timeout_s: float) -> T:
        """``action()`` within ``timeout_s`` (wall): a timeout is :attr:`LinkResult.TIMEOUT`, an error MAVSDK raises
        (its ``ActionError``, ``OffboardError``... carry a ``.result``) :attr:`LinkResult.REFUSED`."""
        try:
            return await asyncio.wait_for(action(), timeout_s)
        except asyncio.TimeoutError:
            raise VehicleError(self.url, f"{what}: no answer within {timeout_s:g} s", LinkResult.TIMEOUT) from None
        except Exception as exc:
            refused = f"{what} refused: {getattr(exc, 'result', exc)}"
            raise VehicleError(self.url, refused, LinkResult.REFUSED) from None


class MavsdkAction:
    """:class:`companion.vehicle.link.Action` through MAVSDK's action plugin."""

    def __init__(self, session: MavsdkSession, telemetry: Telemetry) -> None:
        self._session = session
        self._telemetry = telemetry

    def _action(self) -> Any:
        from mavsdk.asyncio.plugins.action import ActionAsync

        return self._session.plugin(ActionAsync)

    async def _call(self, what: str, action: Callable[[], Awaitable[Any]], timeout_s: float = 10.0) -> None:
        await self._session.call(what, action, timeout_s)

    async def arm_and_takeoff(self, altitude_m: float, timeout_s: float) -> None:
        """Wait until armable, arm, take off and wait for ``altitude_m`` (within 0.5 m), all within ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        status, poses = self._telemetry.status, self._telemetry.poses
        await self._telemetry.wait_for(lambda: status.armable and status.local_position_ok, deadline, "armable")
        await self.take_off(altitude_m)

        def high_enough() -> bool:
            t = poses.latest_t_s
            pose = poses.pose_at(t) if t is not None else None
            return pose is not None and pose.altitude_m >= altitude_m - 0.5

        await self._telemetry.wait_for(high_enough, deadline, f"takeoff to {altitude_m:g} m")

    async def take_off(self, altitude_m: float) -> None:
        """Set the takeoff altitude, arm and take off; returns when the autopilot has acknowledged all three."""
        action = self._action()
        await self._call("set takeoff altitude", lambda: action.set_takeoff_altitude(altitude_m))
        await self._call("arm", action.arm)
        await self._call("takeoff", action.takeoff)

    async def land(self) -> None:
        """Land in place."""
        await self._call("land", self._action().land)

    async def hold(self) -> None:
        """Hold (loiter)."""
        await self._call("hold", self._action().hold)

    async def return_to_launch(self) -> None:
        """Return to launch."""
        await self._call("return to launch", self._action().return_to_launch)

    async def set_actuator(self, index: int, value: float) -> None:
        """An actuator output: MAVSDK's ``set_actuator``, which waits for the COMMAND_ACK."""
        action = self._action()
        await self._call(f"actuator {index} to {value:g}", lambda: action.set_actuator(index, value), timeout_s=5.0)


class MavsdkOffboard:
    """:class:`companion.vehicle.link.Offboard` through MAVSDK's offboard plugin (which re-sends the last setpoint
    at 20 Hz on its own thread until the next)."""

    def __init__(self, session: MavsdkSession) -> None:
        self._session = session

    def _offboard(self) -> Any:
        from mavsdk.asyncio.plugins.offboard import OffboardAsync

        return self._session.plugin(OffboardAsync)

    async def start(self, setpoint: Setpoint) -> None:
        """Send the first setpoint, then ask for OFFBOARD (PX4 wants a setpoint stream first)."""
        offboard = self._offboard()
        await self.set_setpoint(setpoint)
        await self._session.call("offboard start", offboard.start, 10.0)

    async def set_setpoint(self, setpoint: Setpoint) -> None:
        """One SET_POSITION_TARGET_LOCAL_NED."""
        from mavsdk.plugins.offboard import PositionNedYaw

        offboard = self._offboard()
        values = (setpoint.north_m, setpoint.east_m, setpoint.down_m, setpoint.yaw_deg)
        if not all(math.isfinite(v) for v in values):
            raise VehicleError(self._session.url, f"refusing a non-finite setpoint {values}", LinkResult.INVALID)
        await self._session.call("setpoint", lambda: offboard.set_position_ned(PositionNedYaw(*values)), 2.0)

    async def stop(self) -> None:
        """Stop offboard: MAVSDK stops re-sending and the autopilot switches to hold."""
        await self._session.call("offboard stop", self._offboard().stop, 10.0)

    def stop_blocking(self) -> None:
        """Stop offboard from any thread, without the event loop (the stall watchdog's way out)."""
        from mavsdk.asyncio.plugins.offboard import OffboardAsync

        offboard = self._session.existing(OffboardAsync)
        if offboard is None:
            return
        try:
            offboard._plugin.stop()  # the blocking C call under OffboardAsync.stop
        except Exception as exc:  # the watchdog must not die; the autopilot's own failsafe remains
            logger.error("emergency offboard stop failed: %s", exc)


class MavsdkMission:
    """:class:`companion.vehicle.link.MissionStore`: the EKF origin (telemetry plugin) and the rally points
    (mission_raw plugin), each read once and bounded by ``timeout_s`` (wall)."""

    def __init__(self, session: MavsdkSession) -> None:
        self._session = session

    async def global_origin(self, timeout_s: float) -> tuple[float, float]:
        """The EKF origin (GPS_GLOBAL_ORIGIN): latitude and longitude, degrees."""
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        telemetry = self._session.plugin(TelemetryAsync)
        url = self._session.url
        try:
            origin = await asyncio.wait_for(telemetry.get_gps_global_origin(), timeout_s)
        except asyncio.TimeoutError:
            raise VehicleError(url, f"no GPS_GLOBAL_ORIGIN within {timeout_s:g} s", LinkResult.TIMEOUT) from None
        except Exception as exc:  # TelemetryError: the autopilot has no origin yet
            raise VehicleError(url, f"no GPS_GLOBAL_ORIGIN: {exc}", LinkResult.REFUSED) from None
        lat, lon = float(origin.latitude_deg), float(origin.longitude_deg)
        if not (math.isfinite(lat) and math.isfinite(lon)):
            raise VehicleError(url, "GPS_GLOBAL_ORIGIN not set (no GPS fix yet?)", LinkResult.REFUSED)
        return lat, lon

    async def rally_points(self, timeout_s: float) -> list[tuple[float, float]]:
        """The autopilot's rally points: latitude and longitude, degrees."""
        from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync

        mission = self._session.plugin(MissionRawAsync)
        url = self._session.url
        try:
            items = await asyncio.wait_for(mission.download_rallypoints(), timeout_s)
        except asyncio.TimeoutError:
            raise VehicleError(url, f"no rally point list within {timeout_s:g} s", LinkResult.TIMEOUT) from None
        except Exception as exc:  # MissionRawError: the autopilot refused or timed out the download
            raise VehicleError(url, f"rally points not downloaded: {exc}", LinkResult.REFUSED) from None
        return [(item.x * 1e-7, item.y * 1e-7) for item in items]


class MavsdkParams:
    """:class:`companion.vehicle.link.Params` through MAVSDK's param plugin."""

    def __init__(self, session: MavsdkSession) -> None:
        self._session = session

    async def read_all(self, timeout_s: float = 15.0) -> dict[str, float] | None:
        """Every parameter of the autopilot by name (integers as floats), from one list request; None when the list
        does not arrive within ``timeout_s`` (the doctor says so). Asking for the list, not for names it may lack,
        leaves no retries and no "Retrying failed" errors for a parameter another autopilot version names
        differently."""
        from mavsdk.asyncio.plugins.param import ParamAsync

        params = self._session.plugin(ParamAsync)
        try:
            every = await asyncio.wait_for(params.get_all_params(), timeout_s)
        except asyncio.TimeoutError:
            return None
        except Exception as exc:  # ParamError: the list could not be read
            logger.warning("%s: the parameter list could not be read: %s", self._session.url, exc)
            return None
        values = {p.name: float(p.value) for p in every.int_params}
        values.update({p.name: float(p.value) for p in every.float_params})
        return values


class MavsdkGround:
    """:class:`companion.vehicle.link.Ground` through MAVSDK's MAVLink-direct plugin (libmav packs each message from
    its fields' JSON), broadcast: the autopilot forwards it to its ground-station link."""

    def __init__(self, session: MavsdkSession) -> None:
        self._session = session

    async def send(self, message: GroundMessage) -> None:
        """One message, sent within 2 s."""
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        direct = self._session.plugin(MavlinkDirectAsync)
        name = message.message_name
        packed = MavlinkMessage(message_name=name, fields_json=json.dumps(message.fields(), allow_nan=False))
        await self._session.call(name, lambda: direct.send_message(packed), 2.0)
