"""`slz report`'s event list from a flight log: phase changes, failsafes, and every switch between zones with the
decision's reason (a field report jumped from zone 1 to zone 10 without saying why)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from companion.flightlog.flight_log import FlightLog, RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.guidance.landing import CommandKind, Decision, LandingPhase
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent
from companion.perception.selection import Target
from companion.tools.report import summarize

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
        event = DecisionEvent.APPROACH if target is not None else DecisionEvent.HOLD_NO_TARGET
        decision = Decision(float(k), phase, CommandKind.SETPOINT, None, target, reason, event)
        recorder.write(RecordKind.DECISION, float(k), decision=decision, source="frame", state=state, inputs={})
    recorder.close()
    events = [(e["t_s"], e["event"], e["reason"]) for e in summarize(FlightLog.read(tmp_path))["events"]]
    assert events == [
        (1.0, "target none -> zone 1 (r = 2.50 m)", "approach target 1"),
        (3.0, "target zone 1 -> zone 10 (r = 3.50 m)", "approach target 10; switched: zone 10 is larger"),
        (5.0, "target none -> zone 3 (r = 2.20 m)", "approach target 3"),
    ]


def test_the_landing_report_names_the_site_the_zone_and_the_nearest_occupied_ground(tmp_path: Path) -> None:
    from companion.tools.landing_report import REPORT_NAME, write_landing_report

    recorder = FlightRecorder(tmp_path)
    recorder.write(RecordKind.HEADER, None, config={"mode": "fly"}, version="0.1.0", model="m.onnx", model_sha256="ab")
    high = VehicleState(10.0, 0.0, 0.0, -20.0, 0.0)
    gate = VehicleState(30.0, 4.0, 3.0, -5.0, 0.0)
    low = VehicleState(40.0, 4.0, 3.0, -2.0, 0.0)
    zone_high, zone_low = Target(4.0, 3.0, 5.1, 7), Target(4.05, 3.0, 2.2, 7)
    plan = [
        (high, LandingPhase.APPROACH, CommandKind.SETPOINT, zone_high, None),
        (high, LandingPhase.DESCENT, CommandKind.SETPOINT, zone_high, 6.5),
        (gate, LandingPhase.DESCENT, CommandKind.SETPOINT, zone_low, 2.9),
        (low, LandingPhase.LAND, CommandKind.LAND, zone_low, None),
    ]
    for state, phase, kind, target, nearest in plan:
        event = {LandingPhase.APPROACH: DecisionEvent.APPROACH, LandingPhase.DESCENT: DecisionEvent.DESCEND}.get(
            phase, DecisionEvent.LAND
        )
        decision = Decision(state.t_s, phase, kind, None, target, f"{phase.value} over zone 7", event)
        observed = {} if nearest is None else {"observed": {"nearest_occupied_m": nearest}}
        recorder.write(
            RecordKind.DECISION, state.t_s, decision=decision, source="frame", state=state, inputs={}, **observed
        )
    outcome = {"phase": "done", "reason": "landed", "touchdown_ne_m": [4.1, 3.05], "touchdown_t_s": 44.0}
    recorder.write(RecordKind.END, None, outcome=outcome)
    recorder.close()
    path = write_landing_report(tmp_path)
    assert path == tmp_path / REPORT_NAME
    report = json.loads(path.read_text())
    assert report["ended_in"] == "done"
    assert report["land_decided"] == {"t_s": 40.0, "north_m": 4.0, "east_m": 3.0, "sent": True}
    assert report["touchdown"]["north_m"] == 4.1
    assert report["zone"] == {"track_id": 7, "north_m": 4.05, "east_m": 3.0, "radius_m": 2.2}
    assert report["zone_when_descent_began"]["radius_m"] == 5.1
    assert report["zone_when_descent_began"]["seen_from_altitude_m"] == 20.0
    assert report["nearest_occupied_m"] == 2.9  # the last map that decided, at the gate
    assert [e["event"] for e in report["decisions"]] == ["target none -> zone 7 (r = 5.10 m)"]
    assert report["fallback_site"] is None  # a zone
    assert report["ground_commands"] == []


def test_the_landing_report_names_the_fallback_site_landed_at_and_the_ground_stations_commands(tmp_path: Path) -> None:
    from companion.tools.landing_report import REPORT_NAME, write_landing_report

    sites = [{"name": "roi_corner", "north_m": 12.0, "east_m": 12.0, "radius_m": 3.0}]
    sites.append({"name": "rally_1", "north_m": 21.0, "east_m": -4.0, "radius_m": 3.0})
    recorder = FlightRecorder(tmp_path)
    recorder.write(RecordKind.HEADER, None, config={"mode": "fly"}, version="0.1.0", model="m.onnx", model_sha256="ab")
    recorder.write(RecordKind.FALLBACK_SITES, None, sites=sites, rally_points=1)
    recorder.write(
        RecordKind.GROUND_COMMAND, 20.0, command="reject_zone", result="accepted", reason="zone rejected", force=False
    )
    low = VehicleState(90.0, 21.0, -4.0, -2.0, 0.0)
    site = Target(21.0, -4.0, 3.0, -2)  # the second site
    landing = Decision(90.0, LandingPhase.LAND, CommandKind.LAND, None, site, "land on the site", DecisionEvent.LAND)
    recorder.write(RecordKind.DECISION, 90.0, decision=landing, source="frame", state=low, inputs={})
    recorder.write(RecordKind.END, None, outcome={"phase": "done", "reason": "landed"})
    recorder.close()
    write_landing_report(tmp_path)
    report = json.loads((tmp_path / REPORT_NAME).read_text())
    assert report["version"] == 3
    assert report["fallback_site"] == "rally_1"
    assert report["ground_commands"] == [
        {
            "t_s": 20.0,
            "command": "reject_zone",
            "result": "accepted",
            "reason": "zone rejected",
            "force": False,
            "signed": None,
        }
    ]


def test_the_nearest_occupied_cell_is_measured_from_the_point() -> None:
    from companion.guidance.footprint import nearest_occupied_m
    from companion.perception.projection import GridSpec, HeadPlaneOccupancy

    grid = GridSpec(north_min_m=0.0, east_min_m=0.0, resolution_m=0.5, rows=20, cols=20)
    free = np.ones((20, 20), bool)
    known = np.ones((20, 20), bool)
    assert nearest_occupied_m(HeadPlaneOccupancy(grid, free, known), 5.0, 5.0) is None
    free[4, 16] = False  # the cell centred at north 2.25 m, east 8.25 m
    assert nearest_occupied_m(HeadPlaneOccupancy(grid, free, known), 2.25, 5.25) == pytest.approx(3.0)
    known[4, 16] = False  # unseen is not occupied
    assert nearest_occupied_m(HeadPlaneOccupancy(grid, free, known), 2.25, 5.25) is None


def _ended(tmp_path: Path, decisions: list[tuple[LandingPhase, CommandKind, DecisionEvent, str]], **end: object) -> str:
    """The landing report's outcome of a log with these decisions (source, phase, kind, event) and end record."""
    from companion.tools.landing_report import REPORT_NAME, write_landing_report

    recorder = FlightRecorder(tmp_path)
    mode = end.pop("mode", "fly")
    recorder.write(RecordKind.HEADER, None, config={"mode": mode}, version="0.1.0", model="m.onnx", model_sha256="ab")
    state = VehicleState(5.0, 1.0, 2.0, -12.0, 0.0)
    for k, (phase, kind, event, source) in enumerate(decisions):
        decision = Decision(5.0 + k, phase, kind, None, None, f"{event.value}", event)
        recorder.write(RecordKind.DECISION, 5.0 + k, decision=decision, source=source, state=state, inputs={})
    supervision = end.pop("supervision", None)
    if supervision is not None:
        recorder.write(RecordKind.SUPERVISION, 9.0, event=supervision, reason=str(supervision))
    if end.pop("link_lost_record", False):
        recorder.write(RecordKind.FAILSAFE, 8.0, reason="link lost: stop commanding")  # an older log: no action
    if not end.pop("crashed", False):
        recorder.write(RecordKind.END, None, outcome={"phase": "search", "reason": "", **end})
    recorder.close()
    path = write_landing_report(tmp_path)
    assert path is not None, "no landing report"
    report = json.loads((tmp_path / REPORT_NAME).read_text())
    assert report["outcome_says"]
    return str(report["outcome"])


