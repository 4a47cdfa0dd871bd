"""The SITL vehicle on the wire, as an API client sees it: identity, streams, parameters, commands, bad input."""

from __future__ import annotations

import functools
import itertools
import math
import struct
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl.autopilot.modes import FlightMode
from sitl.harness.process import SitlProcess
from sitl.px4_params import ParamType
from sitl.testing.helpers import MavlinkPeer, api_port, position_setpoint, state_when, wait_until

pytestmark = pytest.mark.sitl

ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED = 0, 1, 2, 3


@pytest.fixture(scope="module")
def sitl(tmp_path_factory: pytest.TempPathFactory, module_instance: int) -> Iterator[SitlProcess]:
    with SitlProcess(["--speed", "2"], module_instance, tmp_path_factory.mktemp("sitl")) as process:
        yield process


@pytest.fixture
def api(sitl: SitlProcess) -> Iterator[MavlinkPeer]:
    peer = MavlinkPeer(api_port(sitl.instance), system_id=245, component_id=190, only_sysid=sitl.instance + 1)
    wait_until(lambda: peer.latest("HEARTBEAT"), 5, "a heartbeat")
    yield peer
    peer.close()


def test_it_looks_like_a_px4_quadrotor(api: MavlinkPeer, sitl: SitlProcess) -> None:
    hb = api.latest("HEARTBEAT")
    assert hb.get_srcSystem() == sitl.instance + 1  # PX4: the instance + 1
    assert hb.get_srcComponent() == 1
    assert hb.type == mavlink.MAV_TYPE_QUADROTOR
    assert hb.autopilot == mavlink.MAV_AUTOPILOT_PX4
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert FlightMode.from_custom_mode(hb.custom_mode) is FlightMode.AUTO_LOITER
    status = wait_until(lambda: api.latest("SYS_STATUS"), 3, "SYS_STATUS")
    assert status.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_SENSOR_GPS
    assert status.onboard_control_sensors_health & 0x10000000  # pre-arm checks pass: armable
    for kind in (
        "ATTITUDE",
        "ATTITUDE_QUATERNION",
        "LOCAL_POSITION_NED",
        "GLOBAL_POSITION_INT",
        "GPS_RAW_INT",
        "EXTENDED_SYS_STATE",
        "BATTERY_STATUS",
    ):
        wait_until(functools.partial(api.latest, kind), 5, kind)
    assert api.latest("EXTENDED_SYS_STATE").landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
    position = api.latest("GLOBAL_POSITION_INT")
    assert position is not None
    assert position.lat == pytest.approx(473977420, abs=50)
    assert position.lon == pytest.approx(85455940, abs=50)


def test_requested_messages_and_intervals(api: MavlinkPeer) -> None:
    assert api.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == ACCEPTED
    version = wait_until(lambda: api.latest("AUTOPILOT_VERSION"), 2, "AUTOPILOT_VERSION")
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert api.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) == ACCEPTED
    home = wait_until(lambda: api.latest("HOME_POSITION"), 2, "HOME_POSITION")
    assert (home.x, home.y, home.z) == (0.0, 0.0, 0.0)
    assert api.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 9999) == UNSUPPORTED
    # The same request as COMMAND_INT.
    api.messages.clear()
    api.send(
        api.mav.command_int_encode(
            api.vehicle_sysid,
            1,
            0,
            mavlink.MAV_CMD_REQUEST_MESSAGE,
            0,
            0,
            mavlink.MAVLINK_MSG_ID_HOME_POSITION,
            0,
            0,
            0,
            0,
            0,
            0,
        )
    )
    ack = wait_until(lambda: api.latest("COMMAND_ACK"), 2, "the COMMAND_INT ack")
    assert ack.command == mavlink.MAV_CMD_REQUEST_MESSAGE
    assert ack.result == ACCEPTED
    assert ack.target_system == 245
    # ATTITUDE at 5 Hz: consecutive time_boot_ms (the simulated clock) 200 ms apart.
    assert api.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE, 200_000) == ACCEPTED
    api.messages.clear()

    def attitudes() -> list[Any] | None:
        api.poll()
        found = [m for m in api.messages if m.get_type() == "ATTITUDE"]
        return found if len(found) >= 6 else None

    times = [m.time_boot_ms for m in wait_until(attitudes, 5, "six ATTITUDE messages")][1:]
    assert all(b - a == 200 for a, b in itertools.pairwise(times))
    assert api.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE, 0) == ACCEPTED


