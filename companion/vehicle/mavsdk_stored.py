"""What the autopilot stores and the companion reads once, through MAVSDK: its EKF origin, its rally points, its
parameters (for :class:`~companion.vehicle.mavsdk_link.MavsdkVehicleLink`, which passes its MAVSDK system and
telemetry plugin). Each read is bounded by ``timeout_s`` (wall) and fails with a :class:`VehicleError` naming the
vehicle's URL and what was missing, but the parameter list, whose absence is ``None`` (the doctor says so)."""

from __future__ import annotations

import asyncio
import logging
import math
from typing import Any

from companion.vehicle.link import VehicleError

logger = logging.getLogger(__name__)


async def global_origin(telemetry: Any, url: str, timeout_s: float) -> tuple[float, float]:
    """The EKF origin (GPS_GLOBAL_ORIGIN): latitude and longitude, degrees."""
    try:
        origin = await asyncio.wait_for(telemetry.get_gps_global_origin(), timeout_s)
    except asyncio.TimeoutError:
        raise VehicleError(url, f"no GPS_GLOBAL_ORIGIN within {timeout_s:g} s") from None
    except Exception as exc:  # TelemetryError: the autopilot has no origin yet
        raise VehicleError(url, f"no GPS_GLOBAL_ORIGIN: {exc}") from None
    lat, lon = float(origin.latitude_deg), float(origin.longitude_deg)
    if not (math.isfinite(lat) and math.isfinite(lon)):
        raise VehicleError(url, "GPS_GLOBAL_ORIGIN not set (no GPS fix yet?)")
    return lat, lon


async def rally_points(system: Any, url: str, timeout_s: float) -> list[tuple[float, float]]:
    """The autopilot's rally points: latitude and longitude, degrees."""
    from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync

    try:
        items = await asyncio.wait_for(MissionRawAsync(system).download_rallypoints(), timeout_s)
    except asyncio.TimeoutError:
        raise VehicleError(url, f"no rally point list within {timeout_s:g} s") from None
    except Exception as exc:  # MissionRawError: the autopilot refused or timed out the download
        raise VehicleError(url, f"rally points not downloaded: {exc}") from None
    return [(item.x * 1e-7, item.y * 1e-7) for item in items]


async def parameters(system: Any, url: str, timeout_s: float) -> dict[str, float] | None:
    """Every parameter of the autopilot by name (integers as floats), from one list request; None when the list
    does not arrive within ``timeout_s``. Asking for the list, not for names it may lack, leaves no retries and no
    "Retrying failed" errors for a parameter that another autopilot version names differently."""
    from mavsdk.asyncio.plugins.param import ParamAsync

    try:
        every = await asyncio.wait_for(ParamAsync(system).get_all_params(), timeout_s)
    except asyncio.TimeoutError:
        return None
    except Exception as exc:  # ParamError: the list could not be read
        logger.warning("%s: the parameter list could not be read: %s", url, exc)
        return None
    values = {p.name: float(p.value) for p in every.int_params}
    values.update({p.name: float(p.value) for p in every.float_params})
    return values
