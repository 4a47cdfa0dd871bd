"""The control channel vocabulary shared by the SITL and its clients: requests built, events parsed, bad ones named."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from companion.vehicle.sim_control import (
    Command,
    Event,
    LockstepAck,
    RequestError,
    SetpointNedYaw,
    Tick,
    ack_counting,
    ack_expecting,
    decode_event,
    encode,
    frames_wanted,
    lockstep_ack,
    parse_request,
    same_setpoint,
    subscribe_request,
)

pytestmark = pytest.mark.unit


def test_a_tick_goes_out_and_comes_back_the_same() -> None:
    tick = Tick(seq=7, t_s=0.7, frame_seq=6)
    event = decode_event(json.dumps(tick.to_event()).encode())
    assert event is not None
    assert event["event"] == Event.TICK
    assert Tick.from_event(event) == tick
    assert Tick.from_event({**tick.to_event(), "frame_seq": None}).frame_seq is None


@pytest.mark.parametrize(
    ("field", "value", "named"),
    [("seq", -1, "seq"), ("seq", "7", "seq"), ("t_s", float("nan"), "t_s"), ("frame_seq", 1.5, "frame_seq")],
)
def test_a_malformed_tick_names_its_field(field: str, value: object, named: str) -> None:
    with pytest.raises(RequestError, match=named):
        Tick.from_event({**Tick(1, 0.1, 0).to_event(), field: value})


def test_both_kinds_of_acknowledgement_pass_the_sitl_s_checks() -> None:
    expecting = parse_request(ack_expecting(Tick(3, 0.3, 2), SetpointNedYaw(1.0, 2.0, -20.0, 0.5)))
    assert expecting["cmd"] == Command.LOCKSTEP_ACK
    assert lockstep_ack(expecting) == LockstepAck(3, True, expect_setpoint=(1.0, 2.0, -20.0, 0.5))
    counting = parse_request(ack_counting(4, 120, 245, 190))
    assert lockstep_ack(counting) == LockstepAck(4, True, counted=(120, 245, 190))


def test_a_client_can_ask_for_ticks_without_frames_and_for_frames_again() -> None:
    subscribe = parse_request(subscribe_request(1, frames=False))
    assert subscribe["cmd"] == Command.LOCKSTEP_SUBSCRIBE
    assert not frames_wanted(subscribe)
    assert frames_wanted(parse_request(subscribe_request(1)))  # the default, as every older client sends it
    without = lockstep_ack(parse_request(ack_expecting(Tick(3, 0.3, None), None, frames=False)))
    assert without == LockstepAck(3, False)  # expects nothing: moves on at once
    assert lockstep_ack(parse_request(ack_expecting(Tick(4, 0.4, None), None))).frames


@pytest.mark.parametrize("value", ["false", 0, None, [False]])
def test_a_frames_flag_that_is_not_a_json_boolean_is_refused(value: object) -> None:
    with pytest.raises(RequestError, match="frames"):
        lockstep_ack({"cmd": "lockstep_ack", "seq": 1, "expect": {}, "frames": value})


def test_every_command_encodes_as_a_request_the_sitl_parses() -> None:
    for command in Command:
        assert parse_request(encode(command))["cmd"] == command.value


@pytest.mark.parametrize("data", [b"", b"\xff", b"[1]", b'{"no": "event"}', b'{"event": 5}', b"[" * 5000])
def test_anything_but_an_event_is_refused_for_counting(data: bytes) -> None:
    assert decode_event(data) is None


def test_a_setpoint_is_the_same_as_float32_travels_it_and_its_yaw_within_1e_4_rad() -> None:
    sent = SetpointNedYaw(1.0000000001, -2.5, -20.0, math.radians(90.0))
    arrived = tuple(float(np.float32(v)) for v in sent)  # as SET_POSITION_TARGET_LOCAL_NED carries it
    assert same_setpoint(arrived, list(sent))
    assert not same_setpoint(arrived, [1.001, -2.5, -20.0, sent.yaw_rad])  # a millimetre: the previous setpoint
    assert not same_setpoint(arrived, [*sent[:3], sent.yaw_rad + 2e-4])
