"""The vehicle link through MAVSDK (``mavsdk`` 4.x, ``mavsdk.asyncio``), in parts as MAVSDK's ``System`` has plugins:
telemetry (:mod:`companion.vehicle.mavsdk_telemetry`), action, offboard, mission, params and ground
(:mod:`companion.vehicle.mavsdk_parts`). This module finds the autopilot, takes its system id and starts the
telemetry. MAVSDK re-sends the last offboard setpoint on its own thread; the application's watchdog stops offboard
when its own decision loop stalls. One ``Mavsdk`` instance per process (MAVSDK's own advice).
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import Any

from companion.vehicle.link import LinkResult, VehicleError
from companion.vehicle.mavsdk_parts import (
    MavsdkAction,
    MavsdkGround,
    MavsdkMission,
    MavsdkOffboard,
    MavsdkParams,
    MavsdkSession,
)
from companion.vehicle.mavsdk_telemetry import MavsdkTelemetry
from companion.vehicle.port_holders import taken_by_another

logger = logging.getLogger(__name__)

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
        self._session = MavsdkSession(url)
        self.telemetry = MavsdkTelemetry(url, telemetry_rate_hz)
        self.action = MavsdkAction(self._session, self.telemetry)
        self.offboard = MavsdkOffboard(self._session)
        self.mission = MavsdkMission(self._session)
        self.params = MavsdkParams(self._session)
        self.ground = MavsdkGround(self._session)
        self._mavsdk: Any = None

    async def connect(self, timeout_s: float) -> None:
        """Find the autopilot within ``timeout_s`` (wall), take its system id (or refuse a configured one that
        differs) and start the telemetry."""
        deadline = time.monotonic() + timeout_s
        taken = taken_by_another(self.name)
        if taken is not None:
            raise VehicleError(self.name, taken, LinkResult.CONNECTION_ERROR)
        system = await self._find_autopilot(timeout_s)
        autopilot_id = int(await system.get_system_id())
        if autopilot_id != self.system_id:
            if self.configured_system_id is not None:
                await self.close()
                raise VehicleError(
                    self.name,
                    f"the autopilot is system {autopilot_id}, vehicle.system_id says {self.configured_system_id}: the "
                    f"companion must share the autopilot's system id (set it to {autopilot_id}, or leave it out)",
                    LinkResult.INVALID,
                )
            logger.info("the autopilot is system %d: the companion takes its id", autopilot_id)
            await self.close()  # MAVSDK's own id is set before it connects: again, as the autopilot's component
            self.system_id = autopilot_id
            system = await self._find_autopilot(max(1.0, deadline - time.monotonic()))
        self._session.attach(system)
        await self.telemetry.start(self._session)

    async def _find_autopilot(self, timeout_s: float) -> Any:
        """A MAVSDK instance as component ``COMPANION_COMPUTER`` of ``system_id``, and the first autopilot it finds."""
        from mavsdk.asyncio import Configuration, Mavsdk
        from mavsdk.component_type import ComponentType

        route_mavsdk_logs()
        config = Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER)
        config.system_id = self.system_id
        self._mavsdk = Mavsdk(config)
        try:
            await asyncio.wait_for(self._mavsdk.add_any_connection(self.name), timeout_s)
        except Exception as exc:  # MavsdkConnectionError, bad URL, busy port, missing serial device
            raise VehicleError(self.name, f"cannot open the connection: {exc}", LinkResult.CONNECTION_ERROR) from None
        system = await self._mavsdk.first_autopilot(timeout_s=timeout_s)
        if system is None:
            raise VehicleError(self.name, f"no autopilot answered within {timeout_s:g} s", LinkResult.TIMEOUT)
        return system

    async def close(self) -> None:
        """Stop the telemetry and destroy the MAVSDK instance."""
        await self.telemetry.stop()
        self._session.attach(None)
        if self._mavsdk is not None:
            self._mavsdk.destroy()
            self._mavsdk = None
