"""People who notice the vehicle's warning and step away (scenario.reaction, issue 53), and the autopilot's actuator
outputs that sound it: the scene is the same with and without the warning until it sounds; then noticers near the
vehicle walk out to the keep-away distance after their reaction time, others walk on exactly as before."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from companion.config import ConfigError, validate_config
from sitl.autopilot.actuators import ActuatorOutputs
from sitl.autopilot.status import MavResult
from sitl.world.crowd import Crowd
from sitl.world.scenario import ScenarioConfig

pytestmark = pytest.mark.unit

TICK_S = 0.1  # the crowd's walk tick at the default 10 Hz


def scenario(**overrides: Any) -> ScenarioConfig:
    settings: dict[str, Any] = {"moving_fraction": 0.2, "walker": "persistent", "reaction": {"enabled": True}}
    return validate_config(ScenarioConfig, {**settings, **overrides}, prefix="scenario")


def distances_m(crowd: Crowd, north_m: float, east_m: float) -> np.ndarray:
    return np.hypot(crowd.positions_ne_m[:, 0] - north_m, crowd.positions_ne_m[:, 1] - east_m)


def test_with_the_reaction_on_the_scene_walks_as_without_it_until_a_warning_sounds() -> None:
    reacting, plain = Crowd(scenario(), 7), Crowd(scenario(reaction={"enabled": False}), 7)
    assert reacting.reaction.reactive.sum() > 0.5 * len(reacting)  # 70 % notice, drawn per person
    assert not plain.reaction.reactive.any()
    for t_s in (0.0, 3.0, 12.5):
        reacting.advance_to(t_s)
        plain.advance_to(t_s)
        np.testing.assert_array_equal(reacting.positions_ne_m, plain.positions_ne_m)
    np.testing.assert_array_equal(reacting.mobile, reacting.moving | reacting.reaction.reactive)


def test_noticers_near_the_vehicle_step_out_to_the_keep_away_distance_after_their_reaction_time() -> None:
    config = scenario()
    reaction = config.reaction
    crowd, silent = Crowd(config, 11), Crowd(config, 11)
    warned_at_s = 4.0
    crowd.advance_to(warned_at_s)
    silent.advance_to(warned_at_s)
    start = crowd.positions_ne_m.copy()
    near = distances_m(crowd, 0.0, 0.0) < reaction.keep_away_m
    stepping = near & crowd.reaction.reactive
    standing = stepping & ~crowd.moving
    assert standing.sum() >= 2, "the scene needs standing noticers near the ROI's centre"
    crowd.warn(warned_at_s, 0.0, 0.0, on=True)

    # Nobody moves before the shortest reaction time: the standing noticers are still where they stood.
    early_s = warned_at_s + reaction.reaction_time_s.low - 2 * TICK_S
    crowd.advance_to(early_s)
    silent.advance_to(early_s)
    np.testing.assert_array_equal(crowd.positions_ne_m[standing], start[standing])

    # Once the slowest has reacted and walked the whole way at the slowest speed, every noticer who was near is out.
    walk_s = reaction.keep_away_m / config.walking_speed_mps.low
    late_s = warned_at_s + reaction.reaction_time_s.high + walk_s + 2 * TICK_S
    crowd.advance_to(late_s)
    silent.advance_to(late_s)
    away = distances_m(crowd, 0.0, 0.0)
    assert np.all(away[stepping] >= reaction.keep_away_m - 1e-6)
    assert np.all(away[stepping] <= reaction.keep_away_m + 1e-6)  # out to it, no farther
    # Straight out: each standing noticer's bearing from the vehicle is kept.
    before = np.arctan2(start[standing, 1], start[standing, 0])
    after = np.arctan2(crowd.positions_ne_m[standing, 1], crowd.positions_ne_m[standing, 0])
    np.testing.assert_allclose(np.angle(np.exp(1j * (after - before))), 0.0, atol=1e-9)
    # Those who do not notice are untouched: standing people stand, walkers walk exactly the silent scene's steps.
    deaf = ~crowd.reaction.reactive
    np.testing.assert_array_equal(crowd.positions_ne_m[deaf], silent.positions_ne_m[deaf])
    assert crowd.reaction.reactions >= stepping.sum()
    assert crowd.reaction.stepped_m > 0.0


def test_a_noticing_walker_outside_the_keep_away_distance_stops_until_the_warning_ends() -> None:
    config = scenario(moving_fraction=0.5)
    crowd = Crowd(config, 5)
    crowd.advance_to(2.0)
    d = distances_m(crowd, 0.0, 0.0)
    watchers = crowd.moving & crowd.reaction.reactive & (d > config.reaction.keep_away_m + 0.5)
    watchers &= d < config.reaction.notice_radius_m - 2.0  # stays within notice range over a tick or two
    assert watchers.any()
    crowd.warn(2.0, 0.0, 0.0, on=True)
    crowd.advance_to(2.0 + config.reaction.reaction_time_s.high + TICK_S)
    held = crowd.positions_ne_m[watchers].copy()
    crowd.advance_to(10.0)
    np.testing.assert_array_equal(crowd.positions_ne_m[watchers], held)  # standing, watching the vehicle
    crowd.warn(10.0, 0.0, 0.0, on=False)
    crowd.advance_to(12.0)
    assert np.all(np.hypot(*(crowd.positions_ne_m[watchers] - held).T) > 0.5)  # walking on


def test_the_same_warnings_give_the_same_steps_however_often_the_crowd_is_advanced() -> None:
    config = scenario()
    coarse, fine = Crowd(config, 3), Crowd(config, 3)
    for crowd, times in ((coarse, [5.0, 20.0]), (fine, [*np.arange(0.05, 20.0, 0.05).tolist(), 20.0])):
        warned = False
        for t_s in times:
            if not warned and t_s >= 5.0:
                crowd.warn(5.0, 1.0, -2.0, on=True)
                warned = True
            crowd.advance_to(float(t_s))
    np.testing.assert_array_equal(coarse.positions_ne_m, fine.positions_ne_m)
    assert coarse.reaction.reactions == fine.reaction.reactions > 0


def test_a_warning_said_again_in_place_changes_nothing_and_one_elsewhere_is_new() -> None:
    repeated, once = Crowd(scenario(), 11), Crowd(scenario(), 11)
    for crowd in (repeated, once):
        crowd.warn(1.0, 0.0, 0.0, on=True)
        crowd.advance_to(6.0)
    repeated.warn(6.0, 0.5, 0.0, on=True)  # the same warning, said again
    for crowd in (repeated, once):
        crowd.advance_to(12.0)
    np.testing.assert_array_equal(repeated.positions_ne_m, once.positions_ne_m)
    assert repeated.reaction.reactions == once.reaction.reactions
    repeated.warn(12.0, 8.0, 8.0, on=True)  # the vehicle moved on: a new warning, which those near it hear
    for crowd in (repeated, once):
        crowd.advance_to(18.0)
    assert repeated.reaction.reactions > once.reaction.reactions


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"notice_share": 1.5}, "scenario.reaction.notice_share"),
        ({"warning_actuator": 7}, "scenario.reaction.warning_actuator"),
        ({"reaction_time_s": {"low": -1.0, "high": 2.0}}, "reaction_time_s must lie in [0, 60] s"),
        ({"keep_away_m": 0.0}, "scenario.reaction.keep_away_m"),
    ],
)
def test_a_bad_reaction_config_names_the_field(overrides: dict[str, Any], message: str) -> None:
    with pytest.raises(ConfigError) as info:
        scenario(reaction={"enabled": True, **overrides})
    assert message in str(info.value)


# -- the autopilot's actuator outputs ------------------------------------------------------------------------------
NAN = math.nan


def test_the_warning_device_sounds_while_its_output_is_above_zero_and_its_listeners_hear_each_switch() -> None:
    outputs = ActuatorOutputs(warning_output=2)
    heard: list[tuple[float, float, float, bool]] = []
    outputs.listeners.append(lambda t, n, e, on: heard.append((t, n, e, on)))
    assert outputs.command([NAN, 1.0, NAN, NAN, NAN, NAN], 0.0, 3.0, 1.0, -2.0) is MavResult.ACCEPTED
    assert outputs.warning_on
    assert outputs.command([0.5, 1.0, NAN, NAN, NAN, NAN], 0.0, 3.5, 1.0, -2.0) is MavResult.ACCEPTED  # still on
    assert outputs.values[:2] == [0.5, 1.0]
    assert outputs.command([NAN, NAN, NAN, NAN, NAN, NAN], NAN, 4.0, 1.0, -2.0) is MavResult.ACCEPTED  # no change
    assert outputs.command([NAN, -1.0, NAN, NAN, NAN, NAN], 0.0, 9.0, 1.5, -2.0) is MavResult.ACCEPTED
    assert not outputs.warning_on
    assert heard == [(3.0, 1.0, -2.0, True), (9.0, 1.5, -2.0, False)]
    assert outputs.warnings == 1


@pytest.mark.parametrize(
    ("params", "actuator_set"),
    [
        ([2.0, NAN, NAN, NAN, NAN, NAN], 0.0),  # outside [-1, 1]
        ([math.inf, NAN, NAN, NAN, NAN, NAN], 0.0),
        ([1.0, NAN, NAN, NAN, NAN, NAN], 1.0),  # PX4 has one actuator set
        ([1.0, NAN, NAN, NAN, NAN, NAN], math.inf),
    ],
)
def test_a_bad_actuator_command_is_denied_and_changes_no_output(params: list[float], actuator_set: float) -> None:
    outputs = ActuatorOutputs(warning_output=1)
    assert outputs.command(params, actuator_set, 1.0, 0.0, 0.0) is MavResult.DENIED
    assert outputs.values == [0.0] * 6
    assert not outputs.warning_on
