"""The SITL as a ground station sees it: QGroundControl's connect sequence, the mission, fence and rally protocols,
parameters with ``_HASH_CHECK``, MAVLink FTP, the default streams, the fly-view commands, status texts, and two
ground stations on one link. Real processes over real UDP; the ground stations are pymavlink peers that send what
QGroundControl sends, with its timeouts."""

from __future__ import annotations

import functools
import itertools
import math
import struct
import time
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl.autopilot.modes import FlightMode
from sitl.geodesy import ned_to_geodetic
from sitl.harness.process import SitlProcess
from sitl.testing.helpers import GroundStation, free_udp_port, state_when, wait_until

pytestmark = pytest.mark.sitl

ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED = 0, 1, 2, 3
# QGroundControl's own limits: a command's ACK within 1.2 s (MavCommandQueue), a mission-protocol answer within
# 1.5 s (PlanManager's ack timeout; it retries every 250 ms), a missing parameter re-requested after 3 s.
COMMAND_ACK_TIMEOUT_S = 1.2
MISSION_TIMEOUT_S = 1.5
PARAM_TIMEOUT_S = 3.0
ORIGIN = (47.397742, 8.545594, 488.0)  # the SITL's default geodetic origin (PX4's)


@pytest.fixture
def gcs_sitl(tmp_path: Path, instance: int) -> Iterator[tuple[SitlProcess, int]]:
    """A SITL (speed 4) whose ground-station link sends to a free port of this test's own."""
    gcs_port = free_udp_port()
    config = tmp_path / "sitl.yaml"
    config.write_text(f"sitl:\n  gcs_port_remote: {gcs_port}\n")
    with SitlProcess(["--config", str(config), "--speed", "4"], instance, tmp_path) as sitl:
        yield sitl, gcs_port


@pytest.fixture
def qgc(gcs_sitl: tuple[SitlProcess, int]) -> Iterator[GroundStation]:
    sitl, port = gcs_sitl
    station = GroundStation(sitl.instance, port)
    wait_until(lambda: station.latest("HEARTBEAT"), 5, "the vehicle's heartbeat")
    yield station
    station.close()


def answer(station: GroundStation, match: Callable[[Any], bool], timeout_s: float, what: str) -> Any:
    """The first received message ``match`` accepts that no earlier call returned, within ``timeout_s``."""

    def found() -> Any:
        station.poll()
        for msg in station.messages:
            if not getattr(msg, "answered", False) and match(msg):
                msg.answered = True
                return msg
        return None

    return wait_until(found, timeout_s, what, poll_s=0.005)


def heartbeat(station: GroundStation) -> None:
    station.send(station.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0))


def mission_list(station: GroundStation, mission_type: int) -> list[Any]:
    """Download a list as QGroundControl's PlanManager does (MISSION_REQUEST_INT per item, then MISSION_ACK)."""
    sysid = station.vehicle_sysid
    station.send(station.mav.mission_request_list_encode(sysid, 1, mission_type))
    count = answer(
        station,
        lambda m: m.get_type() == "MISSION_COUNT" and m.mission_type == mission_type,
        MISSION_TIMEOUT_S,
        f"MISSION_COUNT of type {mission_type}",
    ).count
    items = []
    for seq in range(count):
        station.send(station.mav.mission_request_int_encode(sysid, 1, seq, mission_type))
        items.append(
            answer(
                station,
                functools.partial(lambda m, wanted: m.get_type() == "MISSION_ITEM_INT" and m.seq == wanted, wanted=seq),
                MISSION_TIMEOUT_S,
                f"item {seq}",
            )
        )
    station.send(station.mav.mission_ack_encode(sysid, 1, 0, mission_type))
    return items


