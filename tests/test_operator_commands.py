"""The ground station's commands in the landing logic (an OperatorOrder to LandingGuidance.on) and at the flight's desk
(OperatorDesk: the person check on the newest map), on hand-made maps and tracks. The same commands sent over
MAVLink to a companion flying the SITL are in tests/test_ground_commands_flight.py."""

from __future__ import annotations

import math
from pathlib import Path
from typing import cast

import pytest

from companion.app.operator_desk import OperatorDesk
from companion.flightlog.recorder import FlightRecorder, read_log
from companion.ground.command_channel import AckResult, CommandChannel, GroundCommand, RefusedCommand
from companion.guidance.landing import CommandKind, Decision, LandingGuidance, LandingPhase
from companion.guidance.stimulus import Denied, FrameSeen, OperatorOrder, Started
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent, OperatorCommand, RefusalCause
from companion.perception.selection import Target
from tests.test_landing_logic import _descending_over, _frame, _guidance, _map, _track

pytestmark = pytest.mark.unit

ZONE = _track(7, 6.0, 8.0, 2.5)
TARGET = Target(6.0, 8.0, 2.5, 7)


def approaching(g: LandingGuidance) -> VehicleState:
    """Searching at 20 m over the origin, then approaching the zone 10 m away."""
    state = VehicleState(0.0, 0.0, 0.0, -20.0, 0.0)
    g.on(Started(state))
    d = g.on(FrameSeen(state, _frame(0.1, [ZONE], TARGET, _map()), seq=0))
    assert d.phase is LandingPhase.APPROACH
    return state


def test_a_command_with_nothing_to_act_on_is_denied_and_changes_nothing() -> None:
    g = _guidance()
    state = VehicleState(0.0, 0.0, 0.0, -20.0, 0.0)
    for command in (OperatorCommand.GO_AROUND, OperatorCommand.REJECT_ZONE, OperatorCommand.LAND_NOW):
        assert g.on(OperatorOrder(state, command, False, False)) == Denied(
            "no approach or descent to act on (phase idle)"
        )
    g.on(Started(state))
    denied = g.on(OperatorOrder(state, OperatorCommand.GO_AROUND, False, False))
    assert denied == Denied("no approach or descent to act on (phase search)")
    assert g.phase is LandingPhase.SEARCH
    assert g.reselections == 0


def test_a_go_around_in_the_descent_climbs_back_and_searches_again() -> None:
    g = _guidance()
    state = _descending_over(g, 8.0)
    d = g.on(OperatorOrder(state, OperatorCommand.GO_AROUND, False, False))
    assert isinstance(d, Decision)
    assert (d.phase, d.event, d.cause) == (LandingPhase.SEARCH, DecisionEvent.OPERATOR_GO_AROUND, RefusalCause.OPERATOR)
    assert d.setpoint is not None
    assert -d.setpoint.down_m > state.altitude_m  # climbs
    assert g.reselections == 1  # a re-selection spent, as an aborted descent's


def test_a_rejected_zone_in_the_approach_is_refused_and_another_is_chosen() -> None:
    g = _guidance()
    state = approaching(g)
    d = g.on(OperatorOrder(state, OperatorCommand.REJECT_ZONE, False, False))
    assert isinstance(d, Decision)
    assert (d.phase, d.event, d.cause) == (LandingPhase.SEARCH, DecisionEvent.OPERATOR_REJECT, RefusalCause.OPERATOR)
    assert d.setpoint is not None
    assert (d.setpoint.north_m, d.setpoint.east_m) == (0.0, 0.0)  # holds where it is
    other = _track(9, -6.0, -8.0, 2.0)
    after = g.on(FrameSeen(state, _frame(0.2, [ZONE, other], TARGET, _map()), seq=0))
    assert after.phase is LandingPhase.APPROACH
    assert after.target is not None
    assert after.target.track_id == 9  # the rejected zone, bigger, is not chosen again


def test_land_now_lands_over_the_target_is_denied_away_from_it_or_over_a_person_unless_forced() -> None:
    g = _guidance()
    state = approaching(g)
    far = g.on(OperatorOrder(state, OperatorCommand.LAND_NOW, False, False))
    assert far == Denied("10.0 m from the target: land-now lands where the vehicle is; wait until over it")
    over = VehicleState(1.0, 6.2, 8.1, -12.0, 0.0)
    person = g.on(OperatorOrder(over, OperatorCommand.LAND_NOW, True, False))
    assert person == Denied("a person in the footprint on the newest map (param1 = 1 forces the landing)")
    assert g.phase is LandingPhase.APPROACH  # a denial changes nothing
    forced = g.on(OperatorOrder(over, OperatorCommand.LAND_NOW, True, True))
    assert isinstance(forced, Decision)
    assert (forced.phase, forced.kind, forced.event) == (
        LandingPhase.LAND,
        CommandKind.LAND,
        DecisionEvent.OPERATOR_LAND,
    )
    assert "forced" in forced.reason
    clear = _guidance()
    approaching(clear)
    landed = clear.on(OperatorOrder(over, OperatorCommand.LAND_NOW, False, False))
    assert isinstance(landed, Decision)
    assert landed.kind is CommandKind.LAND
    assert "forced" not in landed.reason
    assert math.isclose(landed.target.north_m if landed.target else math.nan, 6.0)