SEARCH = (LandingPhase.SEARCH, CommandKind.SETPOINT, DecisionEvent.HOLD_NO_TARGET, "frame")


@pytest.mark.parametrize(
    ("decisions", "end", "named"),
    [
        (
            [SEARCH, (LandingPhase.LAND, CommandKind.LAND, DecisionEvent.LAND, "frame")],
            {"phase": "done", "touchdown_ne_m": [1.0, 2.0]},
            "landed",
        ),
        ([SEARCH], {"link_lost": True, "link_lost_record": True}, "link_lost"),
        (
            [SEARCH, (LandingPhase.FAILSAFE, CommandKind.HOLD, DecisionEvent.LIMIT, "stop")],
            {"phase": "failsafe"},
            "stopped",
        ),
        ([SEARCH], {"phase": "search", "supervision": "stopped"}, "stopped"),
        (
            [SEARCH, (LandingPhase.YIELDED, CommandKind.NONE, DecisionEvent.PILOT_TOOK_OVER, "takeover")],
            {"phase": "yielded"},
            "pilot_took_over",
        ),
        (
            [SEARCH, (LandingPhase.FAILSAFE, CommandKind.HOLD, DecisionEvent.TIME_LIMIT, "time")],
            {"phase": "failsafe", "supervision": "pilot_has_it"},
            "pilot_took_over",
        ),
        (
            [SEARCH, (LandingPhase.FAILSAFE, CommandKind.HOLD, DecisionEvent.TIME_LIMIT, "time")],
            {"phase": "failsafe"},
            "held",
        ),
        (
            [SEARCH, (LandingPhase.FAILSAFE, CommandKind.RETURN, DecisionEvent.ENERGY_LOW, "energy")],
            {"phase": "failsafe", "touchdown_ne_m": [0.0, 0.0]},
            "returned",
        ),
        (
            [SEARCH, (LandingPhase.FAILSAFE, CommandKind.LAND, DecisionEvent.PERCEPTION_FAILSAFE, "silence")],
            {"phase": "failsafe", "touchdown_ne_m": [1.0, 2.0]},
            "landed_by_failsafe",
        ),
        ([SEARCH], {"crashed": True}, "crashed"),
        ([SEARCH], {"mode": "dry_run"}, "dry_run"),
        ([], {"phase": "idle"}, "nothing_flown"),
    ],
)
def test_every_ending_gets_a_landing_report_that_names_it(
    tmp_path: Path,
    decisions: list[tuple[LandingPhase, CommandKind, DecisionEvent, str]],
    end: dict[str, object],
    named: str,
) -> None:
    assert _ended(tmp_path, decisions, **end) == named


