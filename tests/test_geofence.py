"""Geofence: inside/outside, clamping to the nearest allowed point, and config errors that name the field."""

from __future__ import annotations

import pytest

from companion.app.mission import MissionConfig
from companion.config import ConfigError, validate_config
from companion.guidance.geofence import Geofence, GeofenceConfig

pytestmark = pytest.mark.unit


def test_inside_outside_and_altitude_band() -> None:
    fence = Geofence(
        GeofenceConfig(polygon_ne_m=[(0, 0), (0, 10), (10, 10), (10, 0)], min_altitude_m=2, max_altitude_m=30)
    )
    assert fence.contains(5, 5, 10)
    assert fence.contains(0, 5, 10)  # on the boundary
    assert not fence.contains(11, 5, 10)
    assert not fence.contains(5, 5, 31)
    assert not fence.contains(5, 5, 1)
    assert fence.distance_inside_m(5, 2) == pytest.approx(2.0)
    assert fence.distance_inside_m(-3, 5) == pytest.approx(-3.0)


def test_a_concave_fence_and_clamping() -> None:
    l_shape = [(0.0, 0.0), (0.0, 20.0), (10.0, 20.0), (10.0, 10.0), (20.0, 10.0), (20.0, 0.0)]
    fence = Geofence(GeofenceConfig(polygon_ne_m=l_shape, max_altitude_m=40))
    assert fence.contains_ne(15, 5)
    assert not fence.contains_ne(15, 15)  # the notch
    n, e, alt = fence.clamp(15.0, 16.0, 55.0)
    assert fence.contains(n, e, alt)
    assert alt == 40.0
    assert (n, e) == pytest.approx((10.0, 16.0), abs=0.02)  # the nearest edge is the notch's north side
    assert fence.clamp(5.0, 5.0, 10.0) == (5.0, 5.0, 10.0)


def test_bad_fences_are_named() -> None:
    with pytest.raises(ConfigError, match=r"geofence\.polygon_ne_m"):
        validate_config(GeofenceConfig, {"polygon_ne_m": [(0, 0), (1, 1)]}, prefix="geofence")
    with pytest.raises(ConfigError, match="max_altitude_m"):
        validate_config(GeofenceConfig, {"min_altitude_m": 50, "max_altitude_m": 40}, prefix="geofence")
    with pytest.raises(ConfigError, match="1 m"):
        validate_config(GeofenceConfig, {"polygon_ne_m": [(0, 0), (0, 1), (0, 2)]}, prefix="geofence")


def test_a_landing_area_must_lie_inside_the_geofence() -> None:
    fence = {"polygon_ne_m": [(-25.0, -25.0), (-25.0, 25.0), (25.0, 25.0), (25.0, -25.0)]}
    roi = [(-15.0, -15.0), (-15.0, 15.0), (15.0, 15.0), (15.0, -15.0)]
    config = validate_config(
        MissionConfig, {"geofence": fence, "perception": {"zones": {"landing_area_ne_m": roi}}}, prefix="mission"
    )
    assert config.perception.zones.landing_area_ne_m == roi
    beyond = [*roi[:2], (30.0, 15.0), roi[3]]
    with pytest.raises(ConfigError, match=r"landing_area_ne_m vertex \(30.0, 15.0\) lies outside geofence") as caught:
        validate_config(
            MissionConfig,
            {
                "geofence": fence,
                "perception": {"zones": {"landing_area_ne_m": beyond}},
                "start": {"start_north_m": 90.0, "start_east_m": 0.0},
            },
        )
    # Each contradiction is a line of its own, in the validator's words, without pydantic's "<root>: Value error,".
    lines = caught.value.problems
    assert any(line.startswith("perception.zones.landing_area_ne_m vertex (30.0, 15.0)") for line in lines), lines
    assert any(line.startswith("start.start_north_m, start.start_east_m (90.0, 0.0)") for line in lines), lines
    assert not any("Value error" in line or "<root>" in line for line in lines), lines


def test_latitude_and_longitude_project_as_px4_does_into_the_local_frame() -> None:
    from companion.guidance.geofence import latlon_to_ne_m
    from sitl.geodesy import geodetic_to_ned, ned_to_geodetic

    lat0, lon0 = 47.397742, 8.545594
    assert latlon_to_ne_m(lat0, lon0, lat0, lon0) == (0.0, 0.0)
    for north_m, east_m in ((100.0, 0.0), (0.0, 100.0), (-60.0, 80.0), (500.0, -300.0)):
        lat, lon, _ = ned_to_geodetic(north_m, east_m, 0.0, lat0, lon0, 0.0)
        n, e = latlon_to_ne_m(lat, lon, lat0, lon0)
        want_n, want_e, _ = geodetic_to_ned(lat, lon, 0.0, lat0, lon0, 0.0)
        # PX4's sphere against the SITL's WGS-84 radii at the origin (meridian and prime vertical): 0.3 % at most
        assert abs(n - want_n) <= 3e-3 * abs(want_n) + 0.01
        assert abs(e - want_e) <= 3e-3 * abs(want_e) + 0.01


def test_a_fence_is_given_once_in_local_ned_or_in_latitude_and_longitude() -> None:
    corners = [(47.0, 8.0), (47.0, 8.001), (47.001, 8.001)]
    config = GeofenceConfig.model_validate({"polygon_latlon_deg": corners})
    assert config.polygon_latlon_deg == corners
    with pytest.raises(ValueError, match="give polygon_ne_m or polygon_latlon_deg, not both"):
        GeofenceConfig.model_validate({"polygon_latlon_deg": corners, "polygon_ne_m": [(0, 0), (0, 5), (5, 5)]})
    with pytest.raises(ValueError, match=r"vertex \(97.0, 8.0\) is not a latitude and longitude"):
        GeofenceConfig.model_validate({"polygon_latlon_deg": [(97.0, 8.0), *corners[1:]]})
