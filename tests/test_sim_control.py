"""The control channel vocabulary shared by the SITL and its clients: requests built, events parsed, bad ones named."""

from __future__ import annotations

import json

import pytest

from companion.vehicle.sim_control import (
    Command,
    Event,
    RequestError,
    Tick,
    ack_counting,
    ack_expecting,
    decode_event,
    encode,
    lockstep_ack,
    parse_request,
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
    expecting = parse_request(ack_expecting(Tick(3, 0.3, 2), (1.0, 2.0, -20.0, 0.5)))
    assert expecting["cmd"] == Command.LOCKSTEP_ACK
    assert lockstep_ack(expecting) == {"seq": 3, "expect": {"setpoint": [1.0, 2.0, -20.0, 0.5]}}
    counting = parse_request(ack_counting(4, 120, 245, 190))
    assert lockstep_ack(counting) == {"seq": 4, "mavlink_sent": 120, "sysid": 245, "compid": 190}


def test_every_command_encodes_as_a_request_the_sitl_parses() -> None:
    for command in Command:
        assert parse_request(encode(command))["cmd"] == command.value


@pytest.mark.parametrize("data", [b"", b"\xff", b"[1]", b'{"no": "event"}', b'{"event": 5}', b"[" * 5000])
def test_anything_but_an_event_is_refused_for_counting(data: bytes) -> None:
    assert decode_event(data) is None
