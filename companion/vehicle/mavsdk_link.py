"""The vehicle link through MAVSDK (``mavsdk`` 4.x, ``mavsdk.asyncio``).

Poses are stamped with the autopilot's own clock: ``LOCAL_POSITION_NED`` and ``ATTITUDE_QUATERNION`` are read through
the MAVLink-direct plugin so that their ``time_boot_ms`` travels with them into the :class:`PoseBuffer` (MAVSDK's
``position_velocity_ned`` has no timestamp). Mode, armed state and landed state come from the telemetry plugin.
MAVSDK re-sends the last offboard setpoint on its own thread; the application's watchdog stops offboard when its
own decision loop stalls. One ``Mavsdk`` instance per process (MAVSDK's own advice).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

from companion.vehicle import mavsdk_stored as stored
from companion.vehicle.clock import VehicleClock
from companion.vehicle.link import FlightMode, Setpoint, VehicleError, VehicleStatus
from companion.vehicle.port_holders import shared_now, taken_by_another
from companion.vehicle.pose_buffer import PoseBuffer, PoseBufferError

logger = logging.getLogger(__name__)

CLOSE_TIMEOUT_S = 3.0  # wall time the telemetry streams get to end when the link closes

_MODES = {
    "MANUAL": FlightMode.MANUAL,
    "ALTCTL": FlightMode.ALTCTL,
    "POSCTL": FlightMode.POSCTL,
    "HOLD": FlightMode.HOLD,
    "TAKEOFF": FlightMode.TAKEOFF,
    "LAND": FlightMode.LAND,
    "RETURN_TO_LAUNCH": FlightMode.RETURN_TO_LAUNCH,
    "OFFBOARD": FlightMode.OFFBOARD,
    "MISSION": FlightMode.MISSION,
    "UNKNOWN": FlightMode.UNKNOWN,
}


MAVSDK_LOGGER = logging.getLogger("mavsdk")
"""MAVSDK's own messages (its C++ core), plain, through Python's logging: the console, the journal and a log file
get them without the terminal colour codes MAVSDK prints itself."""
_MAVSDK_LEVELS = {0: logging.DEBUG, 1: logging.INFO, 2: logging.WARNING, 3: logging.ERROR}
_routed: list[Any] = []  # the subscribed callback, kept alive while MAVSDK may call it


def route_mavsdk_logs() -> None:
    """Once per process: MAVSDK's log messages go to the ``mavsdk`` logger (at its levels) instead of MAVSDK's own
    coloured output."""
    if _routed:
        return
    from mavsdk.logging import LogLevel, log_subscribe

    def forward(level: LogLevel, message: str, file: str | None, line: int) -> bool:
        MAVSDK_LOGGER.log(_MAVSDK_LEVELS.get(int(level), logging.INFO), "%s", message)
        return True  # MAVSDK prints nothing itself

    log_subscribe(forward)
    _routed.append(forward)


PORT_CHECK_PERIOD_S = 2.0
"""Wall seconds between two looks at who else holds the link's UDP port."""
PROVISIONAL_SYSTEM_ID = 1
"""The companion's MAVLink system id while it looks for an autopilot whose id it is told to take (PX4's default)."""


