"""Local NED <-> geodetic coordinates around an origin (flat-earth on the WGS-84 ellipsoid; metres-accurate
within a few kilometres, which is the SITL's scale)."""

from __future__ import annotations

import math

WGS84_A_M = 6378137.0
WGS84_E2 = 6.69437999014e-3


def ned_to_geodetic(
    north_m: float, east_m: float, down_m: float, lat0_deg: float, lon0_deg: float, alt0_m: float
) -> tuple[float, float, float]:
    """(lat_deg, lon_deg, alt_m AMSL) of a local NED point relative to the origin (lat0, lon0, alt0)."""
    lat0 = math.radians(lat0_deg)
    s = math.sin(lat0)
    r_n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s * s)  # prime vertical radius
    r_m = r_n * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * s * s)  # meridian radius
    lat = lat0_deg + math.degrees(north_m / r_m)
    lon = lon0_deg + math.degrees(east_m / (r_n * math.cos(lat0)))
    return lat, lon, alt0_m - down_m


def geodetic_to_ned(
    lat_deg: float, lon_deg: float, alt_m: float, lat0_deg: float, lon0_deg: float, alt0_m: float
) -> tuple[float, float, float]:
    """Inverse of :func:`ned_to_geodetic`."""
    lat0 = math.radians(lat0_deg)
    s = math.sin(lat0)
    r_n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s * s)
    r_m = r_n * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * s * s)
    north = math.radians(lat_deg - lat0_deg) * r_m
    east = math.radians(lon_deg - lon0_deg) * r_n * math.cos(lat0)
    return north, east, alt0_m - alt_m
