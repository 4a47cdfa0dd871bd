"""The safety filter every setpoint of the landing logic goes through (:mod:`companion.guidance.landing`)."""

from __future__ import annotations

import math

from companion.guidance.config import GuidanceConfig
from companion.guidance.geofence import Geofence
from companion.guidance.vehicle_state import VehicleState
from companion.vehicle.link import Setpoint


def filtered_setpoint(
    config: GuidanceConfig,
    geofence: Geofence,
    state: VehicleState,
    north_m: float,
    east_m: float,
    altitude_m: float,
    yaw_deg: float,
) -> Setpoint:
    """A position setpoint (local NED) towards ``north_m``, ``east_m``, ``altitude_m`` (above home) from ``state``:
    at most ``max_step_m`` away horizontally, never more than ``descent_rate_limit_mps *
    autopilot_z_time_constant_s`` below the vehicle (a position controller with that time constant then descends no
    faster than the limit), and clamped into the geofence, in that order."""
    c = config
    dn, de = north_m - state.north_m, east_m - state.east_m
    dist = math.hypot(dn, de)
    if dist > c.max_step_m:
        north_m, east_m = state.north_m + dn * c.max_step_m / dist, state.east_m + de * c.max_step_m / dist
    lowest = state.altitude_m - c.descent_rate_limit_mps * c.autopilot_z_time_constant_s
    altitude_m = max(altitude_m, lowest)
    north_m, east_m, altitude_m = geofence.clamp(north_m, east_m, altitude_m)
    return Setpoint(north_m, east_m, -altitude_m, yaw_deg)