def test_parameters_read_set_list(api: MavlinkPeer) -> None:
    api.messages.clear()
    api.send(api.mav.param_request_list_encode(api.vehicle_sysid, 1))

    def all_params() -> list[Any] | None:
        api.poll()
        values = [m for m in api.messages if m.get_type() == "PARAM_VALUE"]
        return values if values and len(values) == values[0].param_count + 1 else None  # with _HASH_CHECK

    values = wait_until(all_params, 3, "the whole parameter list")
    assert values[0].param_id == "_HASH_CHECK"  # first, as PX4 sends it
    names = {v.param_id for v in values[1:]}
    assert {"MIS_TAKEOFF_ALT", "COM_OF_LOSS_T", "COM_OBL_RC_ACT", "MPC_XY_VEL_MAX"} <= names

    def read(name: str) -> Any:
        api.messages.clear()
        api.send(api.mav.param_request_read_encode(api.vehicle_sysid, 1, name.encode(), -1))
        return wait_until(lambda: api.latest("PARAM_VALUE"), 2, f"PARAM_VALUE {name}")

    assert read("COM_OF_LOSS_T").param_value == pytest.approx(1.0)
    # INT32 parameters travel bytewise, as PX4 sends them.
    as_float = struct.unpack("<f", struct.pack("<i", 2))[0]
    api.messages.clear()
    api.send(api.mav.param_set_encode(api.vehicle_sysid, 1, b"COM_OBL_RC_ACT", as_float, ParamType.INT32))
    echoed = wait_until(lambda: api.latest("PARAM_VALUE"), 2, "the PARAM_SET echo")
    assert echoed.param_type == ParamType.INT32
    assert struct.unpack("<i", struct.pack("<f", echoed.param_value))[0] == 2
    # Out of range: stored and echoed as PX4 stores it (the controller flies with the range's end); NaN refused.
    api.messages.clear()
    api.send(api.mav.param_set_encode(api.vehicle_sysid, 1, b"MPC_XY_VEL_MAX", 500.0, ParamType.REAL32))
    assert wait_until(lambda: api.latest("PARAM_VALUE"), 2, "echo").param_value == pytest.approx(500.0)
    api.messages.clear()
    api.send(api.mav.param_set_encode(api.vehicle_sysid, 1, b"MPC_XY_VEL_MAX", math.nan, ParamType.REAL32))
    assert wait_until(lambda: api.latest("PARAM_VALUE"), 2, "echo").param_value == pytest.approx(500.0)
    api.send(api.mav.param_set_encode(api.vehicle_sysid, 1, b"MPC_XY_VEL_MAX", 5.0, ParamType.REAL32))
    api.send(
        api.mav.param_set_encode(
            api.vehicle_sysid, 1, b"COM_OBL_RC_ACT", struct.unpack("<f", struct.pack("<i", 0))[0], 6
        )
    )


def test_commands_in_the_wrong_state_get_the_right_result(api: MavlinkPeer, sitl: SitlProcess) -> None:
    assert api.command(31999) == UNSUPPORTED  # unknown command
    assert (
        api.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
        == TEMPORARILY_REJECTED
    )
    offboard = (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6, 0)
    assert api.command(mavlink.MAV_CMD_DO_SET_MODE, *offboard) == TEMPORARILY_REJECTED  # no setpoint stream
    assert api.command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5, 0) == UNSUPPORTED
    # MAVSDK retries a command up to four times: duplicates are answered, and change nothing twice.
    assert [api.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) for _ in range(4)] == [ACCEPTED] * 4
    assert sitl.state()["armed"]
    assert api.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan) == ACCEPTED
    wait_until(lambda: sitl.state()["landed_state"] == "IN_AIR", 10, "in the air")
    assert api.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0) == DENIED  # would drop the vehicle
    assert sitl.state()["armed"]
    assert api.command(mavlink.MAV_CMD_NAV_LAND) == ACCEPTED
    wait_until(lambda: not sitl.state()["armed"], 30, "landed and disarmed")


def test_malformed_and_unknown_mavlink_is_dropped_and_counted(api: MavlinkPeer, sitl: SitlProcess) -> None:
    before = sitl.state()["links"]["api"]
    hb = api.mav.heartbeat_encode(6, 8, 0, 0, 0).pack(api.mav)
    corrupted = bytearray(hb)
    corrupted[-1] ^= 0xFF  # bad CRC
    unknown = struct.pack("<BBBBBBBHB", 0xFD, 3, 0, 0, 7, 245, 190, 0xBCDE, 0x0A) + b"\x01\x02\x03\x00\x00"
    for data in (bytes(corrupted), b"\x00" * 40, b"\xfd\x09garbage", unknown, hb[:7]):
        api.send_raw(data)
    after = state_when(
        sitl,
        lambda s: s["links"]["api"]["dropped_malformed"] >= before["dropped_malformed"] + 3,
        3,
        "the drops to be counted",
    )["links"]["api"]
    assert after["dropped_unknown"] >= before["dropped_unknown"] + 1
    assert sitl.request({"cmd": "ping"})["event"] == "pong"  # still alive
    assert api.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) == ACCEPTED


