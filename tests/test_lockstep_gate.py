"""The lockstep gate's rules without any I/O: one client, ticks in order, acknowledgements only for the tick out."""

from __future__ import annotations

import pytest

from companion.vehicle.sim_control import LockstepAck, SetpointNedYaw
from sitl.timing.lockstep_gate import LockstepGate

pytestmark = pytest.mark.unit

CLIENT = ("127.0.0.1", 40001)
STRANGER = ("127.0.0.1", 40002)


def test_ticks_pass_only_with_the_acknowledgement_of_the_tick_out() -> None:
    gate = LockstepGate(enabled=True, period_s=0.1, timeout_s=10.0)
    assert gate.at_tick(0.0)
    gate.subscribe(CLIENT)
    gate.sent()
    assert gate.tick_out
    gate.acknowledge(CLIENT, LockstepAck(1))  # not the tick out
    assert gate.pending_ack() is None
    gate.acknowledge(CLIENT, LockstepAck(0))
    assert gate.pending_ack() == LockstepAck(0)
    gate.passed(SetpointNedYaw(1.0, 2.0, -3.0, 0.0))
    assert gate.seq == 1
    assert gate.next_tick_s == pytest.approx(0.1)
    assert not gate.tick_out
    assert gate.latched_setpoint == (1.0, 2.0, -3.0, 0.0)
    assert gate.between_ticks(0.05)
    assert not gate.at_tick(0.05)
    assert gate.at_tick(0.1)


def test_frames_follow_the_subscription_then_each_acknowledgement() -> None:
    gate = LockstepGate(enabled=True, period_s=0.1, timeout_s=10.0)
    assert gate.frames_wanted  # a client that says nothing gets a frame with every tick
    gate.subscribe(CLIENT, frames=False)
    assert not gate.frames_wanted
    for seq, frames in enumerate([False, False, True, True]):
        gate.sent()
        gate.acknowledge(CLIENT, LockstepAck(seq, frames))
        assert gate.pending_ack() is not None
        gate.passed(None)
        assert gate.frames_wanted is frames  # for the next tick
    gate.sent()
    gate.acknowledge(CLIENT, LockstepAck(4))  # an acknowledgement without the flag: frames
    gate.passed(None)
    assert gate.frames_wanted


def test_a_stranger_can_neither_acknowledge_nor_take_a_live_lockstep() -> None:
    gate = LockstepGate(enabled=True, period_s=0.1, timeout_s=10.0)
    gate.subscribe(CLIENT)
    with pytest.raises(ValueError, match="not this SITL's lockstep client"):
        gate.acknowledge(STRANGER, LockstepAck(0))
    gate.acknowledge(CLIENT, LockstepAck(0))
    with pytest.raises(ValueError, match="live client"):
        gate.subscribe(STRANGER)
    gate.subscribe(CLIENT)  # the client itself may subscribe again


def test_a_released_or_disabled_gate_runs_free() -> None:
    off = LockstepGate(enabled=False, period_s=0.1, timeout_s=10.0)
    assert off.free_running
    assert not off.at_tick(5.0)
    with pytest.raises(ValueError, match="does not run in lockstep"):
        off.subscribe(CLIENT)
    gate = LockstepGate(enabled=True, period_s=0.1, timeout_s=10.0)
    gate.subscribe(CLIENT)
    gate.release()
    assert gate.free_running
    assert not gate.at_tick(0.0)


def test_a_frame_client_gone_counts_only_after_the_first_tick() -> None:
    gate = LockstepGate(enabled=True, period_s=0.1, timeout_s=0.0)
    assert not gate.frame_client_gone_too_long(connected=False)  # before the first tick: wait for it
    gate.subscribe(CLIENT)
    gate.sent()
    gate.acknowledge(CLIENT, LockstepAck(0))
    gate.passed(None)
    assert not gate.frame_client_gone_too_long(connected=False)  # first seen gone: the clock starts
    assert gate.frame_client_gone_too_long(connected=False)  # gone past the (zero) timeout
    assert not gate.frame_client_gone_too_long(connected=True)
