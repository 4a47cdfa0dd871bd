"""The energy budget (issue 53): the companion's search budget from the battery the autopilot reports, and the
SITL's battery with PX4's battery failsafe. Unit tests, no processes: the flight is in tests/test_energy_flight.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.config import ConfigError, validate_config
from companion.guidance.config import EnergyConfig, FailsafeAction, GuidanceConfig
from companion.guidance.energy import EnergyBudget
from companion.guidance.geofence import Geofence, GeofenceConfig
from companion.guidance.landing import CommandKind, LandingGuidance, LandingPhase
from companion.guidance.stimulus import EnergyLow, Started
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent
from companion.perception.selection import BiggestPolicy
from companion.vehicle.link import VehicleStatus
from sitl.autopilot.battery import Battery, BatteryLevel, BatteryMonitor, failsafe_action, level_of
from sitl.autopilot.commander import Commander
from sitl.autopilot.modes import FlightMode
from sitl.autopilot.params import ParameterStore
from sitl.autopilot.status import LandedState, MavResult
from sitl.dynamics.base import VehicleState as SimState

pytestmark = pytest.mark.unit

PACK = EnergyConfig(enabled=True, capacity_mah=5000.0, reserve_fraction=0.25)


def _at(north_m: float, east_m: float, altitude_m: float, t_s: float = 100.0) -> VehicleState:
    return VehicleState(t_s, north_m, east_m, -altitude_m, 0.0)


# -- the companion's budget ---------------------------------------------------------------------------------------


def test_the_budget_is_the_charge_above_the_reserve_at_the_current_drawn_less_the_way_home() -> None:
    budget = EnergyBudget(PACK)
    budget.observe(0.0, 15.0)
    estimate = budget.estimate(_at(30.0, 40.0, 20.0), remaining=0.5, home_ne_m=(0.0, 0.0))
    assert estimate is not None
    # 25 % of 5000 mAh at 15 A: 300 s; home 50 m at 5 m/s and 20 m down at 1 m/s, times 1.3: 39 s.
    assert estimate.seconds_left == pytest.approx(300.0)
    assert estimate.needed_s == pytest.approx(39.0)
    assert not estimate.used_up
    low = budget.estimate(_at(30.0, 40.0, 20.0), remaining=0.27, home_ne_m=(0.0, 0.0))
    assert low is not None
    assert low.seconds_left == pytest.approx(24.0)
    assert low.used_up
    assert "27 % left" in low.reason()
    # Further from home, the same charge runs out sooner.
    near = budget.estimate(_at(0.0, 0.0, 20.0), remaining=0.28, home_ne_m=(0.0, 0.0))
    far = budget.estimate(_at(300.0, 0.0, 20.0), remaining=0.28, home_ne_m=(0.0, 0.0))
    assert near is not None
    assert far is not None
    assert not near.used_up
    assert far.used_up


def test_the_current_is_averaged_on_the_vehicle_clock_and_a_bad_reading_is_ignored() -> None:
    budget = EnergyBudget(PACK)
    assert budget.estimate(_at(0, 0, 10), 0.9, (0.0, 0.0)) is None  # no current read yet: no budget, no decision
    budget.observe(0.0, 10.0)
    for nan in (math.nan, -1.0, math.inf):
        budget.observe(1.0, nan)
    for k in range(1, 101):  # 100 s at 20 A after 10 A: the average follows within a time constant's factor
        budget.observe(float(k), 20.0)
    estimate = budget.estimate(_at(0, 0, 0), 1.0, (0.0, 0.0))
    assert estimate is not None
    assert estimate.current_a == pytest.approx(20.0, abs=0.01)
    brief = EnergyBudget(PACK)
    brief.observe(0.0, 10.0)
    brief.observe(1.0, 40.0)  # one second of a spike moves a 10 s average by a tenth of it
    spiked = brief.estimate(_at(0, 0, 0), 1.0, (0.0, 0.0))
    assert spiked is not None
    assert 12.0 < spiked.current_a < 14.0


def test_a_status_without_a_battery_reading_decides_nothing() -> None:
    budget = EnergyBudget(PACK)
    status = VehicleStatus()
    assert budget.check(_at(0, 0, 20), status) is None
    status.battery_current_a, status.battery_remaining, status.home_ne_m = 15.0, 0.26, (5.0, 5.0)
    low = budget.check(_at(0, 0, 20), status)
    assert low is not None
    assert low.used_up


def test_an_enabled_budget_needs_the_packs_capacity_and_never_lands() -> None:
    with pytest.raises(ConfigError, match="capacity_mah"):
        validate_config(GuidanceConfig, {"energy": {"enabled": True}}, "mission.guidance")
    with pytest.raises(ConfigError, match="action"):
        validate_config(GuidanceConfig, {"energy": {"enabled": True, "capacity_mah": 5000, "action": "land"}}, "g")
    assert GuidanceConfig().energy.enabled is False  # off by default: the paper's tables fly without it


def test_the_budgets_end_returns_the_vehicle_while_searching_but_never_interrupts_a_landing() -> None:
    fence = Geofence(GeofenceConfig(polygon_ne_m=[(-50, -50), (-50, 50), (50, 50), (50, -50)], max_altitude_m=40))
    config = GuidanceConfig.model_validate({"energy": PACK.model_dump()})
    guidance = LandingGuidance(config, fence, 1.0, min_zone_radius_m=1.0, policy=BiggestPolicy())
    state = _at(0.0, 0.0, 15.0, t_s=0.0)
    assert guidance.on(EnergyLow(state, "energy budget used up")) is None  # not started
    guidance.on(Started(state))
    decision = guidance.on(EnergyLow(_at(0.0, 0.0, 20.0, t_s=30.0), "energy budget used up: 26 % left"))
    assert decision is not None
    assert (decision.phase, decision.kind, decision.event) == (
        LandingPhase.FAILSAFE,
        CommandKind.RETURN,
        DecisionEvent.ENERGY_LOW,
    )
    assert decision.reason == "energy budget used up: 26 % left: return"
    assert config.energy.action is FailsafeAction.RETURN
    assert guidance.on(EnergyLow(_at(0.0, 0.0, 20.0, t_s=31.0), "again")) is None  # once


# -- the SITL's battery and PX4's battery failsafe ----------------------------------------------------------------


def test_the_pack_drains_with_thrust_from_its_initial_charge() -> None:
    pack = Battery(capacity_mah=1000.0, initial_fraction=0.5)
    assert pack.remaining == pytest.approx(0.5)
    pack.update(collective=0.5, dt_s=60.0, armed=True)  # 14.6 A for a minute: 243 mAh
    assert pack.current_a == pytest.approx(0.5 + 40.0 * 0.5**1.5)
    assert pack.remaining == pytest.approx(0.5 - pack.current_a * 60.0 / 3.6 / 1000.0)
    assert pack.time_remaining_s == pytest.approx(pack.remaining * 1000.0 * 3.6 / pack.current_a)


def test_px4s_battery_levels_and_actions() -> None:
    params = ParameterStore()  # BAT_LOW_THR 0.15, BAT_CRIT_THR 0.07, BAT_EMERGEN_THR 0.05
    assert [level_of(r, params) for r in (0.5, 0.15, 0.07, 0.05)] == [
        BatteryLevel.OK,
        BatteryLevel.LOW,
        BatteryLevel.CRITICAL,
        BatteryLevel.EMERGENCY,
    ]
    # COM_LOW_BAT_ACT: 0 warning, 1 return, 2 land, 3 return at critical and land at emergency.
    table = {act: [failsafe_action(level, act) for level in BatteryLevel] for act in range(4)}
    assert table == {
        0: [None, None, None, None],
        1: [None, None, "rtl", "rtl"],
        2: [None, None, "land", "land"],
        3: [None, None, "rtl", "land"],
    }
    monitor = BatteryMonitor()
    seen = [monitor.update(r, params) for r in (0.5, 0.14, 0.13, 0.2, 0.06, 0.04, 0.3)]
    assert seen == [None, BatteryLevel.LOW, None, None, BatteryLevel.CRITICAL, BatteryLevel.EMERGENCY, None]


def _mode(cmd: Commander) -> FlightMode:
    """The commander's mode, read afresh (the state machine changes it inside calls)."""
    return cmd.mode