class FakeChannel:
    """The command channel's side the desk uses: commands handed out once, answers kept."""

    def __init__(self, commands: list[GroundCommand], refusals: list[RefusedCommand] | None = None) -> None:
        self.commands = commands
        self.refusals = refusals or []
        self.answers: list[tuple[OperatorCommand, AckResult, str | None]] = []

    def pending(self) -> list[GroundCommand]:
        out, self.commands = self.commands, []
        return out

    def answer(self, command: GroundCommand, result: AckResult, text: str | None = None) -> None:
        self.answers.append((command.command, result, text))

    def refused(self) -> list[RefusedCommand]:
        """The refusals given, handed out once (the channel's own: tests/test_ground_channel.py)."""
        out, self.refusals = self.refusals, []
        return out


def land_now(force: bool) -> GroundCommand:
    return GroundCommand(OperatorCommand.LAND_NOW, 31011, force, (255, 190), ("127.0.0.1", 1), True)


def test_the_desk_denies_a_land_now_over_a_person_on_the_newest_map_and_records_a_forced_one(tmp_path: Path) -> None:
    g = _guidance()
    approaching(g)
    over = VehicleState(1.0, 6.2, 8.1, -12.0, 0.0)
    someone_there = _frame(0.9, [ZONE], TARGET, _map(person_at=(6.3, 7.9)))
    channel = FakeChannel([land_now(force=False)])
    desk = OperatorDesk(cast(CommandChannel, channel), FlightRecorder(tmp_path), footprint_radius_m=1.0)
    assert desk.take(g, over, someone_there) == []
    reason = "land_now denied: a person in the footprint on the newest map (param1 = 1 forces the landing)"
    assert channel.answers == [(OperatorCommand.LAND_NOW, AckResult.DENIED, reason)]
    assert desk.take(g, over, _frame(0.95, [ZONE], TARGET, _map())) == []  # nothing new: nothing decided
    channel.commands = [land_now(force=True)]
    ((order, decision),) = desk.take(g, over, someone_there)
    assert decision.kind is CommandKind.LAND
    assert order.inputs() == {"command": "land_now", "force": True, "person_seen": True}
    desk.recorder.close()
    records = [r for r in read_log(desk.recorder.path) if r["kind"] == "ground_command"]
    assert [(r["result"], r["force"], r["person_seen"]) for r in records] == [
        ("denied", False, True),
        ("accepted", True, True),
    ]
    assert "forced" in records[1]["reason"]


def test_refused_and_misaddressed_commands_are_ground_command_records_the_landing_report_lists(tmp_path: Path) -> None:
    # Issue 65: an unsigned command showed only as a console warning; no record, nothing in the landing report.
    from companion.flightlog.flight_log import FlightLog, RecordKind
    from companion.tools.landing_report import landing_report

    refusals = [
        RefusedCommand(31011, (255, 190), ("127.0.0.1", 1), AckResult.DENIED, "not signed", False),
        RefusedCommand(
            191, (255, 190), ("127.0.0.1", 1), None, "addressed to system 6, this vehicle is system 1", False
        ),
        RefusedCommand(400, (255, 190), ("127.0.0.1", 1), AckResult.UNSUPPORTED, "command 400 is not supported", True),
    ]
    recorder = FlightRecorder(tmp_path)
    recorder.write(RecordKind.HEADER, None, config={"mode": "fly"}, version="0.1.0", model="m.onnx", model_sha256="ab")
    desk = OperatorDesk(cast(CommandChannel, FakeChannel([], refusals)), recorder, footprint_radius_m=1.0)
    g = _guidance()
    approaching(g)
    assert desk.take(g, VehicleState(3.0, 0.0, 0.0, -12.0, 0.0), None) == []
    recorder.write(RecordKind.END, None, outcome={"phase": "search", "reason": ""})
    recorder.close()
    listed = landing_report(FlightLog.read(tmp_path))["ground_commands"]
    assert [(c["command"], c["result"], c["reason"]) for c in listed] == [
        ("land_now", "denied", "not signed"),
        ("go_around", "not_for_us", "addressed to system 6, this vehicle is system 1"),
        ("MAV_CMD 400", "unsupported", "command 400 is not supported"),
    ]
    assert all(c["t_s"] == 3.0 for c in listed)
