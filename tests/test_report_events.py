"""`slz report`'s event list from a flight log: phase changes, failsafes, and every switch between zones with the
decision's reason (a field report jumped from zone 1 to zone 10 without saying why)."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.app.flight_log import FlightLog, RecordKind
from companion.app.recorder import FlightRecorder
from companion.app.report import summarize
from companion.guidance.landing import CommandKind, Decision, LandingPhase, VehicleState
from companion.perception.selection import Target

pytestmark = pytest.mark.unit


def test_the_report_lists_each_switch_of_target_with_its_reason(tmp_path: Path) -> None:
    recorder = FlightRecorder(tmp_path)
    state = VehicleState(0.0, 0.0, 0.0, -20.0, 0.0)
    plan = [
        (LandingPhase.SEARCH, None, "no target yet: hold"),
        (LandingPhase.APPROACH, Target(3.0, 1.0, 2.5, 1), "approach target 1"),
        (LandingPhase.APPROACH, Target(3.0, 1.0, 2.5, 1), "approach target 1"),
        (LandingPhase.APPROACH, Target(-4.0, 2.0, 3.5, 10), "approach target 10; switched: zone 10 is larger"),
        (LandingPhase.SEARCH, None, "person seen inside the footprint: climb back and re-select"),
        (LandingPhase.APPROACH, Target(6.0, 6.0, 2.2, 3), "approach target 3"),
    ]
    for k, (phase, target, reason) in enumerate(plan):
        decision = Decision(float(k), phase, CommandKind.SETPOINT, None, target, reason)
        recorder.write(RecordKind.DECISION, float(k), decision=decision, source="frame", state=state, inputs={})
    recorder.close()
    events = [(e["t_s"], e["event"], e["reason"]) for e in summarize(FlightLog.read(tmp_path))["events"]]
    assert events == [
        (1.0, "target none -> zone 1 (r = 2.50 m)", "approach target 1"),
        (3.0, "target zone 1 -> zone 10 (r = 3.50 m)", "approach target 10; switched: zone 10 is larger"),
        (5.0, "target none -> zone 3 (r = 2.20 m)", "approach target 3"),
    ]
