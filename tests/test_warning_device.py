"""The warning for the people below (guidance.warning): when it sounds, what goes to the autopilot, what is recorded,
and that nothing goes out in a dry run and a refused switch does not stop the landing. In flight, against the SITL's
people who step away: tests/test_warning_flight.py and docs/results/warning_walkers.md."""

from __future__ import annotations

from pathlib import Path
from typing import Any, cast

import pytest

from companion.app.commands import VehicleCommands
from companion.app.outcome import FlightOutcome
from companion.app.warning_device import WarningDevice, warning_wanted
from companion.config import ConfigError, validate_config
from companion.flightlog.flight_log import FlightLog, RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.guidance.config import WarningConfig
from companion.guidance.landing import CommandKind, Decision, LandingPhase
from companion.guidance.vocabulary import DecisionEvent
from companion.vehicle.link import Action, LinkResult, VehicleError

pytestmark = pytest.mark.unit


def decision(t_s: float, phase: LandingPhase, event: DecisionEvent) -> Decision:
    return Decision(t_s, phase, CommandKind.NONE, None, None, "test", event)


# A landing as the flight decides it: search, approach, descent with a wait at the walker gate, land, landed.
LANDING = [
    decision(1.0, LandingPhase.SEARCH, DecisionEvent.HOLD_NO_TARGET),
    decision(2.0, LandingPhase.APPROACH, DecisionEvent.APPROACH),
    decision(3.0, LandingPhase.DESCENT, DecisionEvent.DESCEND),
    decision(4.0, LandingPhase.DESCENT, DecisionEvent.WAIT_AT_GATE),
    decision(5.0, LandingPhase.DESCENT, DecisionEvent.WAIT_AT_GATE),
    decision(6.0, LandingPhase.DESCENT, DecisionEvent.DESCEND),
    decision(7.0, LandingPhase.LAND, DecisionEvent.LAND),
    decision(8.0, LandingPhase.LAND, DecisionEvent.FRAME_IGNORED),
    decision(9.0, LandingPhase.DONE, DecisionEvent.LANDED),
]


class ActuatorLink:
    """The one call the warning makes of a vehicle link's action part; refuses when told to."""

    def __init__(self, refuse: bool = False) -> None:
        self.calls: list[tuple[int, float]] = []
        self.refuse = refuse

    async def set_actuator(self, index: int, value: float) -> None:
        if self.refuse:
            raise VehicleError("udp://test", "actuator 3 to 1 refused: DENIED", LinkResult.REFUSED)
        self.calls.append((index, value))


async def fly(tmp_path: Path, config: dict[str, Any], dry_run: bool = False, refuse: bool = False) -> ActuatorLink:
    link = ActuatorLink(refuse)
    recorder = FlightRecorder(tmp_path)
    unused = cast(Any, None)  # the warning sends nothing through telemetry or offboard
    commands = VehicleCommands(unused, cast(Action, link), unused, recorder, FlightOutcome(), dry_run)
    device = WarningDevice(validate_config(WarningConfig, config), commands, recorder)
    for d in LANDING:
        await device.follow(d)
    recorder.close()
    return link


def warnings(tmp_path: Path) -> list[dict[str, Any]]:
    return FlightLog.read(tmp_path).of(RecordKind.WARNING)


async def test_it_sounds_from_the_descents_start_to_the_touchdown_on_its_output(tmp_path: Path) -> None:
    link = await fly(tmp_path, {"enabled": True, "actuator": 3, "on_value": 0.8, "off_value": -1.0})
    assert link.calls == [(3, 0.8), (3, -1.0)]
    records = warnings(tmp_path)
    assert [(r["t_s"], r["on"], r["sent"], r["event"]) for r in records] == [
        (3.0, True, True, "descend"),
        (9.0, False, True, "landed"),
    ]


async def test_at_the_walker_gate_only_it_sounds_while_the_descent_waits(tmp_path: Path) -> None:
    link = await fly(tmp_path, {"enabled": True, "when": "walker_gate"})
    assert link.calls == [(1, 1.0), (1, -1.0)]
    assert [(r["t_s"], r["on"]) for r in warnings(tmp_path)] == [(4.0, True), (6.0, False)]


async def test_off_by_default_nothing_is_sent_or_recorded(tmp_path: Path) -> None:
    link = await fly(tmp_path, {})
    assert link.calls == []
    assert warnings(tmp_path) == []
    assert not any(warning_wanted(WarningConfig(), d) for d in LANDING)


async def test_a_dry_run_records_when_it_would_sound_and_sends_nothing(tmp_path: Path) -> None:
    link = await fly(tmp_path, {"enabled": True}, dry_run=True)
    assert link.calls == []
    assert [(r["on"], r["sent"]) for r in warnings(tmp_path)] == [(True, False), (False, False)]


async def test_a_refused_switch_is_recorded_and_the_landing_goes_on(tmp_path: Path) -> None:
    await fly(tmp_path, {"enabled": True}, refuse=True)  # follow() raised nothing: every decision was taken
    log = FlightLog.read(tmp_path)
    errors = [r for r in log.of(RecordKind.ERROR) if r.get("where") == "warning"]
    assert len(errors) == 2
    assert "DENIED" in errors[0]["error"]


def test_on_and_off_values_must_differ() -> None:
    with pytest.raises(ConfigError, match="on_value and off_value must differ"):
        validate_config(WarningConfig, {"on_value": 0.5, "off_value": 0.5}, prefix="guidance.warning")
