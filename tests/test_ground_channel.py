"""The ground station's command channel: MAVLink 2 frames against pymavlink, signing, and the channel's answers
over real UDP sockets on loopback (a pymavlink ground station on one side, the channel on the other)."""

from __future__ import annotations

import asyncio
import logging
import socket
import time
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.ground import mavlink_frames as frames
from companion.ground.command_channel import AckResult, CommandChannel, GroundCommand
from companion.guidance.vocabulary import OperatorCommand
from sitl.testing.helpers import free_udp_port, wait_until_async

pytestmark = pytest.mark.unit

KEY = frames.key_from_passphrase("slz ground test")
VEHICLE_SYSID = 1


class Gcs:
    """A pymavlink ground station (system 255, component 190) on its own UDP socket, signing with ``key`` if given."""

    def __init__(
        self,
        port: int,
        key: bytes | None = None,
        link_id: int = 0,
        reply_key: bytes | None = None,
        vehicle_sysid: int = VEHICLE_SYSID,
    ) -> None:
        self.vehicle_sysid = vehicle_sysid  # the companion answers on its autopilot's system id (issue 65)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.address = ("127.0.0.1", port)
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        if key is not None:
            self.mav.signing.secret_key = key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.link_id = link_id
            self.mav.signing.timestamp = frames.signing_timestamp(time.time())
        self.rx = mavlink.MAVLink(None)
        self.rx.signing.secret_key = reply_key  # None: reads unsigned replies
        self.received: list[Any] = []

    def command(
        self, mav_cmd: int, param1: float = 0.0, target_component: int = 191, target_system: int | None = None
    ) -> bytes:
        """Send COMMAND_LONG to the vehicle's system (or ``target_system``); the bytes sent."""
        target_system = self.vehicle_sysid if target_system is None else target_system
        msg = self.mav.command_long_encode(target_system, target_component, mav_cmd, 0, param1, 0, 0, 0, 0, 0, 0)
        data = msg.pack(self.mav)
        self.sock.sendto(data, self.address)
        return bytes(data)

    def poll(self) -> list[Any]:
        """The replies received so far (COMMAND_ACK, STATUSTEXT); after :meth:`close`, those read before it."""
        while self.sock.fileno() >= 0:
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                break
            self.received += self.rx.parse_buffer(data) or []
        return self.received

    def acks(self) -> list[tuple[int, int]]:
        return [(m.command, m.result) for m in self.poll() if m.get_type() == "COMMAND_ACK"]

    def texts(self) -> list[str]:
        return [m.text for m in self.poll() if m.get_type() == "STATUSTEXT"]

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> Gcs:
        return self

    def __exit__(self, *exc_info: object) -> None:
        """The replies still pending read (:meth:`texts` and :meth:`acks` keep them), then the socket closed."""
        self.poll()
        self.close()


@pytest.fixture
def port() -> int:
    return free_udp_port()


def test_frames_read_what_pymavlink_writes_and_pymavlink_reads_what_they_write() -> None:
    mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id, mav.signing.timestamp = KEY, True, 3, 77
    sent = mavlink.MAVLink_command_long_message(1, 191, 191, 0, 1.0, 2.5, 0, 0, 0, 0, -7.0).pack(mav)
    got = frames.unpack(bytes(sent), KEY)
    assert (got.sys_id, got.comp_id, got.link_id, got.timestamp, got.signature_ok) == (255, 190, 3, 77, True)
    assert got.fields["command"] == 191
    assert (got.fields["param1"], got.fields["param2"], got.fields["param7"]) == (1.0, 2.5, -7.0)
    assert frames.unpack(bytes(sent), frames.key_from_passphrase("another")).signature_ok is False
    cases: list[tuple[frames.MessageSpec, dict[str, Any]]] = [
        (frames.COMMAND_ACK, {"command": 31011, "result": 2, "result_param2": -5, "target_system": 255}),
        (frames.STATUSTEXT, {"severity": 4, "text": b"land_now denied: a person in the footprint"}),
        (frames.HEARTBEAT, {"type": 18, "autopilot": 8, "mavlink_version": 3}),
        (frames.COMMAND_LONG, {"command": 31010, "param1": 1.0, "target_system": 1, "target_component": 191}),
    ]
    for spec, values in cases:
        for key in (None, KEY):
            reader = mavlink.MAVLink(None)
            reader.signing.secret_key = key
            data = frames.pack(spec, values, 9, 1, 191, key, 0, 123456)
            (msg,) = reader.parse_buffer(data)
            read = msg.to_dict()
            assert all(read[k] == (v.decode() if isinstance(v, bytes) else v) for k, v in values.items()), read
            assert (msg.get_srcSystem(), msg.get_srcComponent()) == (1, 191)
            assert frames.unpack(data, key).fields == {**dict.fromkeys(spec.fields, 0), **values} | (
                {"text": values["text"].ljust(50, b"\0")} if "text" in values else {}
            )


