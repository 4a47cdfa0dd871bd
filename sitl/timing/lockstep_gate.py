"""The lockstep gate's bookkeeping: which client steps with the SITL, which tick is out, which acknowledgement came.

Simulated time stops at every tick (every ``period_s``) until the client acknowledges it; the vehicle
(:class:`sitl.vehicle.process.SitlVehicle`) sends the tick's frame, pose and event and checks that an acknowledgement
does not overtake the client's MAVLink. This class holds the state of that exchange and its rules, without any I/O,
so the vehicle keeps one attribute for it instead of ten.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from companion.vehicle.sim_control import LockstepAck, SetpointNedYaw, same_setpoint

Address = tuple[str, int]

LIVE_CLIENT_S = 2.0  # a client that acknowledged a tick this recently keeps the lockstep against a new subscriber


class LockstepGate:
    """The lockstep exchange's state (see the module docstring).

    Parameters
    ----------
    enabled : bool
        The SITL runs in lockstep (``sitl.harness.lockstep``).
    period_s : float
        Simulated seconds between ticks.
    timeout_s : float
        Wall seconds to wait for an acknowledgement (or for a frame client that left) before the SITL stops.
    """

    def __init__(self, enabled: bool, period_s: float, timeout_s: float) -> None:
        self.enabled = enabled
        self.period_s = period_s
        self.timeout_s = timeout_s
        self.client: Address | None = None
        self.seq = 0  # the tick now out (or next to go out)
        self.next_tick_s = 0.0
        self.released = False  # the client left the lockstep: the SITL runs free
        self.latched_setpoint: SetpointNedYaw | None = None  # the setpoint acknowledged with the last tick
        self.frames_wanted = True  # the client wants a camera frame with the next tick
        self.setpoints_between_ticks = 0  # ignored: arrived between ticks and not the acknowledged setpoint
        self._sent_wall = math.nan  # when the current tick went out (NaN: not yet)
        self._ack: LockstepAck | None = None
        self._last_ack_wall = -math.inf
        self._frame_client_lost_wall = math.nan

    # -- the client --------------------------------------------------------------------------------------------
    def subscribe(self, addr: Address, frames: bool = True) -> None:
        """``addr`` becomes the client (the pending tick is sent to it again), with a camera frame at each tick
        unless ``frames`` is False (until an acknowledgement asks for them); refused (ValueError) when this SITL
        does not step, or another client acknowledged a tick within :data:`LIVE_CLIENT_S`."""
        if not self.enabled:
            raise ValueError("this SITL does not run in lockstep")
        live = time.monotonic() - self._last_ack_wall < LIVE_CLIENT_S
        if self.client is not None and addr != self.client and live:
            raise ValueError(f"lockstep has a live client (it acknowledged a tick within {LIVE_CLIENT_S:g} s)")
        self.client = addr
        self.frames_wanted = frames
        self.released = False
        self._sent_wall = math.nan

    def release(self) -> None:
        """The client leaves: the SITL runs free from here."""
        self.released = True

    def acknowledge(self, addr: Address, ack: LockstepAck) -> None:
        """A checked ``lockstep_ack`` from ``addr`` (ValueError from anyone but the client)."""
        if not self.enabled or addr != self.client:
            raise ValueError("not this SITL's lockstep client")
        self._ack = ack
        self._last_ack_wall = time.monotonic()

    # -- the tick ----------------------------------------------------------------------------------------------
    @property
    def free_running(self) -> bool:
        """Simulated time does not wait for anyone."""
        return not self.enabled or self.released

    def at_tick(self, now_s: float) -> bool:
        """Simulated time has reached the next tick and must wait there."""
        return not self.free_running and now_s >= self.next_tick_s - 1e-9

    def between_ticks(self, now_s: float) -> bool:
        """In lockstep and stepping: an acknowledged tick behind, the next not yet reached."""
        stepping = math.isnan(self._sent_wall) and now_s < self.next_tick_s - 1e-9
        return not self.free_running and self.seq > 0 and stepping

    @property
    def tick_out(self) -> bool:
        """The current tick has been sent."""
        return not math.isnan(self._sent_wall)

    def sent(self) -> None:
        """The current tick went out now."""
        self._sent_wall = time.monotonic()

    def pending_ack(self) -> LockstepAck | None:
        """The acknowledgement of the current tick, when it came."""
        ack = self._ack
        return ack if ack is not None and ack.seq == self.seq else None

    def passed(self, latest_setpoint: SetpointNedYaw | None) -> None:
        """The current tick was acknowledged and its MAVLink received: on to the next; ``latest_setpoint`` holds
        until then (a late re-send of an older one between ticks is ignored)."""
        if self._ack is not None:
            self.frames_wanted = self._ack.frames
        self._ack = None
        self.seq += 1
        self.next_tick_s += self.period_s
        self._sent_wall = math.nan
        self.latched_setpoint = latest_setpoint

    @staticmethod
    def ack_covers_mavlink(
        ack: LockstepAck,
        last_setpoint: SetpointNedYaw | None,
        commands_seen: dict[int, int],
        received_from: Callable[[tuple[int, int]], int],
    ) -> bool:
        """The client's MAVLink messages sent before its ``ack`` have all been received (no overtaking).

        Either the ack counts them (``mavlink_sent`` from ``sysid/compid``: ``received_from`` says how many came from
        that source), or it says what must have arrived: ``expect = {"setpoint": [north_m, east_m, down_m,
        yaw_rad]}`` (``last_setpoint``, the latest position setpoint received, equals it: positions exactly as
        float32, the yaw within 1e-4 rad) and/or ``{"commands": {id: count}}`` (checked: ids as numbers;
        ``commands_seen``: that many COMMAND_LONG/INT of each id).
        """
        if ack.counted is None:
            setpoint = ack.expect_setpoint
            if setpoint is not None and (last_setpoint is None or not same_setpoint(last_setpoint, list(setpoint))):
                return False
            wanted = (ack.expect_commands or {}).items()
            return all(commands_seen.get(command, 0) >= count for command, count in wanted)
        sent, sysid, compid = ack.counted
        return bool(received_from((sysid, compid)) >= sent)

    def ack_overdue(self) -> bool:
        """The current tick has waited longer than ``timeout_s`` for its acknowledgement."""
        return self.tick_out and time.monotonic() - self._sent_wall > self.timeout_s

    def frame_client_gone_too_long(self, connected: bool) -> bool:
        """Track a frame client that left after the first tick; True once it has been gone ``timeout_s``."""
        if connected or self.seq == 0:
            self._frame_client_lost_wall = math.nan
            return False
        if math.isnan(self._frame_client_lost_wall):
            self._frame_client_lost_wall = time.monotonic()
            return False
        return time.monotonic() - self._frame_client_lost_wall > self.timeout_s