def test_a_lost_links_failsafe_record_reads_in_the_timeline_with_or_without_its_action(tmp_path: Path) -> None:
    from companion.flightlog.timeline import flight_events

    recorder = FlightRecorder(tmp_path)
    recorder.write(RecordKind.FAILSAFE, 8.0, reason="link lost: stop commanding")  # before issue 65: no action
    recorder.write(RecordKind.FAILSAFE, 9.0, reason="link lost: stop commanding", action="autopilot")
    recorder.close()
    events = flight_events(FlightLog.read(tmp_path))
    assert [e["event"] for e in events] == ["failsafe (autopilot)", "failsafe (autopilot)"]


def test_the_path_slz_fly_prints_is_one_slz_report_takes(tmp_path: Path) -> None:
    # Issue 65: `slz fly` printed .../flight.jsonl and `slz report` looked for .../flight.jsonl/flight.jsonl.
    from companion.flightlog.flight_log import flight_folder

    recorder = FlightRecorder(tmp_path / "run" / "flight")
    recorder.write(RecordKind.HEADER, None, config={"mode": "fly"}, version="0.1.0")
    recorder.close()
    folder = tmp_path / "run" / "flight"
    assert flight_folder(folder / "flight.jsonl") == folder  # the log itself
    assert flight_folder(folder) == folder
    assert flight_folder(tmp_path / "run") == folder  # a demo's run folder


def test_the_report_says_why_frames_failed_not_only_how_many(tmp_path: Path) -> None:
    # Issue 65: "frame errors 37" without saying they were all the head plane out of sight after the land command.
    recorder = FlightRecorder(tmp_path)
    for k in range(3):
        recorder.write(RecordKind.FRAME_ERROR, float(k), seq=k, error="projection.gsd: the head plane is not visible")
    recorder.write(RecordKind.FRAME_ERROR, 4.0, seq=4, error="pipeline.process: frame is 320x240")
    recorder.close()
    summary = summarize(FlightLog.read(tmp_path))
    assert summary["frame_errors"] == 4
    assert summary["frame_errors_by_why"] == {
        "projection.gsd: the head plane is not visible": 3,
        "pipeline.process: frame is 320x240": 1,
    }


def test_the_landing_report_lists_the_warning_devices_switches(tmp_path: Path) -> None:
    # Issue 65: the warning device's switches appeared only in the log.
    from companion.tools.landing_report import landing_report

    recorder = FlightRecorder(tmp_path)
    recorder.write(RecordKind.HEADER, None, config={"mode": "fly"}, version="0.1.0", model="m.onnx", model_sha256="ab")
    recorder.write(RecordKind.WARNING, 30.0, on=True, sent=True, phase="descent", event="descend", actuator=1)
    recorder.write(RecordKind.WARNING, 41.0, on=False, sent=True, phase="done", event="landed", actuator=1)
    recorder.write(RecordKind.END, None, outcome={"phase": "done", "reason": "landed"})
    recorder.close()
    switches = landing_report(FlightLog.read(tmp_path))["warning_device"]
    assert [(s["t_s"], s["on"], s["event"]) for s in switches] == [(30.0, True, "descend"), (41.0, False, "landed")]