def upload(
    station: GroundStation, items: list[tuple[int, int, float, float, float, list[float]]], mission_type: int = 0
) -> int:
    """Upload ``(frame, command, lat_deg, lon_deg, alt_m, params)`` items as QGroundControl does: MISSION_COUNT,
    then an item for each request; returns the MISSION_ACK's result."""
    sysid = station.vehicle_sysid
    station.messages.clear()
    station.send(station.mav.mission_count_encode(sysid, 1, len(items), mission_type))
    while True:
        msg = answer(
            station,
            lambda m: m.get_type() in ("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"),
            MISSION_TIMEOUT_S,
            "a request or the ACK",
        )
        if msg.get_type() == "MISSION_ACK":
            return int(msg.type)
        frame, command, lat, lon, alt, params = items[msg.seq]
        p = [*params, *([0.0] * (4 - len(params)))]
        station.send(
            station.mav.mission_item_int_encode(
                sysid, 1, msg.seq, frame, command, 0, 1, *p, round(lat * 1e7), round(lon * 1e7), alt, mission_type
            )
        )


def geo(north_m: float, east_m: float) -> tuple[float, float]:
    lat, lon, _ = ned_to_geodetic(north_m, east_m, 0.0, *ORIGIN)
    return lat, lon


def hash_of(values: dict[str, Any]) -> int:
    """QGroundControl's cache hash: CRC-32 without inversion over each name and its four value bytes, by name."""
    crc = 0
    for name in sorted(values):
        msg = values[name]
        data = struct.pack("<f", msg.param_value)  # the wire bytes (bytewise for integers)
        for chunk in (name.encode(), data):
            crc = ~zlib.crc32(chunk, ~crc & 0xFFFFFFFF) & 0xFFFFFFFF
    return crc