@pytest.mark.parametrize(
    ("datagram", "why"),
    [
        (b"", "not a MAVLink 2 frame"),
        (b"\xfe\x09" + bytes(15), "not a MAVLink 2 frame"),  # MAVLink 1
        (frames.pack(frames.HEARTBEAT, {"type": 6}, 0, 255, 190)[:-1], "bytes where the header says"),
        (frames.pack(frames.HEARTBEAT, {"type": 6}, 0, 255, 190)[:-2] + b"\0\0", "bad crc"),
        (b"\xfd\x01\x00\x00\x00\xff\xbe\x21\x00\x00\x00\x00\x00", "not one the command channel reads"),
        (b"\xfd\x01\x04\x00\x00\xff\xbe\x00\x00\x00\x00\x00\x00", "unknown incompatibility flags"),
    ],
)
def test_a_datagram_that_is_not_a_frame_it_reads_is_a_frame_error_naming_why(datagram: bytes, why: str) -> None:
    with pytest.raises(frames.FrameError, match=why):
        frames.unpack(datagram)


async def run_channel(port: int, key: bytes | None, script: Any) -> CommandChannel:
    """Open a channel on ``port`` and run ``script(channel)`` (a coroutine function) beside it; closed after it."""
    channel = CommandChannel(f"udpin://127.0.0.1:{port}", VEHICLE_SYSID, key)
    await channel.open()
    try:
        await asyncio.wait_for(script(channel), timeout=20.0)
    finally:
        channel.close()
    return channel


async def test_with_a_key_only_signed_fresh_commands_are_taken_the_rest_refused_with_the_reason(port: int) -> None:
    good = Gcs(port, KEY, link_id=1, reply_key=KEY)
    unsigned, wrong = Gcs(port, reply_key=KEY), Gcs(port, frames.key_from_passphrase("x"), reply_key=KEY)
    taken: list[GroundCommand] = []

    async def script(channel: CommandChannel) -> None:
        sent = good.command(191)
        await wait_until_async(lambda: channel.counts.taken == 1, 10, "the signed go-around taken")
        taken.extend(channel.pending())
        channel.answer(taken[0], AckResult.ACCEPTED)
        unsigned.command(191)
        wrong.command(191)
        good.sock.sendto(sent, good.address)  # the same signed packet again: a replay
        good.command(31011, param1=1.0, target_component=1)  # to the autopilot, not to the companion
        await wait_until_async(
            lambda: (
                (channel.counts.unsigned, channel.counts.bad_signature, channel.counts.replayed) == (1, 1, 1)
                and channel.counts.not_for_us == 1
            ),
            10,
            "the refusals",
        )
        await wait_until_async(lambda: len(unsigned.acks()) and len(wrong.acks()), 10, "the refusals answered")
        await wait_until_async(lambda: len(good.acks()) == 3, 10, "the signed sender's answers")

    channel = await run_channel(port, KEY, script)
    assert [(c.command, c.signed, c.sender) for c in taken] == [(OperatorCommand.GO_AROUND, True, (255, 190))]
    assert channel.pending() == []  # nothing refused was taken
    # Issue 65: every refusal is handed out for the flight log (the command to the autopilot is not the channel's).
    refused = [(r.mav_cmd, r.result, r.reason) for r in channel.refused()]
    assert sorted(refused, key=str) == sorted(
        [
            (191, AckResult.DENIED, "not signed"),
            (191, AckResult.DENIED, "bad signature"),
            (191, AckResult.DENIED, "replayed or stale signature timestamp"),
        ],
        key=str,
    )
    assert channel.refused() == []  # handed out once
    assert good.acks() == [(191, AckResult.IN_PROGRESS), (191, AckResult.ACCEPTED), (191, AckResult.DENIED)]
    assert good.texts() == ["refused: replayed or stale signature timestamp"]
    assert unsigned.acks() == [(191, AckResult.DENIED)]
    assert unsigned.texts() == ["refused: not signed"]
    assert wrong.texts() == ["refused: bad signature"]
    # Every reply of a channel with a key is signed with it.
    for gcs in (good, unsigned, wrong):
        assert all(m.get_signed() for m in gcs.poll())
        gcs.close()


