"""Unit tests of the SITL's parts: dynamics, controller, commander, parameters, modes, geodesy, schedules, config."""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest

from companion.config import ConfigError, validate_config
from sitl.autopilot.commander import Commander
from sitl.autopilot.controller import CascadedController, Setpoint
from sitl.autopilot.modes import FlightMode
from sitl.autopilot.params import ParamError, ParameterStore, decode_value, encode_value
from sitl.autopilot.status import LandedState, MavResult
from sitl.autopilot.telemetry import StreamSchedule
from sitl.config import SitlConfig
from sitl.dynamics.base import DynamicsBackend, VehicleState
from sitl.dynamics.factory import make_dynamics
from sitl.dynamics.rigid_body import RigidBodyQuadrotor, quaternion_to_matrix
from sitl.geodesy import geodetic_to_ned, ned_to_geodetic
from sitl.px4_params import ParamType

pytestmark = pytest.mark.unit

RATE_HZ = 400.0
DT_S = 1.0 / RATE_HZ


def fly(dynamics: Any, waypoints: Sequence[tuple[float, float, float]], seconds_each: float) -> np.ndarray:
    """Fly position holds through the waypoints; returns positions (N, 3) sampled every 0.1 s."""
    controller = CascadedController(dynamics.airframe)
    track, k = [], 0
    for wp in waypoints:
        setpoint = Setpoint.hold(np.array(wp, dtype=float), 0.0)
        for _ in range(int(seconds_each * RATE_HZ)):
            state = dynamics.state()
            if k % 4 == 0:
                controller.update_position(state, setpoint, 4 * DT_S)
            dynamics.set_motor_commands(controller.update_attitude(state, DT_S))
            dynamics.step(DT_S)
            if k % 40 == 0:
                track.append(dynamics.state().position_ned_m.copy())
            k += 1
    return np.array(track)


SQUARE = [(0.0, 0.0, -5.0), (5.0, 0.0, -5.0), (5.0, 5.0, -5.0), (0.0, 5.0, -5.0), (0.0, 0.0, -5.0)]


def test_rigid_body_flies_the_square_and_settles_on_the_ground() -> None:
    track = fly(RigidBodyQuadrotor(), [*SQUARE, (0.0, 0.0, 0.5)], 8.0)
    per_leg = len(track) // 6
    for i, wp in enumerate(SQUARE):
        end = track[(i + 1) * per_leg - 1]
        assert np.linalg.norm(end - wp) < 0.1, f"waypoint {wp}: ended at {end}"
    assert track[-1][2] == pytest.approx(-0.12, abs=0.01)  # resting on its legs


def test_both_backends_fly_the_same_square_within_half_a_metre() -> None:
    pytest.importorskip("jsbsim")
    rigid = fly(make_dynamics(DynamicsBackend.RIGID_BODY, RATE_HZ), SQUARE, 8.0)
    jsb = fly(make_dynamics(DynamicsBackend.JSBSIM_F450, RATE_HZ), SQUARE, 8.0)
    # Stated tolerance: the same controller on two models of an F450 keeps within 0.5 m horizontally and 0.3 m
    # vertically of each other at every 0.1 s sample once airborne (their motors, drag and resting heights differ).
    airborne = slice(20, None)
    horizontal = np.linalg.norm(rigid[airborne, :2] - jsb[airborne, :2], axis=1)
    vertical = np.abs(rigid[airborne, 2] - jsb[airborne, 2])
    assert horizontal.max() < 0.5
    assert vertical.max() < 0.3


def test_ground_contact_is_still_at_rest_and_after_a_drop() -> None:
    quad = RigidBodyQuadrotor()
    for _ in range(int(2 * RATE_HZ)):
        quad.step(DT_S)
    rest = quad.state()
    assert rest.on_ground
    assert np.linalg.norm(rest.velocity_ned_mps) < 1e-3
    # Lift it 1 m and let it fall: it bounces at most a little and comes to rest level.
    north_m, east_m, down_m = quad._pos
    quad._pos = (north_m, east_m, down_m - 1.0)
    for _ in range(int(3 * RATE_HZ)):
        quad.step(DT_S)
    after = quad.state()
    assert after.on_ground
    assert np.linalg.norm(after.velocity_ned_mps) < 1e-2
    assert after.position_ned_m[2] == pytest.approx(rest.position_ned_m[2], abs=0.01)
    assert quaternion_to_matrix(after.quaternion_wxyz)[2, 2] > 0.999  # level