def test_qgroundcontrol_connect_sequence_answers_within_its_timeouts(qgc: GroundStation) -> None:
    started = time.monotonic()
    heartbeat(qgc)
    steps: dict[str, float] = {}

    def step(name: str, action: Callable[[], Any]) -> Any:
        t0 = time.monotonic()
        result = action()
        steps[name] = time.monotonic() - t0
        return result

    # 1. AUTOPILOT_VERSION, then the protocol version (MAVLink 2)
    assert step("autopilot_version", lambda: qgc.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 148)) == ACCEPTED
    version = wait_until(lambda: qgc.latest("AUTOPILOT_VERSION"), COMMAND_ACK_TIMEOUT_S, "AUTOPILOT_VERSION")
    for capability in ("MISSION_INT", "MISSION_FENCE", "MISSION_RALLY", "FTP", "MAVLINK2", "PARAM_ENCODE_BYTEWISE"):
        assert version.capabilities & getattr(mavlink, f"MAV_PROTOCOL_CAPABILITY_{capability}"), capability
    assert step("protocol_version", lambda: qgc.command(519)) == ACCEPTED
    # 2. The full parameter list: _HASH_CHECK first, then every parameter once; two "lost" ones re-requested
    qgc.messages.clear()
    qgc.send(qgc.mav.param_request_list_encode(qgc.vehicle_sysid, 1))
    t0 = time.monotonic()
    values: dict[str, Any] = {}
    first = answer(qgc, lambda m: m.get_type() == "PARAM_VALUE", PARAM_TIMEOUT_S, "the first PARAM_VALUE")
    assert first.param_id == "_HASH_CHECK"
    assert first.param_index == 65535
    total = first.param_count

    def all_params() -> bool:
        qgc.poll()
        for msg in qgc.messages:
            if msg.get_type() == "PARAM_VALUE" and msg.param_id != "_HASH_CHECK":
                values[msg.param_id] = msg
        return len(values) >= int(total)

    wait_until(all_params, PARAM_TIMEOUT_S, f"{total} parameters", poll_s=0.005)
    steps["param_list"] = time.monotonic() - t0
    assert total >= 150
    for name in ("SYS_AUTOSTART", "CAL_ACC0_ID", "CAL_GYRO0_ID", "CAL_MAG0_ID", "RC_MAP_THROTTLE", "COM_FLTMODE1"):
        assert name in values, name
    assert struct.unpack("<i", struct.pack("<f", values["SYS_AUTOSTART"].param_value))[0] == 4001
    assert sorted(values) == [values[n].param_id for n in sorted(values, key=lambda n: values[n].param_index)]
    qgc.messages.clear()
    for lost in ("RC3_MAX", "BAT1_N_CELLS"):
        qgc.send(qgc.mav.param_request_read_encode(qgc.vehicle_sysid, 1, b"", values[lost].param_index))
        named = functools.partial(lambda m, name: m.get_type() == "PARAM_VALUE" and m.param_id == name, name=lost)
        again = answer(qgc, named, PARAM_TIMEOUT_S, lost)
        assert again.param_value == values[lost].param_value
    # The hash QGroundControl computes over its cache equals the vehicle's: the next connect can use the cache.
    vehicle_hash = struct.unpack("<I", struct.pack("<f", first.param_value))[0]
    assert hash_of(values) == vehicle_hash
    qgc.send(qgc.mav.param_request_read_encode(qgc.vehicle_sysid, 1, b"_HASH_CHECK", -1))
    cached = answer(qgc, lambda m: m.get_type() == "PARAM_VALUE", PARAM_TIMEOUT_S, "_HASH_CHECK by name")
    assert cached.param_id == "_HASH_CHECK"
    assert cached.param_value == first.param_value
    # 3. Mission, fence and rally lists (empty), then home
    for mission_type in (0, 1, 2):
        assert step(f"list_{mission_type}", functools.partial(mission_list, qgc, mission_type)) == []
    assert step("home", lambda: qgc.command(mavlink.MAV_CMD_GET_HOME_POSITION)) == ACCEPTED
    home = wait_until(lambda: qgc.latest("HOME_POSITION"), COMMAND_ACK_TIMEOUT_S, "HOME_POSITION")
    assert home.latitude == pytest.approx(ORIGIN[0] * 1e7, abs=2)
    # 4. Stream rates, as QGroundControl's fly view asks for them
    rate = step("interval", lambda: qgc.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 74, 100_000))
    assert rate == ACCEPTED
    assert qgc.command(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, 74) == ACCEPTED
    interval = wait_until(lambda: qgc.latest("MESSAGE_INTERVAL"), COMMAND_ACK_TIMEOUT_S, "MESSAGE_INTERVAL")
    assert (interval.message_id, interval.interval_us) == (74, 100_000)
    assert qgc.command(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, 9999) == ACCEPTED
    assert wait_until(lambda: qgc.latest("MESSAGE_INTERVAL"), 1, "MESSAGE_INTERVAL").interval_us == 0
    total_s = time.monotonic() - started
    assert total_s < 3.0, steps
    assert all(v < COMMAND_ACK_TIMEOUT_S for k, v in steps.items() if k != "param_list"), steps


def test_default_streams_a_ground_station_reads(qgc: GroundStation) -> None:
    for kind in (
        "VFR_HUD",
        "ALTITUDE",
        "ESTIMATOR_STATUS",
        "VIBRATION",
        "RC_CHANNELS",
        "SERVO_OUTPUT_RAW",
        "NAV_CONTROLLER_OUTPUT",
        "POSITION_TARGET_LOCAL_NED",
        "MISSION_CURRENT",
    ):
        wait_until(functools.partial(qgc.latest, kind), 5, kind)
    hud = qgc.latest("VFR_HUD")
    assert hud.alt == pytest.approx(ORIGIN[2], abs=0.5)
    assert hud.groundspeed == pytest.approx(0.0, abs=0.1)
    assert qgc.latest("MISSION_CURRENT").mission_state == mavlink.MISSION_STATE_NO_MISSION
    assert qgc.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN) == ACCEPTED
    origin = answer(qgc, lambda m: m.get_type() == "GPS_GLOBAL_ORIGIN", 2, "GPS_GLOBAL_ORIGIN")
    assert origin.latitude == pytest.approx(ORIGIN[0] * 1e7, abs=2)
    # At the rate asked for: VIBRATION at 20 Hz of simulated time instead of 0.5 Hz.
    assert qgc.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_VIBRATION, 50_000) == ACCEPTED
    qgc.messages.clear()

    def vibrations() -> int:
        qgc.poll()
        return sum(m.get_type() == "VIBRATION" for m in qgc.messages) >= 10  # type: ignore[no-any-return]

    wait_until(vibrations, 2, "ten VIBRATION messages")