class MavsdkVehicleLink:
    """:class:`companion.vehicle.link.VehicleLink` over MAVSDK.

    Parameters
    ----------
    url : str
        MAVSDK connection URL (``udpin://0.0.0.0:14540``, ``serial:///dev/ttyTHS1:921600``).
    telemetry_rate_hz : float
        Rate asked for the pose messages.
    system_id : int or None
        The companion's own MAVLink system id, which must be the autopilot's (the companion is a component of the
        vehicle): None takes it from the autopilot's heartbeat at :meth:`connect`; a number that differs from the
        autopilot's is refused there.
    """

    def __init__(self, url: str, telemetry_rate_hz: float = 50.0, system_id: int | None = None) -> None:
        self.name = url
        self.configured_system_id = system_id
        self.system_id = system_id or PROVISIONAL_SYSTEM_ID
        """The companion's MAVLink system id: the autopilot's once connected."""
        self.url = url
        self.telemetry_rate_hz = telemetry_rate_hz
        self.poses = PoseBuffer(capacity=max(50, int(10 * telemetry_rate_hz)))
        self.clock = VehicleClock()
        self.status = VehicleStatus()
        self.dropped_samples = 0
        self.received: dict[str, int] = {}
        """Samples accepted per stream (``LOCAL_POSITION_NED``, ``ATTITUDE_QUATERNION``, ``flight_mode``, ...)."""
        self._mavsdk: Any = None
        self._system: Any = None
        self._tasks: list[asyncio.Task[None]] = []
        self._updated = asyncio.Event()  # set by every telemetry handler

    async def connect(self, timeout_s: float) -> None:
        """Find the autopilot within ``timeout_s`` (wall), take its system id (or refuse a configured one that
        differs) and start the telemetry tasks."""
        deadline = time.monotonic() + timeout_s
        taken = taken_by_another(self.url)
        if taken is not None:
            raise VehicleError(self.url, taken)
        await self._find_autopilot(timeout_s)
        autopilot_id = int(await self._system.get_system_id())
        if autopilot_id != self.system_id:
            if self.configured_system_id is not None:
                await self.close()
                raise VehicleError(
                    self.url,
                    f"the autopilot is system {autopilot_id}, vehicle.system_id says {self.configured_system_id}: the "
                    f"companion must share the autopilot's system id (set it to {autopilot_id}, or leave it out)",
                )
            logger.info("the autopilot is system %d: the companion takes its id", autopilot_id)
            await self.close()  # MAVSDK's own id is set before it connects: again, as the autopilot's component
            self.system_id = autopilot_id
            await self._find_autopilot(max(1.0, deadline - time.monotonic()))
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        self._telemetry = TelemetryAsync(self._system)
        self._direct = MavlinkDirectAsync(self._system)
        for setter in (self._telemetry.set_rate_landed_state, self._telemetry.set_rate_in_air):
            try:
                await asyncio.wait_for(setter(5.0), 5.0)
            except Exception as exc:  # an autopilot may refuse a rate; telemetry still flows at its default
                logger.warning("telemetry rate request refused: %s", exc)
        self._tasks = [
            asyncio.create_task(self._follow(self._direct.subscribe_message("LOCAL_POSITION_NED"), self._on_position)),
            asyncio.create_task(self._follow(self._direct.subscribe_message("ATTITUDE_QUATERNION"), self._on_attitude)),
            asyncio.create_task(self._follow(self._telemetry.subscribe_flight_mode(), self._on_mode)),
            asyncio.create_task(self._follow(self._telemetry.subscribe_armed(), self._on_armed)),
            asyncio.create_task(self._follow(self._telemetry.subscribe_in_air(), self._on_in_air)),
            asyncio.create_task(self._follow(self._telemetry.subscribe_landed_state(), self._on_landed_state)),
            asyncio.create_task(self._follow(self._telemetry.subscribe_health(), self._on_health)),
            asyncio.create_task(self._follow(self._telemetry.subscribe_battery(), self._on_battery)),
            asyncio.create_task(self._follow(self._direct.subscribe_message("HOME_POSITION"), self._on_home)),
            asyncio.create_task(self._watch_port()),
        ]

    async def _watch_port(self) -> None:
        """Every ``PORT_CHECK_PERIOD_S``: a second program bound on the link's port is said once, and kept in
        ``status.port_shared`` (the lost link's reason names it)."""
        while self.status.port_shared is None:
            shared = shared_now(self.url)
            if shared is not None:
                self.status.port_shared = shared
                logger.error("%s", shared)
                return
            await asyncio.sleep(PORT_CHECK_PERIOD_S)

    async def _find_autopilot(self, timeout_s: float) -> None:
        """A MAVSDK instance as component ``COMPANION_COMPUTER`` of ``system_id``, and the first autopilot it finds."""
        from mavsdk.asyncio import Configuration, Mavsdk
        from mavsdk.component_type import ComponentType

        route_mavsdk_logs()
        config = Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER)
        config.system_id = self.system_id
        self._mavsdk = Mavsdk(config)
        try:
            await asyncio.wait_for(self._mavsdk.add_any_connection(self.url), timeout_s)
        except Exception as exc:  # MavsdkConnectionError, bad URL, busy port, missing serial device
            raise VehicleError(self.url, f"cannot open the connection: {exc}") from None
        self._system = await self._mavsdk.first_autopilot(timeout_s=timeout_s)
        if self._system is None:
            raise VehicleError(self.url, f"no autopilot answered within {timeout_s:g} s")

    async def _follow(self, stream: AsyncIterator[Any], handle: Callable[[Any], None]) -> None:
        try:
            async for item in stream:
                handle(item)
                self._updated.set()
        finally:
            close = getattr(stream, "aclose", None)
            if close is not None:
                await close()

    def _fields(self, message: Any) -> dict[str, Any] | None:
        try:
            fields = json.loads(message.fields_json)
        except (json.JSONDecodeError, TypeError):
            self.dropped_samples += 1
            return None
        return fields if isinstance(fields, dict) else None

    def _on_stamped(self, message: Any, add: Callable[[float, dict[str, Any]], None]) -> None:
        """A message stamped with ``time_boot_ms``: into the clock and, through ``add``, into the pose buffer.

        A malformed or out-of-order sample is dropped and counted, never raised.
        """
        f = self._fields(message)
        if f is None:
            return
        try:
            t_s = float(f["time_boot_ms"]) / 1000.0
            self.clock.observe(t_s)
            add(t_s, f)
        except (KeyError, ValueError, TypeError, OverflowError, PoseBufferError) as exc:
            self.dropped_samples += 1
            logger.debug("%s sample dropped: %s", message.message_name, exc)
            return
        self._count(str(message.message_name))
        self.status.last_telemetry_wall_s = time.monotonic()

    def _count(self, stream: str) -> None:
        self.received[stream] = self.received.get(stream, 0) + 1

    def _on_position(self, message: Any) -> None:
        self._on_stamped(
            message, lambda t_s, f: self.poses.add_position(t_s, float(f["x"]), float(f["y"]), float(f["z"]))
        )

    def _on_attitude(self, message: Any) -> None:
        self._on_stamped(
            message,
            lambda t_s, f: self.poses.add_attitude(
                t_s, [float(f["q1"]), float(f["q2"]), float(f["q3"]), float(f["q4"])]
            ),
        )

    def _on_mode(self, mode: Any) -> None:
        new_mode = _MODES.get(getattr(mode, "name", str(mode)), FlightMode.OTHER)
        if new_mode is FlightMode.OFFBOARD and self.status.mode is not FlightMode.OFFBOARD:
            self.status.offboard_entries += 1
        self.status.mode = new_mode
        self._count("flight_mode")

    def _on_armed(self, armed: bool) -> None:
        self.status.armed = bool(armed)
        self._count("armed")

    def _on_in_air(self, in_air: bool) -> None:
        self.status.in_air = bool(in_air)
        self._count("in_air")

    def _on_landed_state(self, state: Any) -> None:
        self.status.landed_state = str(getattr(state, "name", state))

    def _on_health(self, health: Any) -> None:
        self.status.armable = bool(health.is_armable)
        self.status.local_position_ok = bool(health.is_local_position_ok)

    def _on_battery(self, battery: Any) -> None:
        remaining, current = float(battery.remaining_percent), float(battery.current_battery_a)
        self.status.battery_remaining = remaining / 100.0 if math.isfinite(remaining) and remaining >= 0 else None
        self.status.battery_current_a = current if math.isfinite(current) and current >= 0 else None
        self._count("battery")

    def _on_home(self, message: Any) -> None:
        f = self._fields(message)
        try:
            home = (float(f["x"]), float(f["y"])) if f is not None else None
        except (KeyError, ValueError, TypeError):
            home = None
        if home is None or not all(math.isfinite(v) for v in home):
            self.dropped_samples += 1
            return
        self.status.home_ne_m = home
        self._count("HOME_POSITION")

    async def _call(self, what: str, action: Callable[[], Awaitable[Any]], timeout_s: float = 10.0) -> None:
        try:
            await asyncio.wait_for(action(), timeout_s)
        except asyncio.TimeoutError:
            raise VehicleError(self.url, f"{what}: no answer within {timeout_s:g} s") from None
        except Exception as exc:  # MAVSDK's ActionError / OffboardError carry a .result
            raise VehicleError(self.url, f"{what} refused: {getattr(exc, 'result', exc)}") from None

    def _plugins(self) -> tuple[Any, Any]:
        if self._system is None:
            raise VehicleError(self.url, "not connected")
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.offboard import OffboardAsync

        if not hasattr(self, "_action"):
            self._action, self._offboard = ActionAsync(self._system), OffboardAsync(self._system)
        return self._action, self._offboard

    async def arm_and_takeoff(self, altitude_m: float, timeout_s: float) -> None:
        """Wait until armable, arm, take off and wait for ``altitude_m`` (within 0.5 m), all within ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        await self.wait_for(lambda: self.status.armable and self.status.local_position_ok, deadline, "armable")
        await self.take_off(altitude_m)

        def high_enough() -> bool:
            t = self.poses.latest_t_s
            pose = self.poses.pose_at(t) if t is not None else None
            return pose is not None and pose.altitude_m >= altitude_m - 0.5

        await self.wait_for(high_enough, deadline, f"takeoff to {altitude_m:g} m")

    async def take_off(self, altitude_m: float) -> None:
        """Set the takeoff altitude, arm and take off; returns when the autopilot has acknowledged all three."""
        action, _ = self._plugins()
        await self._call("set takeoff altitude", lambda: action.set_takeoff_altitude(altitude_m))
        await self._call("arm", action.arm)
        await self._call("takeoff", action.takeoff)

    async def wait_for(self, condition: Callable[[], bool], deadline: float, what: str) -> None:
        """Wait until ``condition()`` holds, re-checked at every telemetry update, until ``deadline`` (monotonic s).

        Raises
        ------
        VehicleError
            The deadline passed first.
        """
        while not condition():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise VehicleError(self.url, f"timed out waiting for {what}")
            self._updated.clear()
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._updated.wait(), remaining)

    async def start_offboard(self, setpoint: Setpoint) -> None:
        """Send the first setpoint, then ask for OFFBOARD (PX4 wants a setpoint stream first)."""
        _, offboard = self._plugins()
        await self.set_setpoint(setpoint)
        await self._call("offboard start", offboard.start)

    async def set_setpoint(self, setpoint: Setpoint) -> None:
        """One SET_POSITION_TARGET_LOCAL_NED (MAVSDK re-sends it at 20 Hz until the next)."""
        from mavsdk.plugins.offboard import PositionNedYaw

        _, offboard = self._plugins()
        values = (setpoint.north_m, setpoint.east_m, setpoint.down_m, setpoint.yaw_deg)
        if not all(math.isfinite(v) for v in values):
            raise VehicleError(self.url, f"refusing a non-finite setpoint {values}")
        await self._call("setpoint", lambda: offboard.set_position_ned(PositionNedYaw(*values)), 2.0)

    async def stop_offboard(self) -> None:
        """Stop offboard: MAVSDK stops re-sending and the autopilot switches to hold."""
        _, offboard = self._plugins()
        await self._call("offboard stop", offboard.stop)

    def stop_offboard_blocking(self) -> None:
        """Stop offboard from any thread, without the event loop (the stall watchdog's way out)."""
        offboard = getattr(self, "_offboard", None)
        if offboard is None:
            return
        try:
            offboard._plugin.stop()  # the blocking C call under OffboardAsync.stop
        except Exception as exc:  # the watchdog must not die; the autopilot's own failsafe remains
            logger.error("emergency offboard stop failed: %s", exc)

    async def land(self) -> None:
        """Land in place."""
        action, _ = self._plugins()
        await self._call("land", action.land)

    async def hold(self) -> None:
        """Hold (loiter)."""
        action, _ = self._plugins()
        await self._call("hold", action.hold)

    async def return_to_launch(self) -> None:
        """Return to launch."""
        action, _ = self._plugins()
        await self._call("return to launch", action.return_to_launch)

    async def set_actuator(self, index: int, value: float) -> None:
        """An actuator output (see VehicleLink): MAVSDK's ``set_actuator``, which waits for the COMMAND_ACK."""
        action, _ = self._plugins()
        await self._call(f"actuator {index} to {value:g}", lambda: action.set_actuator(index, value), timeout_s=5.0)

    def _connected(self) -> Any:
        """The MAVSDK system; VehicleError when not connected."""
        if self._system is None:
            raise VehicleError(self.url, "not connected")
        return self._system

    async def global_origin(self, timeout_s: float) -> tuple[float, float]:
        """The EKF origin (GPS_GLOBAL_ORIGIN), latitude and longitude in degrees (see VehicleLink)."""
        self._connected()
        return await stored.global_origin(self._telemetry, self.url, timeout_s)

    async def rally_points(self, timeout_s: float) -> list[tuple[float, float]]:
        """The autopilot's rally points, latitude and longitude in degrees (see VehicleLink)."""
        return await stored.rally_points(self._connected(), self.url, timeout_s)

    async def read_parameters(self, timeout_s: float = 15.0) -> dict[str, float] | None:
        """Every parameter of the autopilot by name (:func:`companion.vehicle.mavsdk_stored.parameters`)."""
        return await stored.parameters(self._connected(), self.url, timeout_s)

    async def send_mavlink(self, name: str, fields: dict[str, Any]) -> None:
        """One message through MAVSDK's MAVLink-direct plugin (libmav packs it from the fields' JSON), broadcast: the
        autopilot forwards it to its ground-station link."""
        self._connected()
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        message = MavlinkMessage(message_name=name, fields_json=json.dumps(fields, allow_nan=False))
        try:
            await asyncio.wait_for(self._direct.send_message(message), 2.0)
        except asyncio.TimeoutError:
            raise VehicleError(self.url, f"{name}: not sent within 2 s") from None
        except Exception as exc:  # MavlinkDirectError: an unknown message or field
            raise VehicleError(self.url, f"{name} refused: {getattr(exc, 'result', exc)}") from None

    async def close(self) -> None:
        """Cancel the telemetry tasks and destroy the MAVSDK instance."""
        for task in self._tasks:
            task.cancel()
        if self._tasks:  # each stream's end unsubscribes in MAVSDK: bounded, a link going away must not hold the exit
            _, pending = await asyncio.wait(self._tasks, timeout=CLOSE_TIMEOUT_S)
            if pending:
                logger.warning("%d telemetry streams did not end within %g s", len(pending), CLOSE_TIMEOUT_S)
        self._tasks = []
        if self._mavsdk is not None:
            self._mavsdk.destroy()
            self._mavsdk = None
            self._system = None
