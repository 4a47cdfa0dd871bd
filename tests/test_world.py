"""The simulated world: scenario validation, seeded crowds, the paper's random walk, weather."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from companion.config import ConfigError, validate_config
from sitl.world.crowd import BodyType, Crowd, CrowdError
from sitl.world.park import ObjectKind, Park
from sitl.world.scenario import ScenarioConfig, WalkerKind, WeatherKind
from sitl.world.weather import WeatherSchedule, WeatherState, apply_weather

pytestmark = pytest.mark.unit


def scenario(**overrides: Any) -> ScenarioConfig:
    return validate_config(ScenarioConfig, overrides, prefix="scenario")


# -- scenario --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"people_max": 5000}, "people_max (5000) cannot be placed without overlap in a 30.0 m square"),
        ({"people_min": 130, "people_max": 120}, "people_min (130) must be <= people_max (120)"),
        ({"person_radius_m": {"low": -0.2, "high": 0.3}}, "person_radius_m must lie in (0, 2]"),
        ({"person_radius_m": {"low": 0.4, "high": 0.3}}, "scenario.person_radius_m"),
        ({"weather": ["hail"]}, "scenario.weather.0: Input should be 'clear', 'fog', 'rain', 'snow', 'dust' or 'dusk'"),
        ({"roi_side_m": -30}, "scenario.roi_side_m: Input should be greater than 0"),
        ({"moving_fraction": 1.5}, "scenario.moving_fraction: Input should be less than or equal to 1"),
        ({"start_altitude_m": {"low": 1, "high": 10}}, "start_altitude_m must stay above 2 m"),
    ],
)
def test_impossible_scenarios_are_rejected_naming_the_field(overrides: dict[str, Any], message: str) -> None:
    with pytest.raises(ConfigError) as info:
        scenario(**overrides)
    assert message in str(info.value)


def test_paper_defaults() -> None:
    config = ScenarioConfig()
    assert config.roi_side_m == 30.0
    assert (config.people_min, config.people_max) == (80, 120)
    assert (config.lattice_step_m, config.walk_rate_hz) == (0.2, 10.0)


# -- crowds ----------------------------------------------------------------------------------------------------
def test_crowd_is_seeded_non_overlapping_and_varied() -> None:
    config = ScenarioConfig()
    a, b, c = Crowd(config, 7), Crowd(config, 7), Crowd(config, 8)
    assert 80 <= len(a) <= 120
    np.testing.assert_array_equal(a.positions_ne_m, b.positions_ne_m)
    assert a.appearances == b.appearances
    assert len(a) != len(c) or not np.array_equal(a.positions_ne_m, c.positions_ne_m)
    d = np.hypot(*(a.positions_ne_m[:, None, :] - a.positions_ne_m[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    assert np.all(d >= a.radii_m[:, None] + a.radii_m[None, :] + config.min_gap_m - 1e-9)
    assert np.all(np.abs(a.positions_ne_m) + a.radii_m[:, None] <= 15.0 + 1e-9)
    bodies = {p.body for seed in range(5) for p in Crowd(config, seed).appearances}
    assert len(bodies) >= 12
    assert len(BodyType) >= 12
    assert any(p.hat_bgr is not None for p in a.appearances)
    assert {p.pattern for p in a.appearances} >= {"solid", "striped"}
    assert any(p.height_m < 1.45 for p in a.appearances)  # children


def test_moving_fraction_is_exact() -> None:
    crowd = Crowd(ScenarioConfig(moving_fraction=0.2), 3)
    assert crowd.moving.sum() == round(0.2 * len(crowd))


def test_a_crowd_that_cannot_fit_fails_clearly() -> None:
    # Past validation (which would refuse it): the generator must still fail clearly, not loop.
    config = ScenarioConfig().model_copy(update={"roi_side_m": 3.0, "people_min": 60, "people_max": 60})
    with pytest.raises(CrowdError, match="could place only"):
        Crowd(config, 0)


def walkers(walker: WalkerKind = WalkerKind.LATTICE) -> Crowd:
    """1000 people, all moving, far apart (a 400 m square): free walks for statistics."""
    config = ScenarioConfig(roi_side_m=400.0, people_min=1000, people_max=1000, moving_fraction=1.0, walker=walker)
    return Crowd(config, 11)


def test_lattice_walk_steps_rate_and_mean_squared_displacement() -> None:
    crowd = walkers()
    start = crowd.positions_ne_m.copy()
    crowd.advance_to(0.099)
    np.testing.assert_array_equal(crowd.positions_ne_m, start)  # nothing before the first 0.1 s tick
    crowd.advance_to(0.1)
    step = crowd.positions_ne_m - start
    assert set(np.round(np.unique(step), 9)) <= {-0.2, 0.0, 0.2}  # 0.2 m * alpha, alpha in {-1, 0, 1}
    fractions = [np.mean(np.isclose(step, v)) for v in (-0.2, 0.0, 0.2)]
    assert fractions == pytest.approx([1 / 3, 1 / 3, 1 / 3], abs=0.03)
    # Mean squared displacement grows linearly: per axis 0.2^2 * 2/3 per tick, 10 ticks a second, two axes.
    expected_rate_m2ps = 2 * 0.2**2 * (2 / 3) * 10
    crowd.advance_to(10.0)
    msd10 = float(np.mean(np.sum((crowd.positions_ne_m - start) ** 2, axis=1)))
    crowd.advance_to(20.0)
    msd20 = float(np.mean(np.sum((crowd.positions_ne_m - start) ** 2, axis=1)))
    assert msd10 == pytest.approx(expected_rate_m2ps * 10, rel=0.1)
    assert msd20 == pytest.approx(expected_rate_m2ps * 20, rel=0.1)


def test_walks_do_not_depend_on_how_often_time_is_advanced() -> None:
    coarse, fine = walkers(), walkers()
    coarse.advance_to(7.3)
    for k in range(1, 731):
        fine.advance_to(k * 0.01)
    np.testing.assert_array_equal(coarse.positions_ne_m, fine.positions_ne_m)
    with pytest.raises(CrowdError, match="backwards"):
        fine.advance_to(1.0)


def test_persistent_walkers_keep_their_speed_and_turn_slowly() -> None:
    crowd = walkers(WalkerKind.PERSISTENT)
    before = crowd.positions_ne_m.copy()
    crowd.advance_to(0.1)
    speed = np.hypot(*(crowd.positions_ne_m - before).T) / 0.1
    assert speed.min() >= 0.8 - 1e-9
    assert speed.max() <= 1.6 + 1e-9
    # Over 1 s (well under the 5 s persistence) people keep walking nearly straight: net/path length near 1.
    p0 = crowd.positions_ne_m.copy()
    path = np.zeros(len(crowd))
    previous = p0
    for k in range(2, 12):
        crowd.advance_to(k * 0.1)
        path += np.hypot(*(crowd.positions_ne_m - previous).T)
        previous = crowd.positions_ne_m.copy()
    straightness = np.hypot(*(crowd.positions_ne_m - p0).T) / path
    assert np.median(straightness) > 0.95


def test_clearance() -> None:
    crowd = Crowd(ScenarioConfig(), 1)
    n, e = crowd.positions_ne_m[0]
    assert crowd.clearance_m(n, e) == pytest.approx(-crowd.radii_m[0])
    assert math.isinf(Crowd(ScenarioConfig(people_min=0, people_max=0), 1).clearance_m(0, 0))


# -- weather ---------------------------------------------------------------------------------------------------
def park_frame() -> np.ndarray:
    rng = np.random.default_rng(0)
    frame = np.zeros((120, 160, 3), dtype=np.uint8)
    frame[:] = (60, 120, 70)
    frame += rng.integers(0, 30, size=frame.shape, dtype=np.uint8)
    frame[40:60, 50:70] = (30, 30, 200)  # a red jacket
    return frame


@pytest.mark.parametrize("kind", list(WeatherKind))
def test_weather_is_deterministic_and_zero_strength_is_clear(kind: WeatherKind) -> None:
    frame = park_frame()
    a = apply_weather(frame, WeatherState(kind, 0.7), frame_seed=5)
    b = apply_weather(frame, WeatherState(kind, 0.7), frame_seed=5)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(apply_weather(frame, WeatherState(kind, 0.0), frame_seed=5), frame)
    assert a.shape == frame.shape
    assert a.dtype == np.uint8


def test_each_effect_does_what_its_name_says() -> None:
    frame = park_frame().astype(np.float32)

    def see(kind: WeatherKind, depth: np.ndarray | None = None) -> np.ndarray:
        return apply_weather(frame.astype(np.uint8), WeatherState(kind, 0.8), 1, depth).astype(np.float32)

    fog = see(WeatherKind.FOG)
    assert fog.std() < 0.5 * frame.std()
    assert fog.mean() > frame.mean() + 50
    depth = np.tile(np.linspace(5, 60, 160, dtype=np.float32), (120, 1))
    deep_fog = see(WeatherKind.FOG, depth)
    assert deep_fog[:, -10:].mean() > deep_fog[:, :10].mean() + 20  # thicker far away
    assert see(WeatherKind.DUSK).mean() < 0.6 * frame.mean()
    snow = see(WeatherKind.SNOW)
    assert (snow.min(axis=2) > 230).mean() > 0.02  # white flakes
    rain = see(WeatherKind.RAIN)
    assert (rain.min(axis=2) > 140).mean() > 0.005  # bright streaks
    assert np.median(rain) < np.median(frame)  # and a darker scene
    dust = see(WeatherKind.DUST)
    assert (dust[..., 2] - dust[..., 0]).mean() > (frame[..., 2] - frame[..., 0]).mean() + 20  # browner


def test_dynamic_weather_changes_at_the_period_and_is_seeded() -> None:
    config = ScenarioConfig(weather=list(WeatherKind), dynamic_weather=True, weather_period_s=20.0)
    schedule, again = WeatherSchedule(config, 4), WeatherSchedule(config, 4)
    states = [schedule.state_at(t) for t in np.arange(0.0, 200.0, 5.0)]
    assert states == [again.state_at(t) for t in np.arange(0.0, 200.0, 5.0)]
    assert all(states[k] == states[k - k % 4] for k in range(len(states)))  # constant within each 20 s
    assert len({s.kind for s in states}) >= 3  # it changes
    assert all(
        config.weather_strength.low <= s.strength <= config.weather_strength.high
        for s in states
        if s.kind is not WeatherKind.CLEAR
    )
    fixed = WeatherSchedule(ScenarioConfig(weather=[WeatherKind.FOG]), 4)
    assert fixed.state_at(0.0) == fixed.state_at(500.0)


@pytest.mark.parametrize("seed", [1, 2026, 3484895844])
def test_the_park_layout_alone_has_the_same_objects_as_the_painted_park(seed: int) -> None:
    # Metrics rebuild the park of a mission flown long ago from its seed, without painting its texture.
    painted, layout = Park(seed), Park(seed, paint=False)
    assert layout.objects == painted.objects
    assert {o.kind for o in layout.objects} >= {ObjectKind.TREE, ObjectKind.BENCH, ObjectKind.DARK_BLOB}
    assert painted.painted
    assert not layout.painted
    assert layout.ground_bgr.shape == (1, 1, 3)
    assert painted.ground_bgr.shape == (1800, 1800, 3)


def test_the_scene_light_comes_from_the_seed_within_the_scenario_ranges() -> None:
    """The light a mission's camera draws with is a function of its seed (the same for a replay and a benchmark that
    reads the mission's config), and its sun lies within the scenario's elevation range."""
    from sitl.config import SitlConfig
    from sitl.render.camera import Light
    from sitl.vehicle.sim_camera import scene_light

    low_sun = ScenarioConfig.model_validate({"sun_elevation_deg": {"low": 20.0, "high": 30.0}})
    lights = [scene_light(SitlConfig(seed=seed, scenario=low_sun)) for seed in range(20)]
    assert all(20.0 <= light.elevation_deg <= 30.0 for light in lights)
    assert scene_light(SitlConfig(seed=7, scenario=low_sun)).key == lights[7].key
    assert len({light.key for light in lights}) == 20
    assert math.isclose(Light.from_angles(25.0, 140.0, 0.3).elevation_deg, 25.0)


def test_ground_kept_clear_gets_no_object_and_an_empty_list_changes_nothing() -> None:
    sites = [(20.0, 20.0, 4.0), (-20.0, -20.0, 4.0), (12.0, -12.0, 3.0)]
    solid_on_a_site = 0  # scenes whose plain park has a solid object on a site
    for seed in range(6):
        plain, empty = Park(seed, paint=False), Park(seed, paint=False, clear_ne_m=[])
        assert plain.objects == empty.objects  # the draws of every existing scene are unchanged
        solid_on_a_site += any(
            o.footprint_distance_m(n, e) <= r and o.kind not in (ObjectKind.DARK_BLOB, ObjectKind.BRIGHT_BLOB)
            for o in plain.objects
            for n, e, r in sites
        )
        cleared = Park(seed, paint=False, clear_ne_m=sites)
        for o in cleared.objects:
            for north_m, east_m, radius_m in sites:
                assert o.footprint_distance_m(north_m, east_m) > radius_m - 1e-9 or o.kind in (
                    ObjectKind.DARK_BLOB,
                    ObjectKind.BRIGHT_BLOB,
                ), (seed, o)
    assert solid_on_a_site > 0  # without the clear ground, sites are built over
    scenario = ScenarioConfig.model_validate({"clear_ne_m": [[20.0, 20.0, 4.0]]})
    assert scenario.clear_ne_m == [(20.0, 20.0, 4.0)]