def test_ftp_is_refused_at_once_and_parameters_stay_fast(qgc: GroundStation) -> None:
    # MAVProxy's first step of `param fetch`: open @PARAM/param.pck over MAVLink FTP.
    name = b"@PARAM/param.pck?withdefaults=1"
    header = struct.pack("<HBBBBBBI", 7, 0, 4, len(name), 0, 0, 0, 0)
    payload = list(header + name + bytes(251 - 12 - len(name)))
    qgc.send(qgc.mav.file_transfer_protocol_encode(0, qgc.vehicle_sysid, 1, payload))
    reply = answer(qgc, lambda m: m.get_type() == "FILE_TRANSFER_PROTOCOL", 0.5, "the FTP answer")
    seq, _session, opcode, size, req_opcode = struct.unpack_from("<HBBBB", bytes(reply.payload))
    assert (seq, opcode, size, req_opcode, reply.payload[12]) == (8, 129, 1, 4, 10)  # NAK FileNotFound
    assert (reply.target_system, reply.target_component) == (255, 190)


def test_parameters_as_px4_stores_them(qgc: GroundStation, gcs_sitl: tuple[SitlProcess, int]) -> None:
    sitl, _ = gcs_sitl
    # Out of range: stored and echoed as PX4 does, with a warning; the vehicle flies with the clamped value.
    qgc.send(qgc.mav.param_set_encode(qgc.vehicle_sysid, 1, b"MPC_XY_VEL_MAX", 50.0, 9))
    warning = answer(qgc, lambda m: m.get_type() == "STATUSTEXT", 2, "the warning")
    assert warning.severity == mavlink.MAV_SEVERITY_WARNING
    assert "MPC_XY_VEL_MAX" in warning.text
    echo = answer(qgc, lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "MPC_XY_VEL_MAX", 2, "the echo")
    assert echo.param_value == 50.0
    # NaN is never stored.
    qgc.send(qgc.mav.param_set_encode(qgc.vehicle_sysid, 1, b"MPC_XY_VEL_MAX", math.nan, 9))
    echo = answer(qgc, lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "MPC_XY_VEL_MAX", 2, "the echo")
    assert echo.param_value == 50.0
    qgc.send(qgc.mav.param_set_encode(qgc.vehicle_sysid, 1, b"MPC_XY_VEL_MAX", 5.0, 9))
    # A takeoff to 7 m leaves MIS_TAKEOFF_ALT alone (PX4 does; a parameter view must not go stale).
    assert qgc.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
    alt_amsl = ORIGIN[2] + 7.0
    assert qgc.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, alt_amsl) == ACCEPTED
    wait_until(lambda: -sitl.state()["position_ned_m"][2] > 6.5, 20, "the climb to 7 m")
    qgc.send(qgc.mav.param_request_read_encode(qgc.vehicle_sysid, 1, b"MIS_TAKEOFF_ALT", -1))
    value = answer(qgc, lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "MIS_TAKEOFF_ALT", 2, "the read")
    assert value.param_value == pytest.approx(2.5)


