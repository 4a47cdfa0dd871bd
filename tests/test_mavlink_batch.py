"""A telemetry pass leaves a link in as few datagrams as fit, with the same frames as one send per message.

Real UDP on loopback between a :class:`MavlinkLink` and a plain socket; the frames are parsed with pymavlink as a
receiver (MAVSDK, MAVProxy, QGroundControl) parses a datagram: frame after frame.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl.autopilot.mavlink_link import MAX_DATAGRAM_BYTES, MavlinkLink

pytestmark = pytest.mark.unit

SYSTEM_ID = 1
RECEIVE_TIMEOUT_S = 2.0


@pytest.fixture
def receiver() -> Iterator[socket.socket]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(RECEIVE_TIMEOUT_S)
    yield sock
    sock.close()


def link_to(receiver: socket.socket) -> MavlinkLink:
    return MavlinkLink("api", "127.0.0.1", 0, receiver.getsockname()[1], SYSTEM_ID)


def attitudes(link: MavlinkLink, count: int) -> list[object]:
    """``count`` distinct ATTITUDE messages (no trailing zeros, so every frame has its full length)."""
    return [link.mav.attitude_encode(1000 + i, 0.1 + i, 0.2, 0.3, 0.4, 0.5, 0.6) for i in range(count)]


def receive_datagrams(sock: socket.socket, count: int) -> list[bytes]:
    return [sock.recvfrom(65535)[0] for _ in range(count)]


def test_a_pass_is_the_frames_of_one_send_each_in_fewer_datagrams(receiver: socket.socket) -> None:
    batched, single = link_to(receiver), link_to(receiver)
    try:
        count = 70  # about 40 bytes a frame: three datagrams of at most 1,200 bytes
        batched.send_all(attitudes(batched, count))
        datagrams = receive_datagrams(receiver, 3)
        for message in attitudes(single, count):
            single.send(message)
        one_each = receive_datagrams(receiver, count)
    finally:
        batched.close()
        single.close()
    assert all(len(d) <= MAX_DATAGRAM_BYTES for d in datagrams)
    assert b"".join(datagrams) == b"".join(one_each)  # the same bytes: frames, sequence numbers, order
    assert batched.stats.sent == single.stats.sent == count  # frames, not datagrams
    parser = mavlink.MAVLink(None)
    frames = [m for d in datagrams for m in parser.parse_buffer(d) or []]
    assert [m.time_boot_ms for m in frames] == [1000 + i for i in range(count)]
    assert [m.get_seq() for m in frames] == [i % 256 for i in range(count)]
    assert parser.total_receive_errors == 0


def test_a_frame_never_straddles_two_datagrams(receiver: socket.socket) -> None:
    link = link_to(receiver)
    try:
        text = link.mav.statustext_encode(6, b"x" * 50)  # a long frame after many short ones
        link.send_all([*attitudes(link, 29), text])
        first, second = receive_datagrams(receiver, 2)
    finally:
        link.close()
    parser = mavlink.MAVLink(None)
    assert [m.get_type() for m in parser.parse_buffer(first) or []] == ["ATTITUDE"] * 29
    assert parser.buf_len() == 0  # nothing left over: the datagram ends on a frame's end
    assert [m.get_type() for m in parser.parse_buffer(second) or []] == ["STATUSTEXT"]


def test_a_cut_link_sends_nothing_and_keeps_counting_sequence(receiver: socket.socket) -> None:
    link = link_to(receiver)
    try:
        link.cut = True
        link.send_all(attitudes(link, 5))
        link.cut = False
        link.send_all(attitudes(link, 1))
        (datagram,) = receive_datagrams(receiver, 1)
    finally:
        link.close()
    (message,) = mavlink.MAVLink(None).parse_buffer(datagram) or []
    assert message.get_seq() == 5  # as five single sends over a cut link: numbered, never sent
    assert link.stats.sent == 1


def test_nothing_to_send_sends_nothing(receiver: socket.socket) -> None:
    link = link_to(receiver)
    try:
        link.send_all([])
        link.send(link.mav.heartbeat_encode(2, 12, 0, 0, 3))
        (datagram,) = receive_datagrams(receiver, 1)
    finally:
        link.close()
    (message,) = mavlink.MAVLink(None).parse_buffer(datagram) or []
    assert message.get_type() == "HEARTBEAT"
    assert message.get_seq() == 0
