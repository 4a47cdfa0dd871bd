"""The ground station's landing commands in a flight (:mod:`companion.ground.command_channel`): taken at the
vehicle's ticks, decided by the landing logic, answered and logged.

A command is taken at the first tick after it arrived, so it is decided at a vehicle time like every decision. Its
decision goes through the flight's one path (recorded with source ``operator`` and its inputs, so a replay decides
the same; reported; sent), and the ground station gets ``ACCEPTED``; a command the logic denies gets ``DENIED`` and
the reason as ``STATUSTEXT``. Every command is a ``ground_command`` record: what, from whom, signed or not, forced or
not, the answer and why.
"""

from __future__ import annotations

import logging
from dataclasses import asdict

from companion.app.mission import MissionConfig
from companion.flightlog.flight_log import RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.ground.command_channel import AckResult, CommandChannel, GroundCommand
from companion.ground.operator_commands import COMMAND_OF_MAV_CMD
from companion.guidance.footprint import nearest_occupied_m
from companion.guidance.landing import Decision, LandingGuidance
from companion.guidance.stimulus import Denied, InputValue, OperatorOrder
from companion.guidance.vehicle_state import VehicleState
from companion.perception.pipeline import FrameResult
from companion.vehicle.mavsdk_link import PROVISIONAL_SYSTEM_ID

logger = logging.getLogger(__name__)


class OperatorDesk:
    """Commands from the channel, decided at ticks (see the module docstring).

    Parameters
    ----------
    channel : CommandChannel or None
        Where commands come from (None: no ground-station commands; the desk does nothing).
    recorder : FlightRecorder
        The ``ground_command`` records.
    footprint_radius_m : float
        A person seen nearer than this to the target makes a land-now a landing on a person.
    """

    def __init__(self, channel: CommandChannel | None, recorder: FlightRecorder, footprint_radius_m: float) -> None:
        self.channel = channel
        self.recorder = recorder
        self.footprint_radius_m = footprint_radius_m

    @classmethod
    def from_config(cls, config: MissionConfig, recorder: FlightRecorder) -> OperatorDesk:
        """The desk of a mission (its ``ground_station`` section; no channel without a ``command_url``): commands to
        the vehicle's system id; the footprint is the zones' smallest radius, as the landing logic's."""
        ground = config.ground_station
        channel = None
        if ground.command_url is not None:
            key, system_id = ground.signing_key, config.vehicle.system_id or PROVISIONAL_SYSTEM_ID
            channel = CommandChannel(ground.command_url, system_id, key, ground.stale_signature_s)
        return cls(channel, recorder, config.perception.zones.min_radius_m)

    async def open(self, system_id: int | None = None) -> None:
        """Listen for commands to the vehicle's ``system_id`` (the link's, once connected) (nothing without a
        channel)."""
        if self.channel is not None:
            if system_id is not None:
                self.channel.system_id = system_id
            await self.channel.open()

    def close(self) -> None:
        """Deny the commands no tick took (the flight is over), record the refused ones, and stop listening."""
        if self.channel is not None:
            for command in self.channel.pending():
                self.channel.answer(command, AckResult.DENIED, f"{command.command.value} denied: the flight is over")
            self._record_refused(None)
            self.channel.close()

    def counts(self) -> dict[str, int] | None:
        """What the channel took, refused and dropped, by why (None without a channel): the log's end says it."""
        return None if self.channel is None else asdict(self.channel.counts)

    def _record_refused(self, t_s: float | None) -> None:
        """A ``ground_command`` record for every command the channel refused or saw addressed to another vehicle."""
        assert self.channel is not None
        for refused in self.channel.refused():
            known = COMMAND_OF_MAV_CMD.get(refused.mav_cmd)
            self.recorder.write(
                RecordKind.GROUND_COMMAND,
                t_s,
                command=known.value if known is not None else f"MAV_CMD {refused.mav_cmd}",
                mav_cmd=refused.mav_cmd,
                sender=list(refused.sender),
                signed=refused.signed,
                result="not_for_us" if refused.result is None else refused.result.name.lower(),
                reason=refused.reason,
                force=False,
            )

    def take(
        self, guidance: LandingGuidance, state: VehicleState, newest: FrameResult | None
    ) -> list[tuple[OperatorOrder, Decision]]:
        """The commands that arrived since the last tick, each handed to the landing logic as an
        :class:`~companion.guidance.stimulus.OperatorOrder` at ``state`` over the ``newest`` map: the accepted ones
        with their decisions (answered ``ACCEPTED``); the denied ones answered and recorded here."""
        if self.channel is None:
            return []
        self._record_refused(state.t_s)
        accepted = []
        for command in self.channel.pending():
            order = OperatorOrder(state, command.command, self._person_seen(guidance, newest), command.force)
            decided = guidance.on(order)
            if isinstance(decided, Denied):
                said = f"{command.command.value} denied: {decided.reason}"
                self._answer(command, state, AckResult.DENIED, said, order.inputs())
                continue
            self._answer(command, state, AckResult.ACCEPTED, decided.reason, order.inputs())
            accepted.append((order, decided))
        return accepted

    def _person_seen(self, guidance: LandingGuidance, newest: FrameResult | None) -> bool:
        """The newest map sees a person within the footprint of the target (or there is no map or no target)."""
        target = guidance.target
        if newest is None or target is None:
            return True
        nearest = nearest_occupied_m(newest.head_plane, target.north_m, target.east_m)
        return nearest is not None and nearest < self.footprint_radius_m

    def _answer(
        self,
        command: GroundCommand,
        state: VehicleState,
        result: AckResult,
        reason: str,
        inputs: dict[str, InputValue],
    ) -> None:
        assert self.channel is not None
        denied = result is AckResult.DENIED
        self.channel.answer(command, result, reason if denied else None)
        (logger.warning if denied or command.force else logger.info)("ground station: %s", reason)
        self.recorder.write(
            RecordKind.GROUND_COMMAND,
            state.t_s,
            mav_cmd=command.mav_cmd,
            sender=list(command.sender),
            signed=command.signed,
            result=result.name.lower(),
            reason=reason,
            **inputs,
        )