def test_refusals_are_critical_and_long_texts_come_in_chunks(qgc: GroundStation) -> None:
    # A mode this SITL does not fly (MANUAL) by SET_MODE: answered as DO_SET_MODE, with a CRITICAL text.
    qgc.messages.clear()
    qgc.send(qgc.mav.set_mode_encode(qgc.vehicle_sysid, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 1 << 16))
    ack = answer(qgc, lambda m: m.get_type() == "COMMAND_ACK", COMMAND_ACK_TIMEOUT_S, "the SET_MODE answer")
    assert (ack.command, ack.result) == (mavlink.MAV_CMD_DO_SET_MODE, UNSUPPORTED)
    # The text went out before the ACK; a ground station shows it at once (CRITICAL), whole.
    chunks = []
    while True:
        text = answer(qgc, lambda m: m.get_type() == "STATUSTEXT", 2, "the refusal text")
        chunks.append(text)
        if len(text.text) < 50:
            break
    assert all(c.severity == mavlink.MAV_SEVERITY_CRITICAL for c in chunks)
    assert len(chunks) >= 2
    assert len({c.id for c in chunks}) == 1
    assert chunks[0].id != 0
    assert [c.chunk_seq for c in chunks] == list(range(len(chunks)))
    assert "".join(c.text for c in chunks) == "Switching to mode MANUAL is not available in this SITL"
    # Mission mode without a mission: refused, CRITICAL.
    assert qgc.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 4, 4) == DENIED
    text = answer(qgc, lambda m: m.get_type() == "STATUSTEXT", 2, "the mission refusal")
    assert text.severity == mavlink.MAV_SEVERITY_CRITICAL
    assert "no mission" in text.text


def test_mission_fence_and_rally_upload_download_and_a_mission_flown(
    qgc: GroundStation, gcs_sitl: tuple[SitlProcess, int]
) -> None:
    sitl, _ = gcs_sitl
    rel = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    a, b = geo(8.0, 0.0), geo(8.0, 8.0)
    mission = [
        (rel, mavlink.MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 6.0, []),
        (rel, mavlink.MAV_CMD_NAV_WAYPOINT, *a, 6.0, [0.0, 1.0]),
        (rel, mavlink.MAV_CMD_NAV_WAYPOINT, *b, 6.0, [0.0, 1.0]),
        (rel, mavlink.MAV_CMD_NAV_LAND, *b, 0.0, []),
    ]
    assert upload(qgc, mission) == 0
    down = mission_list(qgc, 0)
    assert [m.command for m in down] == [22, 16, 16, 21]
    assert (down[1].x, down[1].y, down[1].z) == (round(a[0] * 1e7), round(a[1] * 1e7), 6.0)
    corners = [geo(n, e) for n, e in ((-20, -20), (-20, 20), (20, 20), (20, -20))]
    fence = [(5, 5001, *c, 0.0, [4.0]) for c in corners]
    assert upload(qgc, fence, mission_type=1) == 0
    assert len(mission_list(qgc, 1)) == 4
    assert upload(qgc, [(6, 5100, *geo(3.0, 3.0), 10.0, [])], mission_type=2) == 0
    assert len(mission_list(qgc, 2)) == 1
    # Refused items name what is wrong, and leave the stored list alone.
    assert upload(qgc, [(rel, 183, *a, 6.0, [])]) == mavlink.MAV_MISSION_UNSUPPORTED  # DO_SET_SERVO
    assert upload(qgc, [(rel, 16, 91.0, 0.0, 6.0, [])]) == mavlink.MAV_MISSION_INVALID_PARAM5_X
    assert upload(qgc, [(5, 5001, *corners[0], 0.0, [4.0])], mission_type=1) == mavlink.MAV_MISSION_INVALID
    assert len(mission_list(qgc, 0)) == 4
    # Flown in AUTO.MISSION: armed in mission mode, the items reached in order, landed at the last one.
    assert qgc.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 4, 4) == ACCEPTED
    assert qgc.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
    reached: list[int] = []

    def landed() -> bool:
        reached.extend(m.seq for m in qgc.poll() if m.get_type() == "MISSION_ITEM_REACHED")
        state = sitl.state()
        return not state["armed"] and state["landed_state"] == "ON_GROUND" and len(reached) >= 4

    wait_until(landed, 60, "the mission flown and landed")
    assert reached == [0, 1, 2, 3]
    north, east, _ = sitl.state()["position_ned_m"]
    assert math.hypot(north - 8.0, east - 8.0) < 1.0
    # Cleared: the lists are empty again.
    qgc.send(qgc.mav.mission_clear_all_encode(qgc.vehicle_sysid, 1, 255))
    answer(qgc, lambda m: m.get_type() == "MISSION_ACK", MISSION_TIMEOUT_S, "the clear ACK")
    assert mission_list(qgc, 0) == []
    assert mission_list(qgc, 1) == []


