"""Each hostile input found by hand (issue 23), one at a time, against a running SITL: refused, counted, survived.

The seeded fuzz of the same ports is tests/test_sitl_fuzz.py.
"""

from __future__ import annotations

import hashlib
import json
import socket
import struct
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl.autopilot.mavlink_link import SIGNING_EPOCH_UNIX_S
from sitl.config import SitlConfig
from sitl.harness.process import SitlProcess
from sitl.testing.helpers import MavlinkPeer, api_port, wait_until

pytestmark = pytest.mark.sitl

ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED = 0, 1, 2, 3
NAN, INF = float("nan"), float("inf")


@pytest.fixture(scope="module")
def sitl(tmp_path_factory: pytest.TempPathFactory, module_instance: int) -> Iterator[SitlProcess]:
    with SitlProcess(["--speed", "1"], module_instance, tmp_path_factory.mktemp("sitl")) as process:
        yield process


@pytest.fixture
def api(sitl: SitlProcess) -> Iterator[MavlinkPeer]:
    peer = MavlinkPeer(api_port(sitl.instance), system_id=245, component_id=190)
    wait_until(lambda: peer.latest("HEARTBEAT"), 5, "a heartbeat")
    yield peer
    peer.close()


def control(sitl: SitlProcess, payload: bytes, timeout_s: float = 2.0) -> dict[str, Any]:
    """Send raw bytes to the control port; the SITL's reply."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        s.settimeout(timeout_s)
        s.sendto(payload, sitl.control_addr)
        data, _ = s.recvfrom(65535)
    reply: dict[str, Any] = json.loads(data)
    return reply


@pytest.mark.parametrize(
    ("command", "params"),
    [
        (mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, (NAN, 1e5)),
        (mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, (INF, 1e5)),
        (mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, (32.0, NAN)),
        (mavlink.MAV_CMD_REQUEST_MESSAGE, (NAN,)),
        (mavlink.MAV_CMD_REQUEST_MESSAGE, (-INF,)),
        (mavlink.MAV_CMD_DO_SET_MODE, (NAN, 4.0, 3.0)),
        (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (NAN,)),
        (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (0.7,)),
        (mavlink.MAV_CMD_DO_CHANGE_SPEED, (1.0, 3.4e38)),
    ],
)
def test_a_command_with_a_non_finite_or_meaningless_parameter_is_denied_and_the_sitl_lives(
    sitl: SitlProcess, api: MavlinkPeer, command: int, params: tuple[float, ...]
) -> None:
    for as_int in (False, True):
        p = [*params, *([0.0] * (7 - len(params)))]
        api.messages.clear()
        if as_int:
            api.send(api.mav.command_int_encode(sitl.instance + 1, 1, 1, command, 0, 0, *p[:4], 0, 0, p[6]))
        else:
            api.send(api.mav.command_long_encode(sitl.instance + 1, 1, command, 0, *p))

        def ack() -> Any:
            return next((m for m in api.poll() if m.get_type() == "COMMAND_ACK" and m.command == command), None)

        assert wait_until(ack, 2.0, f"COMMAND_ACK for {command}").result == DENIED
    state = sitl.state()
    assert state["handler_errors"] == 0
    assert state["armed"] is False
    assert state["mode"] == "AUTO.LOITER"


def test_a_stray_sender_is_served_but_does_not_take_the_link(sitl: SitlProcess, api: MavlinkPeer) -> None:
    api.send(api.mav.heartbeat_encode(6, 8, 0, 0, 4))
    partner = f"127.0.0.1:{api_port(sitl.instance)}"
    wait_until(lambda: sitl.state()["links"]["api"]["partner"] == partner or None, 3.0, "the API partner")
    before = sitl.state()["links"]["api"]["stray_frames"]
    stray = MavlinkPeer(0, system_id=66, component_id=1)
    stray.vehicle_addr = ("127.0.0.1", SitlConfig(instance=sitl.instance).api_port_local)
    try:
        for _ in range(20):
            stray.send(stray.mav.system_time_encode(0, 0))
        links = wait_until(
            lambda: ((s := sitl.state()["links"]["api"])["stray_frames"] >= before + 20 and s) or None,
            3.0,
            "the stray frames counted",
        )
        assert links["partner"] == partner
        # A sender with heartbeats (a second ground station) is sent everything too, but does not take the link.
        stray.send(stray.mav.heartbeat_encode(6, 8, 0, 0, 4))
        wait_until(lambda: stray.latest("LOCAL_POSITION_NED"), 2.0, "telemetry to the second peer")
        links = sitl.state()["links"]["api"]
        assert links["stray_frames"] == before + 20
    finally:
        stray.close()
    assert links["partner"] == partner
    # The partner still gets the telemetry.
    api.messages.clear()
    wait_until(lambda: api.latest("LOCAL_POSITION_NED"), 2.0, "telemetry to the partner")


@pytest.mark.parametrize(
    ("payload", "error"),
    [
        (b'{"cmd":"ping","x":' + b"[" * 1000 + b"]" * 1000 + b"}", "nested deeper"),
        (b'{"cmd":"lockstep_ack","seq":Infinity}', "Infinity is not a number"),
        (b'{"cmd":"pilot_sticks","north":NaN}', "NaN is not a number"),
        (b'{"cmd":"wind","ned_mps":[1e999,0,0]}', "overflows"),
        (b'{"cmd":"wind","ned_mps":[1e4,0,0]}', "ned_mps"),
        (b'{"cmd":"wind","ned_mps":[1e308,0,0]}', "ned_mps"),
        (b'{"cmd":"rc_loss","lost":"false"}', "lost: expected true or false"),
        (b'{"cmd":"pilot_sticks","north":"0.5"}', "north: expected a number"),
        (b'{"cmd":"pilot_sticks","north":2.0}', "north: must lie in [-1, 1]"),
        (b'{"cmd":"lockstep_ack","seq":1,"mavlink_sent":1,"sysid":1,"compid":1}', "lockstep"),
        (b'{"cmd":"pilot_mode","mode":["POSCTL"]}', "mode"),
        (b"\xff\xfe\x00", "malformed request"),
        (b"[1, 2, 3]", "expected an object"),
        (json.dumps({"cmd": "ping", "pad": "x" * 9000}).encode(), "bytes"),
    ],
)
def test_a_hostile_control_request_is_answered_with_an_error_and_changes_nothing(
    sitl: SitlProcess, payload: bytes, error: str
) -> None:
    reply = control(sitl, payload)
    assert reply["event"] == "error"
    assert error in reply["error"]
    state = sitl.state()
    assert state["rc_lost"] is False
    assert state["handler_errors"] == 0
    assert max(abs(v) for v in state["velocity_ned_mps"]) < 0.5  # no wind, no sticks: still on the ground


def test_a_state_reply_stays_one_datagram_after_thousands_of_senders(sitl: SitlProcess, api: MavlinkPeer) -> None:
    for sysid in range(1, 256, 3):
        for compid in range(0, 256, 64):
            mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
            # An unknown message id to the vehicle: counted by its sender, no effect.
            api.send_raw(mav.command_long_encode(sitl.instance + 1, 1, 31999, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav))
    state = wait_until(
        lambda: ((s := sitl.state())["commands_by_sender"].get("other", 0) > 0 and s) or None, 3.0, "the senders"
    )
    assert len(state["commands_by_sender"]) <= 33
    assert len(json.dumps(state)) < 60_000


def signed_frame(mav: Any, key: bytes, msg: Any, timestamp: int) -> bytes:
    """``msg`` packed and signed with ``key`` at ``timestamp`` (10 us units since 2015)."""
    mav.signing.secret_key = key
    mav.signing.sign_outgoing = True
    mav.signing.timestamp = timestamp
    data: bytes = msg.pack(mav)
    mav.seq = (mav.seq + 1) % 256
    return data


def test_with_a_signing_key_only_correctly_signed_fresh_frames_are_accepted(tmp_path: Path, instance: int) -> None:
    key = hashlib.sha256(b"slz lander test passphrase").digest()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        gcs_port = s.getsockname()[1]
    config = tmp_path / "sitl.yaml"
    config.write_text(f"sitl:\n  gcs_port_remote: {gcs_port}\n  signing:\n    key_hex: {key.hex()}\n    links: [gcs]\n")
    sitl = SitlProcess(["--config", str(config), "--speed", "1"], instance, tmp_path).start()
    gcs = MavlinkPeer(gcs_port, system_id=255, component_id=190)
    gcs.mav.signing.secret_key = key  # the peer, too, takes only frames signed with the key
    try:
        # The vehicle signs what it sends.
        hb = wait_until(lambda: gcs.latest("HEARTBEAT"), 5.0, "a signed heartbeat")
        assert hb.get_signed()
        sysid = SitlConfig(instance=instance).system_id
        request = gcs.mav.param_request_read_encode(sysid, 1, b"COM_OBL_RC_ACT", -1)

        def answered(data: bytes) -> bool:
            gcs.messages.clear()
            gcs.send_raw(data)
            try:
                wait_until(lambda: gcs.latest("PARAM_VALUE"), 1.0, "PARAM_VALUE")
            except AssertionError:
                return False
            return True

        now = int((time.time() - SIGNING_EPOCH_UNIX_S) * 100_000)  # MAVLink's signing clock: 10 us since 2015
        assert not answered(request.pack(mavlink.MAVLink(None, 255, 190)))  # unsigned
        wrong = hashlib.sha256(b"wrong").digest()
        assert not answered(signed_frame(mavlink.MAVLink(None, 255, 190), wrong, request, now))
        good = signed_frame(mavlink.MAVLink(None, 255, 190), key, request, now + 1)
        assert answered(good)
        assert not answered(good)  # the same frame again: a replay, refused by its timestamp
        assert sitl.state()["links"]["gcs"]["dropped_unsigned"] >= 3
    finally:
        gcs.close()
        sitl.stop()


def test_a_second_frame_client_is_refused_while_the_first_keeps_its_stream(tmp_path: Path, instance: int) -> None:
    config = tmp_path / "sitl.yaml"
    config.write_text("sitl:\n  camera:\n    enabled: true\n    width_px: 64\n    height_px: 48\n")
    sitl = SitlProcess(["--config", str(config), "--speed", "1"], instance, tmp_path).start()
    port = SitlConfig(instance=instance).frame_port
    first = socket.create_connection(("127.0.0.1", port), timeout=5.0)
    intruder: socket.socket | None = None
    try:
        first.settimeout(5.0)

        def read_frame(conn: socket.socket) -> int:
            def exactly(n: int) -> bytes:
                data = b""
                while len(data) < n:
                    chunk = conn.recv(n - len(data))
                    if not chunk:
                        raise ConnectionError("closed")
                    data += chunk
                return data

            assert exactly(4) == b"SLZF"
            (header_len,) = struct.unpack("<I", exactly(4))
            header = json.loads(exactly(header_len))
            (payload_len,) = struct.unpack("<I", exactly(4))
            exactly(payload_len)
            return int(header["seq"])

        seq = read_frame(first)
        intruder = socket.create_connection(("127.0.0.1", port), timeout=5.0)
        intruder.settimeout(5.0)
        assert intruder.recv(1) == b""  # closed at once: refused
        later = [read_frame(first) for _ in range(5)]
        assert later[-1] > seq
        frames = sitl.state()["frames"]
        assert frames["refused"] >= 1
        assert frames["clients"] == 1
    finally:
        first.close()
        if intruder is not None:
            intruder.close()
        sitl.stop()