async def test_without_a_key_commands_are_taken_unsigned_and_a_land_now_with_param1_1_is_forced(port: int) -> None:
    gcs = Gcs(port)
    taken: list[GroundCommand] = []

    async def script(channel: CommandChannel) -> None:
        gcs.command(31011, param1=1.0)
        gcs.command(31010)
        gcs.command(31012)  # the next fallback site
        gcs.command(400)  # arm/disarm: not the companion's
        channel.counts.malformed = 0
        gcs.sock.sendto(b"\xfd garbage", gcs.address)
        await wait_until_async(lambda: channel.counts.taken == 3 and channel.counts.malformed == 1, 10, "three taken")
        await wait_until_async(lambda: len(gcs.acks()) == 4, 10, "four answers")
        taken.extend(channel.pending())

    channel = await run_channel(port, None, script)
    assert [(c.command, c.force, c.signed) for c in taken] == [
        (OperatorCommand.LAND_NOW, True, False),
        (OperatorCommand.REJECT_ZONE, False, False),
        (OperatorCommand.NEXT_FALLBACK, False, False),
    ]
    assert sorted(gcs.acks()) == sorted(
        [(31011, AckResult.IN_PROGRESS), (31010, AckResult.IN_PROGRESS), (31012, AckResult.IN_PROGRESS), (400, 3)]
    )
    assert channel.counts.unsupported == 1
    gcs.close()


async def test_a_denial_longer_than_one_statustext_arrives_whole_in_chunks_sharing_an_id(port: int) -> None:
    gcs = Gcs(port)
    reason = "land_now denied: a person seen inside the footprint at 12.4 m, 0.8 m from the target (zone 3)"

    async def script(channel: CommandChannel) -> None:
        gcs.command(31011)
        gcs.command(31011)
        await wait_until_async(lambda: channel.counts.taken == 2, 10, "both taken")
        for command in channel.pending():
            channel.answer(command, AckResult.DENIED, reason)
        await wait_until_async(lambda: len(gcs.texts()) == 4, 10, "two denials of two chunks each")

    await run_channel(port, None, script)
    chunks = [m for m in gcs.poll() if m.get_type() == "STATUSTEXT"]
    gcs.close()
    assert len(reason) > 50
    assert [(m.chunk_seq, m.severity) for m in chunks] == [(0, 4), (1, 4)] * 2
    assert chunks[0].id == chunks[1].id != 0
    assert chunks[2].id == chunks[3].id != chunks[0].id
    assert chunks[0].text + chunks[1].text == reason  # the last chunk is shorter than 50: the text ends there
    assert len(chunks[0].text) == 50


async def test_a_channel_on_a_port_in_use_names_its_url() -> None:
    from companion.ground.command_channel import CommandChannelError

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        url = f"udpin://127.0.0.1:{busy.getsockname()[1]}"
        with pytest.raises(CommandChannelError, match=url):
            await CommandChannel(url, 1).open()


async def test_a_command_to_another_vehicles_companion_is_logged_and_handed_out_never_silently_dropped(
    port: int, caplog: pytest.LogCaptureFixture
) -> None:
    # Issue 65: with `slz sitl --instance 5` the vehicle was system 6 and commands to it vanished without a word.
    gcs = Gcs(port)

    async def script(channel: CommandChannel) -> None:
        gcs.command(191, target_system=VEHICLE_SYSID + 5)
        gcs.command(31011, target_system=VEHICLE_SYSID + 5, target_component=1)  # another autopilot's: not for us
        await wait_until_async(lambda: channel.counts.not_for_us == 2, 10, "both seen")

    with caplog.at_level(logging.WARNING, logger="companion.ground.command_channel"):
        channel = await run_channel(port, None, script)
    refused = channel.refused()
    assert [(r.mav_cmd, r.result) for r in refused] == [(191, None)]  # not answered: another vehicle's
    assert f"addressed to system {VEHICLE_SYSID + 5}, this vehicle is system {VEHICLE_SYSID}" in refused[0].reason
    assert any("addressed to system" in r.message for r in caplog.records)
    assert gcs.acks() == []
    gcs.close()