def test_wind_is_rejected_by_the_integrators() -> None:
    quad = RigidBodyQuadrotor()
    quad.set_wind(np.array([0.0, 4.0, 0.0]))
    track = fly(quad, [(0.0, 0.0, -5.0)], 20.0)
    assert np.linalg.norm(track[-1] - [0, 0, -5]) < 0.15


def test_mixer_gives_up_yaw_before_roll_and_pitch() -> None:
    ctl = CascadedController(RigidBodyQuadrotor().airframe)
    thrust_roll_only = ctl._mix(0.5, np.array([0.3, 0.0, 0.0]))
    thrust_with_yaw = ctl._mix(0.5, np.array([0.3, 0.0, 1.0]))  # far more yaw than there is room for

    def roll_diff(commands: np.ndarray) -> float:
        thrust = commands**2  # the rigid body's thrust curve
        return float((thrust[1] + thrust[2]) - (thrust[0] + thrust[3]))  # left minus right rotors

    assert roll_diff(thrust_with_yaw) == pytest.approx(roll_diff(thrust_roll_only))
    assert np.all(thrust_with_yaw <= 1.0)
    assert np.all(thrust_with_yaw >= 0.0)


def test_thrust_curve_inverse() -> None:
    ctl = CascadedController(RigidBodyQuadrotor().airframe)
    commands = ctl._mix(0.25, np.zeros(3))
    np.testing.assert_allclose(commands, 0.5)  # quadratic curve: 25 % thrust at half command


# -- commander -------------------------------------------------------------------------------------------------
def grounded() -> VehicleState:
    return VehicleState(position_ned_m=np.array([0.0, 0.0, -0.12]))


def airborne(down_m: float = -5.0) -> VehicleState:
    return VehicleState(position_ned_m=np.array([0.0, 0.0, down_m]), on_ground=False)


def commander() -> Commander:
    return Commander(ParameterStore(), np.zeros(3))


def mode_of(cmd: Commander) -> FlightMode:
    """The commander's mode, read afresh (the state machine changes it inside calls)."""
    return cmd.mode


def test_arming_checks_and_duplicate_requests() -> None:
    cmd = commander()
    cmd.update(0.0, grounded(), 0.0)
    assert cmd.arm() is MavResult.ACCEPTED
    assert cmd.arm() is MavResult.ACCEPTED  # duplicate
    assert cmd.disarm() is MavResult.ACCEPTED
    cmd.set_mode(FlightMode.AUTO_LAND)
    assert cmd.arm() is MavResult.DENIED  # LAND is not armable


def test_offboard_needs_a_stream_and_loss_triggers_the_configured_action() -> None:
    cmd = commander()
    cmd.update(0.0, grounded(), 0.0)
    assert cmd.set_mode(FlightMode.OFFBOARD) is MavResult.TEMPORARILY_REJECTED
    ok, _ = cmd.offboard_setpoint(np.array([0.0, 0.0, -5.0]), np.full(3, np.nan), math.nan)
    assert ok
    assert cmd.set_mode(FlightMode.OFFBOARD) is MavResult.ACCEPTED
    assert cmd.arm() is MavResult.ACCEPTED
    setpoint = cmd.update(0.1, grounded(), 0.0)
    assert setpoint is not None
    assert cmd.landed_state is LandedState.TAKEOFF
    cmd.update(0.9, airborne(), 0.5)
    assert mode_of(cmd) is FlightMode.OFFBOARD  # 0.9 s after the last setpoint: still fine (COM_OF_LOSS_T = 1 s)
    cmd.update(1.05, airborne(), 0.5)
    # PX4 v1.15's default, COM_OBL_RC_ACT = 0: position mode, the vehicle the pilot's (it hovers on centred sticks).
    assert mode_of(cmd) is FlightMode.POSCTL
    assert cmd.failsafe == "Offboard lost"


