"""Why missions held (metrics version 5, issue 33), counted in the report, and a table against its earlier flight."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from companion.flightlog.flight_log import DecisionRecord
from companion.guidance.landing import CommandKind, LandingPhase
from companion.guidance.vocabulary import DecisionEvent, DecisionSource, RefusalCause, ZoneChange
from companion.perception.selection import Target
from sitl.campaign.metrics import HOLD_CAUSES, MissionMetrics, hold_cause, zones_chosen
from sitl.campaign.record import FlownMission, flown_missions, parse_results
from sitl.campaign.report import against_previous, build_report, hold_kind
from sitl.campaign.spec import CampaignSpec, load_campaign_spec

pytestmark = pytest.mark.unit

USED_UP = "person seen inside the footprint; 6 re-selections used up: hold"
TIME_LIMIT = "no landing within 300 s of the start: hold"


def _decision(t_s: float, phase: str, reason: str, target: bool, source: str = "frame") -> DecisionRecord:
    """A decision as a log from before decisions carried their event holds it: read through the legacy reader."""
    zone = {"track_id": 1, "north_m": 0.0, "east_m": 0.0, "radius_m": 2.0} if target else None
    decision = {"kind": "setpoint", "phase": phase, "target": zone, "setpoint": None, "reason": reason}
    return DecisionRecord.from_record({"t_s": t_s, "decision": decision, "source": source, "state": None})


def _end(reason: str, phase: str = "failsafe") -> DecisionRecord:
    return _decision(300.0, phase, reason, False, source="time")


def test_each_hold_is_explained_by_kind_from_an_old_flight_logs_words() -> None:
    searching = [_decision(float(t), "search", "no target: search pattern", False) for t in range(300)]
    assert hold_cause([*searching, _end(TIME_LIMIT)]) == "nothing free"
    chosen_late = [*searching[:-10], _decision(295.0, "approach", "approach target 1; committed to zone 1", True)]
    assert hold_cause([*chosen_late, _end(TIME_LIMIT)]) == "time limit while approaching"
    descending = [*chosen_late, _decision(299.0, "descent", "descend over zone 1", True)]
    assert hold_cause([*descending, _end(TIME_LIMIT)]) == "time limit while descending"
    between = [*chosen_late, _decision(299.0, "search", "no target yet: hold; released: zone 1 not seen", False)]
    assert hold_cause([*between, _end(TIME_LIMIT)]) == "time limit while searching"
    climbing = [*descending, _decision(299.5, "search", "climbing back to 20.0 m before choosing again", False)]
    assert hold_cause([*climbing, _end(TIME_LIMIT)]) == "time limit while climbing back"
    assert hold_cause([*searching, _end(USED_UP)]) == "person in the footprint"
    no_map = "no map saw the footprint free in the last 12 s; 6 re-selections used up: hold"
    assert hold_cause([_end(no_map)]) == "no fresh free map"
    assert hold_cause([_end("zone 3 shrank to 0.80 m; 6 re-selections used up: hold")]) == "zone shrank"
    walker = "a person kept walking towards the footprint for 20 s; 6 re-selections used up: hold"
    assert hold_cause([_end(walker)]) == "walker kept coming"
    gate = "person seen inside the footprint at the gate for 20 s; 6 re-selections used up: hold"
    assert hold_cause([_end(gate)]) == "person in the footprint"
    assert hold_cause([_end("perception silent 5.0 s: land")]) == "perception silent"
    assert hold_cause([_end("perception silent 1.0 s: hold", phase="hold")]) == "perception silent"
    assert hold_cause([_end("pilot took over (mode POSCTL)", phase="yielded")]) == "pilot took over"
    assert hold_cause([_end("something new", phase="search")]) == "other"
    assert hold_cause([]) == "other"
    assert {hold_cause([*searching, _end(r)]) for r in (TIME_LIMIT, USED_UP, "x")} <= set(HOLD_CAUSES)


def test_each_hold_is_explained_by_its_events_whatever_the_words() -> None:
    def typed(t_s: float, phase: str, event: DecisionEvent, cause: RefusalCause | None = None) -> DecisionRecord:
        target = Target(0.0, 0.0, 3.0, 1) if phase in ("approach", "descent") else None
        source = DecisionSource.TIME if event is DecisionEvent.TIME_LIMIT else DecisionSource.FRAME
        kind, at = CommandKind.SETPOINT, LandingPhase(phase)
        return DecisionRecord(t_s, kind, at, target, None, "words", source, None, event, cause)

    searching = [typed(float(t), "search", DecisionEvent.SEARCH_PATTERN) for t in range(300)]
    limit = typed(300.0, "failsafe", DecisionEvent.TIME_LIMIT)
    assert hold_cause([*searching, limit]) == "nothing free"
    approaching = [*searching[:-10], typed(295.0, "approach", DecisionEvent.APPROACH)]
    assert hold_cause([*approaching, limit]) == "time limit while approaching"
    climbing = [*approaching, typed(299.0, "search", DecisionEvent.CLIMB_BACK)]
    assert hold_cause([*climbing, limit]) == "time limit while climbing back"
    for cause, kind in (
        (RefusalCause.PERSON_IN_FOOTPRINT, "person in the footprint"),
        (RefusalCause.PERSON_AT_GATE, "person in the footprint"),
        (RefusalCause.NO_FREE_MAP, "no fresh free map"),
        (RefusalCause.ZONE_SHRANK, "zone shrank"),
        (RefusalCause.WALKER_KEPT_COMING, "walker kept coming"),
    ):
        assert hold_cause([typed(1.0, "failsafe", DecisionEvent.RESELECTIONS_USED_UP, cause)]) == kind
    assert hold_cause([typed(1.0, "failsafe", DecisionEvent.PERCEPTION_FAILSAFE)]) == "perception silent"
    assert hold_cause([typed(1.0, "failsafe", DecisionEvent.LIMIT)]) == "other"
    # After fallback sites (metrics version 7): the last resort's cause says how the last site ended.
    to_site = [*searching, typed(300.0, "approach", DecisionEvent.FALLBACK_SITE)]
    refused = typed(340.0, "failsafe", DecisionEvent.TIME_LIMIT, RefusalCause.PERSON_IN_FOOTPRINT)
    assert hold_cause([*to_site, refused]) == "fallback sites refused"
    late = typed(390.0, "failsafe", DecisionEvent.TIME_LIMIT, RefusalCause.SITE_TIMED_OUT)
    assert hold_cause([*to_site, late]) == "fallback site timed out"
    asked = [*searching[:10], typed(10.0, "approach", DecisionEvent.FALLBACK_SITE, RefusalCause.OPERATOR)]
    assert hold_cause([*asked, typed(40.0, "failsafe", DecisionEvent.FALLBACK_SITE, RefusalCause.OPERATOR)]) == (
        "fallback sites refused"  # given up from the ground station, none left
    )
    out_of_reach = typed(320.0, "failsafe", DecisionEvent.ENERGY_LOW)  # the energy budget gave the site up
    assert hold_cause([*to_site, out_of_reach]) == "energy budget"
    assert hold_cause([*searching, refused]) == "nothing free"  # no site flown to: the time limit's kinds


def test_choices_are_counted_from_the_reasons_not_from_the_trackers_ids() -> None:
    log = [
        _decision(1.0, "approach", "approach target 1; committed to zone 1 (biggest, r=4.0 m)", True),
        _decision(2.0, "approach", "approach target 7; zone 1 seen again as zone 7 (IoU 0.70)", True),
        _decision(9.0, "approach", "approach target 9; switched from zone 7 to zone 9: biggest better", True),
        _decision(12.0, "search", "no target yet: hold; released: zone 9 not seen for 3 s; committed to zone 12", True),
    ]
    assert zones_chosen(log) == 3
    assert [c.change for d in log for c in d.zone_changes] == [
        ZoneChange.COMMIT,
        ZoneChange.REACQUIRE,
        ZoneChange.SWITCH,
        ZoneChange.RELEASE,
        ZoneChange.COMMIT,
    ]


def _spec(tmp_path: Path) -> CampaignSpec:
    path = tmp_path / "holds.yaml"
    path.write_text(
        "campaign:\n  name: holds\n  master_seed: 3\n  runs: 8\n  mission_config: mission_configs/sitl.yaml\n"
        "  conditions:\n    - name: static\n  strategies:\n    - {name: oldest, policy: oldest}\n"
        "    - {name: nearest, policy: nearest}\n"
    )
    return load_campaign_spec(path)


def _results(spec: CampaignSpec, over_a_person: set[str], held: dict[str, str | None]) -> list[dict[str, Any]]:
    """Every mission lands safely except those ``over_a_person`` and those ``held`` (mission id: cause)."""
    rows = []
    for plan in spec.missions():
        bad, hold = plan.mission_id in over_a_person, plan.mission_id in held
        rows.append(
            MissionMetrics(
                plan.mission_id, plan.condition.name, plan.strategy.name, plan.run, plan.seed, "done",
                TIME_LIMIT if hold else "landed", landed=not hold, success=not (bad or hold), warning_1m=bad,
                warning_1_5m=bad, people_within_1m=int(bad), people_within_1_5m=int(bad), touchdown_nearest_m=4.0,
                zone_area_m2=20.0, nearest_person_mean_m=4.0, nearest_person_min_m=4.0, zone_iou=0.8,
                time_to_land_s=40.0, path_length_m=30.0, reselections=0, aborts=0, failsafes=0,
                touchdown_north_m=1.0, touchdown_east_m=2.0, obstacle_distance_m=5.0, obstacle_kind="bench",
                touched_obstacle=False, people_cells=[], hold_cause=held.get(plan.mission_id), zones_chosen=1,
                ending="hold" if hold else "zone", sites_flown_to=0, first_zone_north_m=1.0, first_zone_east_m=2.0,
            ).to_json()
        )  # fmt: skip
    return rows


def _flown(lines: list[dict[str, Any]]) -> list[FlownMission]:
    return flown_missions(parse_results(lines))


def test_the_report_counts_holds_by_cause_and_compares_with_an_earlier_flight(tmp_path: Path) -> None:
    spec = _spec(tmp_path)
    oldest = [p.mission_id for p in spec.missions() if p.strategy.name == "oldest"]
    before = _results(spec, set(oldest[:6]), {})  # six landings over a person before
    now = _results(spec, set(), {oldest[0]: "nothing free", oldest[1]: "person in the footprint"})
    earlier = next(r for r in now if r["mission_id"] == oldest[2])
    earlier.update(landed=False, success=False, reason=TIME_LIMIT)
    for key in ("hold_cause", "ending", "sites_flown_to"):  # a result of metrics version 4
        del earlier[key]
    earlier["metrics_version"] = 4
    assert hold_kind(_flown([earlier])[0]) == "(before version 5) no landing within 300 s of the start"

    cells = {r["cell"]: r for r in against_previous(spec, _flown(now), _flown(before))}
    cell = cells["static/oldest"]
    assert (cell["pairs"], cell["before"], cell["now"]) == (8, 2, 5)
    assert (cell["only_before"], cell["only_now"]) == (0, 3)  # runs 3 to 5 improved; 0 to 2 held now
    assert cell["p"] == pytest.approx(2.0 * 0.5**3)  # exact two-sided McNemar, all discordant pairs one way
    assert cells["static/nearest"]["p"] == 1.0

    summary = build_report(spec, now, tmp_path / "report", previous=("the old table", before))
    assert summary["cells"]["static/oldest"]["holds"] == {
        "(before version 5) no landing within 300 s of the start": 1,
        "nothing free": 1,
        "person in the footprint": 1,
    }
    assert summary["previous"]["cells"][0]["p_holm"] >= summary["previous"]["cells"][0]["p"]
    text = (tmp_path / "report" / "report.md").read_text()
    assert "## Missions without a touchdown, by cause" in text
    held_row = "| static/oldest | 8 | 3 | (before version 5) no landing within 300 s of the start: 1, nothing free: 1"
    assert held_row in text
    assert "## Against the old table (same scenes and start poses, mission by mission)" in text
    # How the missions ended (metrics version 7), beside the one result that predates it.
    assert summary["cells"]["static/oldest"]["endings"] == {"before version 7": 1, "hold": 2, "zone": 5}
    assert "## How the missions ended" in text
    assert "| condition / strategy | missions | a zone the map chose | hold | before version 7 |" in text
    assert "| static/oldest | 8 | 5 | 2 | 1 |" in text
    assert "| static/nearest | 8 | 8 | 0 | 0 |" in text
    v6 = [{k: v for k, v in r.items() if k not in ("ending", "sites_flown_to")} for r in now]
    v6 = [r | {"metrics_version": min(r["metrics_version"], 6)} for r in v6]
    old = build_report(spec, v6, tmp_path / "old")
    assert set(old["cells"]["static/oldest"]["endings"]) == {"before version 7"}
    assert "## How the missions ended" not in (tmp_path / "old" / "report.md").read_text()
    assert "| static/oldest | 8 | 2 | 5 | 0 | 3 | 0.25 |" in text
