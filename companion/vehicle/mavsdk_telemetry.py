"""The telemetry part of the MAVSDK link: stamped poses, the vehicle's clock and its status.

Poses are stamped with the autopilot's own clock: ``LOCAL_POSITION_NED`` and ``ATTITUDE_QUATERNION`` are read through
the MAVLink-direct plugin so that their ``time_boot_ms`` travels with them into the :class:`PoseBuffer` (MAVSDK's
``position_velocity_ned`` has no timestamp). Mode, armed state, landed state, health and battery come from the
telemetry plugin. A malformed or out-of-order sample is dropped and counted, never raised.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

from companion.vehicle.clock import VehicleClock
from companion.vehicle.link import FlightMode, LinkResult, VehicleError, VehicleStatus
from companion.vehicle.mavsdk_parts import MavsdkSession
from companion.vehicle.port_holders import shared_now
from companion.vehicle.pose_buffer import PoseBuffer, PoseBufferError

logger = logging.getLogger(__name__)

CLOSE_TIMEOUT_S = 3.0  # wall time the telemetry streams get to end when the link closes
PORT_CHECK_PERIOD_S = 2.0
"""Wall seconds between two looks at who else holds the link's UDP port."""

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

POSITION_MESSAGE = "LOCAL_POSITION_NED"
ATTITUDE_MESSAGE = "ATTITUDE_QUATERNION"
HOME_MESSAGE = "HOME_POSITION"


class MavsdkTelemetry:
    """:class:`companion.vehicle.link.Telemetry` from a MAVSDK system.

    Parameters
    ----------
    url : str
        The link's connection URL (named in errors; its port is watched for a second program).
    telemetry_rate_hz : float
        Rate asked for the pose messages (sizes the pose buffer).
    """

    def __init__(self, url: str, telemetry_rate_hz: float) -> None:
        self.url = url
        self.poses = PoseBuffer(capacity=max(50, int(10 * telemetry_rate_hz)))
        self.clock = VehicleClock()
        self.status = VehicleStatus()
        self.dropped_samples = 0
        self.received: dict[str, int] = {}
        """Samples accepted per stream (``LOCAL_POSITION_NED``, ``ATTITUDE_QUATERNION``, ``flight_mode``, ...)."""
        self._tasks: list[asyncio.Task[None]] = []
        self._updated = asyncio.Event()  # set by every telemetry handler

    async def start(self, session: MavsdkSession) -> None:
        """Subscribe to every stream of the session's system, each in a task of its own."""
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        telemetry, direct = session.plugin(TelemetryAsync), session.plugin(MavlinkDirectAsync)
        for setter in (telemetry.set_rate_landed_state, telemetry.set_rate_in_air):
            try:
                await asyncio.wait_for(setter(5.0), 5.0)
            except Exception as exc:  # an autopilot may refuse a rate; telemetry still flows at its default
                logger.warning("telemetry rate request refused: %s", exc)
        self._tasks = [
            asyncio.create_task(self._follow(direct.subscribe_message(POSITION_MESSAGE), self._on_position)),
            asyncio.create_task(self._follow(direct.subscribe_message(ATTITUDE_MESSAGE), self._on_attitude)),
            asyncio.create_task(self._follow(telemetry.subscribe_flight_mode(), self._on_mode)),
            asyncio.create_task(self._follow(telemetry.subscribe_armed(), self._on_armed)),
            asyncio.create_task(self._follow(telemetry.subscribe_in_air(), self._on_in_air)),
            asyncio.create_task(self._follow(telemetry.subscribe_landed_state(), self._on_landed_state)),
            asyncio.create_task(self._follow(telemetry.subscribe_health(), self._on_health)),
            asyncio.create_task(self._follow(telemetry.subscribe_battery(), self._on_battery)),
            asyncio.create_task(self._follow(direct.subscribe_message(HOME_MESSAGE), self._on_home)),
            asyncio.create_task(self._watch_port()),
        ]

    async def stop(self) -> None:
        """Cancel the stream tasks, each stream's end bounded (a link going away must not hold the exit)."""
        for task in self._tasks:
            task.cancel()
        if self._tasks:  # each stream's end unsubscribes in MAVSDK
            _, pending = await asyncio.wait(self._tasks, timeout=CLOSE_TIMEOUT_S)
            if pending:
                logger.warning("%d telemetry streams did not end within %g s", len(pending), CLOSE_TIMEOUT_S)
        self._tasks = []

    async def wait_for(self, condition: Callable[[], bool], deadline: float, what: str) -> None:
        """Wait until ``condition()`` holds, re-checked at every telemetry update, until ``deadline`` (monotonic s).

        Raises
        ------
        VehicleError
            The deadline passed first (:attr:`LinkResult.TIMEOUT`).
        """
        while not condition():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise VehicleError(self.url, f"timed out waiting for {what}", LinkResult.TIMEOUT)
            self._updated.clear()
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._updated.wait(), remaining)

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
        """A message stamped with ``time_boot_ms``: into the clock and, through ``add``, into the pose buffer."""
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
        self._count(HOME_MESSAGE)