@pytest.mark.parametrize(
    ("value", "rc_lost", "expected"),
    [
        (0, False, FlightMode.POSCTL),
        (0, True, FlightMode.AUTO_LOITER),  # position mode needs RC: PX4 falls back to hold
        (1, False, FlightMode.POSCTL),  # altitude mode, flown as position mode
        (2, True, FlightMode.AUTO_LOITER),
        (3, False, FlightMode.AUTO_RTL),
        (4, False, FlightMode.AUTO_LAND),
        (5, False, FlightMode.AUTO_LOITER),
        (6, False, FlightMode.AUTO_LAND),  # terminate, flown as land
        (7, False, FlightMode.AUTO_LAND),  # disarm, flown as land
    ],
)
def test_each_offboard_loss_mode_of_px4_v1_15_is_flown(value: int, rc_lost: bool, expected: FlightMode) -> None:
    # NAV_RCL_ACT = 0: the RC's own loss does nothing, so what flies is the offboard loss's choice.
    cmd = Commander(ParameterStore({"COM_OBL_RC_ACT": value, "NAV_RCL_ACT": 0}), np.zeros(3))
    cmd.update(0.0, grounded(), 0.0)
    cmd.offboard_setpoint(np.array([0.0, 0.0, -5.0]), np.full(3, np.nan), math.nan)
    assert cmd.set_mode(FlightMode.OFFBOARD) is MavResult.ACCEPTED
    assert cmd.arm() is MavResult.ACCEPTED
    cmd.update(0.1, grounded(), 0.0)
    cmd.update(0.5, airborne(), 0.5)
    if rc_lost:
        cmd.set_rc_lost(True)
    cmd.update(1.2, airborne(), 0.5)  # COM_OF_LOSS_T (1 s) after the last setpoint
    assert cmd.failsafe == "Offboard lost"
    assert mode_of(cmd) is expected


def test_bad_setpoints() -> None:
    cmd = commander()
    nan3 = np.full(3, np.nan)
    assert not cmd.offboard_setpoint(nan3, nan3, 0.0)[0]
    assert not cmd.offboard_setpoint(np.array([0, 0, np.inf]), nan3, 0.0)[0]
    assert not cmd.offboard_setpoint(nan3, np.array([100.0, 0, 0]), 0.0)[0]
    assert cmd.offboard_setpoint(nan3, np.array([1.0, 0, 0]), math.nan)[0]


def test_rc_loss_in_position_mode_returns_home() -> None:
    cmd = commander()
    cmd.update(0.0, grounded(), 0.0)
    cmd.set_mode(FlightMode.POSCTL)
    cmd.arm()
    cmd.land_detector.state = LandedState.IN_AIR
    cmd.set_rc_lost(True)
    cmd.update(0.3, airborne(), 0.5)
    assert mode_of(cmd) is FlightMode.POSCTL  # COM_RC_LOSS_T = 0.5 s
    cmd.update(0.6, airborne(), 0.5)
    assert mode_of(cmd) is FlightMode.AUTO_RTL
    assert cmd.failsafe == "RC lost"


def test_disarm_in_the_air_is_denied_and_landing_disarms() -> None:
    cmd = commander()
    cmd.update(0.0, grounded(), 0.0)
    cmd.arm()
    cmd.land_detector.state = LandedState.IN_AIR
    assert cmd.disarm() is MavResult.DENIED
    assert cmd.disarm(force=True) is MavResult.ACCEPTED
    cmd = commander()
    cmd.update(0.0, grounded(), 0.0)
    cmd.arm()
    cmd.land_detector.state = LandedState.LANDING
    cmd.set_mode(FlightMode.AUTO_LAND)
    touching = VehicleState(position_ned_m=np.array([0.0, 0.0, -0.12]), on_ground=True)
    t = 10.0
    while cmd.armed and t < 20.0:
        cmd.update(t, touching, 0.1)
        t += 0.01
    assert cmd.landed_state is LandedState.ON_GROUND
    assert t - 10.0 == pytest.approx(0.5 + 2.0, abs=0.05)  # detected after 0.5 s, disarmed COM_DISARM_LAND later


def test_unused_arming_times_out() -> None:
    cmd = commander()
    cmd.update(0.0, grounded(), 0.0)
    cmd.arm()
    cmd.update(9.0, grounded(), 0.0)
    assert cmd.armed
    cmd.update(10.5, grounded(), 0.0)
    assert not cmd.armed  # COM_DISARM_PRFLT = 10 s


# -- parameters, modes, geodesy, schedules, config -------------------------------------------------------------
def test_int_parameters_travel_bytewise() -> None:
    store = ParameterStore()
    spec = store.spec("COM_OBL_RC_ACT")
    wire = encode_value(spec, 2)
    assert struct.unpack("<i", struct.pack("<f", wire))[0] == 2
    assert decode_value(spec, wire, ParamType.INT32) == 2
    assert decode_value(spec, 1.0, ParamType.REAL32) == 1.0