def test_bad_setpoints_are_rejected(api: MavlinkPeer, sitl: SitlProcess) -> None:
    before = sitl.state()["setpoints_rejected"]
    api.send(position_setpoint(api.mav, math.nan, 0.0, -5.0, target_system=api.vehicle_sysid))  # NaN in a used field
    api.send(position_setpoint(api.mav, 1e6, 0.0, -5.0, target_system=api.vehicle_sysid))  # 1000 km away
    api.send(
        api.mav.set_position_target_local_ned_encode(
            0, api.vehicle_sysid, 1, 8, 0b0000_1111_1111_1000, 0, 0, -5, 0, 0, 0, 0, 0, 0, 0, 0
        )
    )
    wait_until(lambda: sitl.state()["setpoints_rejected"] >= before + 3, 3, "three rejections")
    offboard = (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6, 0)
    assert api.command(mavlink.MAV_CMD_DO_SET_MODE, *offboard) == TEMPORARILY_REJECTED  # none of them counts


def test_control_channel_errors_are_answered(sitl: SitlProcess) -> None:
    assert sitl.request({"cmd": "fly_to_the_moon"})["event"] == "error"
    assert "unknown flight mode" in sitl.request({"cmd": "pilot_mode", "mode": "SPORT"})["error"]
    assert sitl.request({"cmd": "wind", "ned_mps": [1, "x"]})["event"] == "error"
    bad_ack = sitl.request({"cmd": "lockstep_ack", "seq": "first", "mavlink_sent": 0, "sysid": 1, "compid": 1})
    assert bad_ack["event"] == "error"
    assert sitl.request({"cmd": "ping"})["event"] == "pong"


def test_two_instances_run_side_by_side(tmp_path: Path, instances: Callable[[], int]) -> None:
    i, j = instances(), instances()
    with SitlProcess(["--speed", "1"], i, tmp_path) as a, SitlProcess(["--speed", "1"], j, tmp_path) as b:
        peer_a, peer_b = MavlinkPeer(api_port(i)), MavlinkPeer(api_port(j))
        try:
            hb_a = wait_until(lambda: peer_a.latest("HEARTBEAT"), 5, f"instance {i}")
            hb_b = wait_until(lambda: peer_b.latest("HEARTBEAT"), 5, f"instance {j}")
            assert (hb_a.get_srcSystem(), hb_b.get_srcSystem()) == (i + 1, j + 1)
            assert a.state()["t_s"] > 0
            assert b.state()["t_s"] > 0
        finally:
            peer_a.close()
            peer_b.close()


def test_a_taken_port_is_a_clear_error(tmp_path: Path, instance: int) -> None:
    blocker = MavlinkPeer(14580 + instance)  # the API link's local port of the instance
    try:
        with pytest.raises(Exception, match=rf"cannot bind 127\.0\.0\.1:{14580 + instance}"):
            SitlProcess([], instance, tmp_path).start(ready_timeout_s=10)
    finally:
        blocker.close()


def test_rc_loss_in_position_mode_returns_home(tmp_path: Path, instance: int) -> None:
    config = tmp_path / "rtl.yaml"
    config.write_text("sitl:\n  params:\n    RTL_RETURN_ALT: 5.0\n    MPC_LAND_SPEED: 1.5\n")
    with SitlProcess(["--config", str(config), "--speed", "4"], instance, tmp_path) as sitl:
        api = MavlinkPeer(api_port(instance))
        try:
            wait_until(lambda: api.latest("HEARTBEAT"), 5, "a heartbeat")
            assert api.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
            assert api.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan) == ACCEPTED
            state_when(sitl, lambda s: s["mode"] == "AUTO.LOITER", 20, "takeoff done")
            assert sitl.request({"cmd": "pilot_mode", "mode": "POSCTL"})["result"] == ACCEPTED
            sitl.request({"cmd": "pilot_sticks", "north": 0.5})
            state_when(sitl, lambda s: s["position_ned_m"][0] > 4.0, 10, "the pilot flying north")
            sitl.request({"cmd": "pilot_sticks", "north": 0.0})
            sitl.request({"cmd": "rc_loss", "lost": True})
            lost = state_when(sitl, lambda s: s["failsafe"] == "RC lost", 5, "the RC-loss failsafe")
            assert lost["mode"] == "AUTO.RTL"  # NAV_RCL_ACT = 2
            status = wait_until(lambda: api.latest("SYS_STATUS"), 3, "SYS_STATUS")
            assert not status.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
            home = state_when(
                sitl, lambda s: not s["armed"] and s["landed_state"] == "ON_GROUND", 90, "landed at home and disarmed"
            )
            assert math.hypot(*home["position_ned_m"][:2]) < 1.0
        finally:
            api.close()