def test_fly_view_commands(qgc: GroundStation, gcs_sitl: tuple[SitlProcess, int]) -> None:
    sitl, _ = gcs_sitl
    assert qgc.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
    assert qgc.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, ORIGIN[2] + 5) == 0
    wait_until(lambda: sitl.state()["mode"] == "AUTO.LOITER", 20, "the takeoff done")
    # Go to a location (QGroundControl sends DO_REPOSITION as COMMAND_INT, relative altitude).
    lat, lon = geo(6.0, -4.0)
    qgc.messages.clear()
    qgc.send(
        qgc.mav.command_int_encode(
            qgc.vehicle_sysid, 1, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink.MAV_CMD_DO_REPOSITION, 0, 0,
            -1, 1, 0, math.nan, round(lat * 1e7), round(lon * 1e7), 8.0,
        )
    )  # fmt: skip
    ack = answer(qgc, lambda m: m.get_type() == "COMMAND_ACK", COMMAND_ACK_TIMEOUT_S, "the reposition ACK")
    assert (ack.command, ack.result) == (mavlink.MAV_CMD_DO_REPOSITION, ACCEPTED)

    def near(n: float, e: float, d: float, tol: float) -> Callable[[], bool]:
        def check() -> bool:
            p = sitl.state()["position_ned_m"]
            return math.dist(p, (n, e, d)) < tol

        return check

    wait_until(near(6.0, -4.0, -8.0, 0.5), 30, "the vehicle at the go-to point")
    # Orbit 5 m around the origin at 2 m/s: it goes round, 5 m from the centre.
    assert qgc.command(mavlink.MAV_CMD_DO_ORBIT, 5.0, 2.0, 0, 0, *geo(0.0, 0.0), math.nan) == ACCEPTED
    assert sitl.state()["mode"] == "POSCTL.ORBIT"
    angles: list[float] = []

    def went_round() -> bool:
        n, e, _ = sitl.state()["position_ned_m"]
        if abs(math.hypot(n, e) - 5.0) < 0.7:
            angles.append(math.atan2(e, n))
        unwrapped = sum((b - a + math.pi) % (2 * math.pi) - math.pi for a, b in itertools.pairwise(angles))
        return unwrapped > math.pi

    wait_until(went_round, 40, "half an orbit")
    # The pilot's joystick in POSCTL: full forward moves the vehicle along its heading.
    assert qgc.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 3, 0) == ACCEPTED
    start = sitl.state()["position_ned_m"]
    deadline = time.monotonic() + 15

    def moved() -> bool:
        qgc.send(qgc.mav.manual_control_encode(qgc.vehicle_sysid, 1000, 0, 500, 0, 0))
        return math.dist(sitl.state()["position_ned_m"][:2], start[:2]) > 3.0

    wait_until(moved, max(deadline - time.monotonic(), 1.0), "the vehicle moved by the joystick", poll_s=0.05)
    # Pause (hold) and land.
    assert qgc.command(mavlink.MAV_CMD_NAV_LAND) == ACCEPTED
    wait_until(lambda: not sitl.state()["armed"], 40, "landed and disarmed")


