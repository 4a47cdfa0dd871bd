"""The autopilot's rally points as fallback sites (``guidance.fallback.rally_points``), at the flight's start.

A ground station uploads rally points with the rally protocol (QGroundControl's rally tool, MAVProxy's ``rally``
module); the companion downloads them once connected, projects each into local NED from the autopilot's EKF origin
(as a fence in latitude and longitude is) and adds it to the mission's fallback sites (:mod:`companion.guidance
.fallback`) as ``rally_1``, ``rally_2``, ... with ``rally_radius_m``. One whose footprint would leave the fence is
dropped, with a warning: the companion never commands outside its fence. A ``fallback_sites`` record keeps every
site the flight used; a replay reads it.
"""

from __future__ import annotations

import logging

from companion.app.mission import MissionConfig, with_fallback_sites
from companion.flightlog.flight_log import RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.guidance.geofence import Geofence, latlon_to_ne_m
from companion.json_value import JsonObject
from companion.vehicle.link import MissionStore

logger = logging.getLogger(__name__)


async def with_rally_sites(config: MissionConfig, mission: MissionStore, recorder: FlightRecorder) -> MissionConfig:
    """The config with the autopilot's rally points among its fallback sites (see the module docstring); its fence
    must be in local NED already."""
    timeout_s = config.vehicle.connect_timeout_s
    fallback = config.guidance.fallback
    sites: list[JsonObject] = [site.model_dump(mode="json") for site in fallback.sites]
    points = await mission.rally_points(timeout_s)
    if points:
        lat0, lon0 = await mission.global_origin(timeout_s)
        fence = Geofence(config.geofence)
        footprint_m = config.perception.zones.min_radius_m
        for k, (lat, lon) in enumerate(points, start=1):
            north_m, east_m = latlon_to_ne_m(lat, lon, lat0, lon0)
            if fence.distance_inside_m(north_m, east_m) < footprint_m:
                logger.warning(
                    "rally point %d (north %.1f m, east %.1f m): outside the fence, not a site", k, north_m, east_m
                )
                continue
            radius_m = max(fallback.rally_radius_m, footprint_m)
            sites.append({"name": f"rally_{k}", "north_m": north_m, "east_m": east_m, "radius_m": radius_m})
    logger.info("fallback sites: %d (%d rally points downloaded)", len(sites), len(points))
    recorder.write(RecordKind.FALLBACK_SITES, None, sites=sites, rally_points=len(points))
    return with_fallback_sites(config, sites)