def _flying(params: dict[str, float]) -> Commander:
    cmd = Commander(ParameterStore(params), np.zeros(3))
    cmd.update(0.0, SimState(position_ned_m=np.array([0.0, 0.0, -0.12])), 0.0)
    assert cmd.arm() is MavResult.ACCEPTED
    cmd.land_detector.state = LandedState.IN_AIR
    return cmd


def test_the_commander_returns_at_critical_and_lands_at_emergency_as_com_low_bat_act_3_asks() -> None:
    cmd = _flying({"COM_LOW_BAT_ACT": 3})
    cmd.battery_failsafe(BatteryLevel.LOW)
    assert _mode(cmd) is FlightMode.AUTO_LOITER  # a warning only
    assert any("Battery low" in text for _, text in cmd.events)
    cmd.battery_failsafe(BatteryLevel.CRITICAL)
    assert _mode(cmd) is FlightMode.AUTO_RTL
    assert cmd.failsafe == "battery critical"
    cmd.battery_failsafe(BatteryLevel.EMERGENCY)
    assert _mode(cmd) is FlightMode.AUTO_LAND
    warned = _flying({"COM_LOW_BAT_ACT": 0})
    warned.battery_failsafe(BatteryLevel.EMERGENCY)
    assert _mode(warned) is FlightMode.AUTO_LOITER  # PX4's default: warnings, the pilot decides


def test_a_critical_pack_cannot_arm() -> None:
    cmd = Commander(ParameterStore(), np.zeros(3))
    cmd.update(0.0, SimState(position_ned_m=np.array([0.0, 0.0, -0.12])), 0.0)
    cmd.battery_failsafe(BatteryLevel.CRITICAL)
    assert cmd.prearm_problem() == "battery critical"
    assert cmd.arm() is MavResult.DENIED