def test_two_ground_stations_on_one_link_each_get_everything(
    qgc: GroundStation, gcs_sitl: tuple[SitlProcess, int]
) -> None:
    sitl, _ = gcs_sitl
    second = GroundStation(sitl.instance, free_udp_port())
    try:
        second.vehicle_addr = qgc.vehicle_addr  # a second QGroundControl that knows the vehicle's address
        second.mav.srcSystem = 254
        for station in (qgc, second):
            heartbeat(station)
        qgc.messages.clear()
        second.messages.clear()
        qgc.heartbeat_wall_times.clear()
        second.heartbeat_wall_times.clear()
        t0 = time.monotonic()

        def both_heard() -> bool:
            for station in (qgc, second):
                station.poll()
                if time.monotonic() - t0 > 1.0:
                    heartbeat(station)  # ground stations send theirs at 1 Hz
            return time.monotonic() - t0 > 5.0

        wait_until(both_heard, 8, "five seconds of telemetry", poll_s=0.1)
        counts = [
            (len(s.heartbeat_wall_times), sum(m.get_type() == "ATTITUDE" for m in s.messages)) for s in (qgc, second)
        ]
        for beats, attitudes in counts:
            assert beats >= 4
            assert attitudes >= 0.8 * 10 * 4 * 5
        # Both can command, and each hears its own ACK.
        assert second.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) == ACCEPTED
        assert qgc.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) == ACCEPTED
        assert sitl.state()["links"]["gcs"]["stray_frames"] == 0
    finally:
        second.close()


def test_modes_round_trip_through_their_names() -> None:
    assert FlightMode.from_name("mission") is FlightMode.AUTO_MISSION
    assert FlightMode.ORBIT.px4_name == "POSCTL.ORBIT"


def test_an_uploaded_fence_is_enforced_as_gf_action_says(qgc: GroundStation, gcs_sitl: tuple[SitlProcess, int]) -> None:
    sitl, _ = gcs_sitl
    # An exclusion circle over home: arming is refused, as PX4 refuses it outside the fence.
    assert upload(qgc, [(5, 5004, *geo(0.0, 0.0), 0.0, [5.0])], mission_type=1) == 0
    assert qgc.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == DENIED
    text = answer(qgc, lambda m: m.get_type() == "STATUSTEXT", 2, "the arming refusal")
    assert "outside the geofence" in text.text
    assert text.severity == mavlink.MAV_SEVERITY_CRITICAL
    # A 20 m square around home instead; a go-to 25 m north leaves it: GF_ACTION 2 (PX4's default) holds.
    square = [geo(n, e) for n, e in ((-10, -10), (-10, 10), (10, 10), (10, -10))]
    assert upload(qgc, [(5, 5001, *c, 0.0, [4.0]) for c in square], mission_type=1) == 0
    assert qgc.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
    assert qgc.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, ORIGIN[2] + 5) == 0
    wait_until(lambda: sitl.state()["mode"] == "AUTO.LOITER", 20, "the takeoff done")
    lat, lon = geo(25.0, 0.0)
    assert qgc.command(mavlink.MAV_CMD_DO_REPOSITION, -1, 1, 0, math.nan, lat, lon, ORIGIN[2] + 5) == ACCEPTED
    state = state_when(sitl, lambda s: s["failsafe"] == "Geofence breached", 30, "the breach")
    assert state["mode"] == "AUTO.LOITER"
    stopped = state_when(sitl, lambda s: math.hypot(*s["velocity_ned_mps"][:2]) < 0.2, 20, "the vehicle stopped")
    assert 10.0 < stopped["position_ned_m"][0] < 16.0  # braked just past the edge, nowhere near the go-to point
    breach = answer(qgc, lambda m: m.get_type() == "STATUSTEXT" and "Geofence breached" in m.text, 2, "the text")
    assert breach.severity == mavlink.MAV_SEVERITY_CRITICAL