def test_parameter_ranges() -> None:
    store = ParameterStore()
    with pytest.raises(ParamError, match=r"outside \[0.0, 60.0\]"):
        store.set("COM_OF_LOSS_T", 100.0)
    with pytest.raises(ParamError, match="unknown parameter"):
        store.set("NOPE", 1.0)
    with pytest.raises(ParamError, match="outside"):
        ParameterStore({"MPC_XY_VEL_MAX": math.nan})


def test_a_wire_value_is_stored_as_px4_stores_it_and_flown_within_its_range() -> None:
    store = ParameterStore()
    before = store.hash_check()
    assert store.set_from_wire("MPC_XY_VEL_MAX", 50.0) is False  # outside [0.5, 20]: stored, and said so
    assert (store.raw("MPC_XY_VEL_MAX"), store["MPC_XY_VEL_MAX"]) == (50.0, 20.0)
    assert store.hash_check() != before  # a ground station's cache of the old value no longer matches
    assert store.set_from_wire("COM_OBL_RC_ACT", 2.4) is True
    assert store.raw("COM_OBL_RC_ACT") == 2.0
    for bad in (math.nan, math.inf):
        with pytest.raises(ParamError, match="is not a real32"):
            store.set_from_wire("MPC_XY_VEL_MAX", bad)
    with pytest.raises(ParamError, match="is not a int32"):
        store.set_from_wire("COM_OBL_RC_ACT", 3e9)
    assert store.raw("MPC_XY_VEL_MAX") == 50.0
    assert store.names() == sorted(store.names())
    assert store.index(store.names()[7]) == 7


@pytest.mark.parametrize("mode", list(FlightMode))
def test_custom_mode_round_trip(mode: FlightMode) -> None:
    assert FlightMode.from_custom_mode(mode.custom_mode) is mode
    assert FlightMode.from_name(mode.px4_name) is mode


def test_mode_names_and_encoding() -> None:
    assert FlightMode.OFFBOARD.custom_mode == 6 << 16
    assert FlightMode.AUTO_LAND.custom_mode == 4 << 16 | 6 << 24
    assert FlightMode.from_name("hold") is FlightMode.AUTO_LOITER
    assert FlightMode.from_px4(5, 0) is None  # ACRO: not flown here
    with pytest.raises(ValueError, match="unknown flight mode"):
        FlightMode.from_name("SPORT")


def test_geodesy_round_trip() -> None:
    lat, lon, alt = ned_to_geodetic(120.0, -80.0, -30.0, 47.397742, 8.545594, 488.0)
    assert alt == pytest.approx(518.0)
    assert lat > 47.397742
    assert lon < 8.545594
    n, e, d = geodetic_to_ned(lat, lon, alt, 47.397742, 8.545594, 488.0)
    assert (n, e, d) == pytest.approx((120.0, -80.0, -30.0), abs=1e-6)
    # One degree of latitude is about 111.2 km there.
    assert ned_to_geodetic(111_200.0, 0, 0, 47.0, 8.0, 0)[0] == pytest.approx(48.0, abs=0.01)


def test_stream_schedule_intervals() -> None:
    schedule = StreamSchedule({"ATTITUDE": 10.0})
    due = [t / 100 for t in range(0, 100) if schedule.due(t / 100)]
    assert len(due) == 10
    schedule.set_interval("ATTITUDE", 500_000)
    assert [t / 100 for t in range(100, 200) if schedule.due(t / 100)] == [1.0, 1.5]
    schedule.set_interval("ATTITUDE", -1)
    assert not any(schedule.due(t / 100) for t in range(200, 300))


def test_sitl_config_validation() -> None:
    with pytest.raises(ConfigError, match="unknown parameters"):
        validate_config(SitlConfig, {"params": {"NOT_A_PARAM": 1}})
    with pytest.raises(ConfigError, match="whole number of physics steps"):
        validate_config(SitlConfig, {"lockstep_period_s": 0.0033})
    with pytest.raises(ConfigError, match="ground-station port"):
        validate_config(SitlConfig, {"instance": 10})
    with pytest.raises(ConfigError, match=r"instance.*less than or equal to 39"):
        validate_config(SitlConfig, {"instance": 40})  # its MAVSDK port would be instance 0's local API port
    with pytest.raises(ConfigError, match=r"sitl\.speed_factor"):
        validate_config(SitlConfig, {"speed_factor": -1}, prefix="sitl")
    config = SitlConfig(instance=3)
    assert (config.api_port_remote, config.api_port_local, config.gcs_port_local, config.control_port) == (
        14543,
        14583,
        18573,
        4563,
    )
    assert config.system_id == 4
