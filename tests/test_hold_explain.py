"""A hold explained from its flight log and its truth: each landing point given up, why, and where the people were."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from companion.flightlog.flight_log import DecisionRecord
from companion.flightlog.legacy_decisions import vocabulary_of, zone_changes_of
from sitl.campaign.hold_explain import TruthAt, abort_kind, explain_hold, explain_run, release_kind
from sitl.vehicle.truth import TruthHeader, TruthRecord

pytestmark = pytest.mark.unit

VEHICLE_RADIUS_M = 0.5
MARGIN_M = 0.5


def _decision(t_s: float, phase: str, reason: str, target: tuple[float, float] | None) -> DecisionRecord:
    """A decision in the words of a log from before decisions carried their event (read by the legacy reader)."""
    zone = None if target is None else {"north_m": target[0], "east_m": target[1], "radius_m": 1.2, "track_id": 1}
    decision = {"kind": "setpoint", "phase": phase, "target": zone, "setpoint": None, "reason": reason}
    return DecisionRecord.from_record({"t_s": t_s, "decision": decision, "source": "frame", "state": None})


def _truth(people_at_s: dict[float, list[tuple[float, float]]]) -> TruthAt:
    """Two people of body radius 0.25 m, who stand where ``people_at_s`` puts them from each time on."""
    first = next(iter(people_at_s.values()))
    header = TruthHeader(1, 0.0, np.array(first, dtype=float), np.full(len(first), 0.25), (True,) * len(first))
    records = [
        TruthRecord(t, (0.0, 0.0, -40.0), True, "OFFBOARD", "IN_AIR", False, np.array(people, dtype=float))
        for t, people in people_at_s.items()
    ]
    return TruthAt(header, records)


def test_the_causes_lose_their_zone_numbers() -> None:
    def release(text: str) -> str:
        (change,) = zone_changes_of(f"no target yet: hold; released: {text}")
        return release_kind(change.cause)

    def abort(reason: str) -> str:
        return abort_kind(vocabulary_of(reason, "search")[1])

    assert release("person seen inside zone 12's footprint") == "person in the footprint"
    assert release("zone 3 shrank to 0.98 m") == "zone shrank"
    assert release("zone 3 not seen for 3 s") == "zone lost"
    assert release("zone 3's footprint left the geofence") == "footprint left the geofence"
    assert abort("person seen inside the footprint: climb back and re-select") == "person in the footprint"
    gate = "person seen inside the footprint at the gate for 20 s; 6 re-selections used up: hold"
    assert abort(gate) == "person in the footprint at the gate, wait limit"
    assert abort("no map saw the footprint free in the last 12 s: climb back and re-select") == "no fresh free map"
    walker = "a person kept walking towards the footprint for 20 s: climb back and re-select"
    assert abort(walker) == "walker kept coming"
    assert release_kind(None) == abort_kind(None) == "other"


def test_a_hold_over_a_wide_berth_reads_as_such() -> None:
    """Two zones released for a person in their footprints and one descent aborted, each with the nearest body 2-3 m
    from the point: the map keeps a wider berth than the footprint, and nobody was inside it."""
    truth = _truth({0.0: [(12.0, 0.0), (0.0, 2.6)], 20.0: [(12.0, 2.2), (30.0, 0.0)]})
    log = [
        _decision(1.0, "approach", "approach target 1; committed to zone 1 (oldest, r=1.1 m)", (0.0, 0.0)),
        _decision(2.0, "approach", "approach target 1 (5.0 m away, r=1.1 m)", (0.0, 0.0)),
        _decision(3.0, "search", "no target yet: hold; released: person seen inside zone 1's footprint", None),
        _decision(4.0, "approach", "approach target 2; committed to zone 2 (oldest, r=1.0 m)", (10.0, 0.0)),
        _decision(5.0, "search", "released: zone 2 shrank to 0.99 m; committed to zone 3 (oldest)", (12.0, 5.0)),
        _decision(21.0, "descent", "descend over zone 3 (offset 0.2 m)", (12.0, 5.0)),
        _decision(22.0, "descent", "wait at 4.8 m over zone 3: a person seen inside the footprint", (12.0, 5.0)),
        _decision(23.0, "search", "person seen inside the footprint: climb back and re-select", None),
    ]
    explained = explain_hold(log, truth, VEHICLE_RADIUS_M, MARGIN_M)
    assert explained.zones_chosen == 3
    assert dict(explained.releases) == {"person in the footprint": 1, "zone shrank": 1}
    assert dict(explained.aborts) == {"person in the footprint": 1}
    edges = {r.event: round(r.nearest_edge_m, 3) for r in explained.refusals}
    assert edges == {"release": 2.35, "gate": 2.55, "abort": 2.55}  # 2.6 - 0.25, 2.8 - 0.25 (the truth at 20 s)
    assert explained.verdict() == "wide berth"
    summary = explained.to_json()
    assert summary["person_refusals"]["release"]["inside_footprint"] == 0
    assert "wide berth" in summary["summary"]


def test_people_really_in_the_footprint_and_false_positives_are_told_apart() -> None:
    aborted = "person seen inside the footprint: climb back and re-select"
    log = [
        _decision(1.0, "descent", "descend over zone 1", (0.0, 0.0)),
        _decision(2.0, "search", aborted, None),
        _decision(3.0, "descent", "descend over zone 2", (0.0, 0.3)),
        _decision(4.0, "search", aborted, None),
    ]
    there = explain_hold(log, _truth({0.0: [(0.5, 0.0), (40.0, 0.0)]}), VEHICLE_RADIUS_M, MARGIN_M)
    assert there.verdict() == "people there"
    assert there.to_json()["person_refusals"]["abort"]["within_vehicle_radius"] == 2
    nobody = explain_hold(log, _truth({0.0: [(20.0, 0.0), (40.0, 0.0)]}), VEHICLE_RADIUS_M, MARGIN_M)
    assert nobody.verdict() == "false positives"
    quiet = explain_hold(log[:1], _truth({0.0: [(20.0, 0.0), (40.0, 0.0)]}), VEHICLE_RADIUS_M, MARGIN_M)
    assert quiet.verdict() == "no person named"


def test_a_mission_folder_is_read_with_its_own_footprint(tmp_path: Path) -> None:
    """The footprint comes from the config the flight log holds, the people from the truth file beside it."""
    flight = tmp_path / "flight"
    flight.mkdir()
    config = {"perception": {"zones": {"vehicle_radius_m": 0.4, "margin_m": 0.8}}}
    decision = _decision(1.0, "descent", "descend over zone 1", (0.0, 0.0))
    target = decision.target
    assert target is not None
    records = [
        {"kind": "header", "schema_version": 2, "config": config, "t_s": 0.0},
        {
            "kind": "decision",
            "t_s": 1.0,
            "decision": {"kind": "setpoint", "phase": "descent", "target": asdict(target), "reason": decision.reason},
            "source": "frame",
            "state": None,
        },
        {
            "kind": "decision",
            "t_s": 2.0,
            "decision": {
                "kind": "setpoint",
                "phase": "search",
                "reason": "person seen inside the footprint: climb back and re-select",
            },
            "source": "frame",
            "state": None,
        },
    ]
    (flight / "flight.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    header = TruthHeader(1, 0.0, np.array([[1.0, 0.0]]), np.array([0.25]), (False,))
    record = TruthRecord(2.0, (0.0, 0.0, -6.0), True, "OFFBOARD", "IN_AIR", False)
    (tmp_path / "truth.jsonl").write_text(json.dumps(header.to_json()) + "\n" + json.dumps(record.to_json()) + "\n")
    explained = explain_run(tmp_path)
    assert math.isclose(explained.footprint_radius_m, 1.2)
    assert [round(r.nearest_edge_m, 3) for r in explained.refusals] == [0.75]
    assert explained.verdict() == "people there"  # 0.75 m: inside this vehicle's 1.2 m footprint


def test_the_truly_free_disc_is_measured_inside_the_area_between_the_bodies() -> None:
    """Two bodies 10 m apart in a 20 m square: the largest disc that neither enters and that stays in the square has
    its centre midway between the far corners' reach; measured on a 0.25 m grid, within the grid's half-diagonal."""
    area = np.array([[-10.0, -10.0], [-10.0, 10.0], [10.0, 10.0], [10.0, -10.0]])
    truth = _truth({0.0: [(0.0, -5.0), (0.0, 5.0)]})
    radius = truth.largest_free_radius_m(0.0, area)
    # A disc centred on the north-south axis at north x touches the square's edge at 10 - |x| and the bodies'
    # edges at hypot(x, 5) - 0.25: the best centre makes them equal, at |x| = 10 - r.
    best = next(r for r in np.arange(0.0, 10.0, 0.001) if math.hypot(10.0 - r, 5.0) - 0.25 <= r)
    assert abs(radius - best) <= 0.25 / math.sqrt(2) + 1e-3
    log = [_decision(float(t), "search", "no target: search pattern", None) for t in range(0, 21)]
    lattice = np.arange(-10.5, 10.6, 1.5)
    crowd = _truth({0.0: [(float(n), float(e)) for n in lattice for e in lattice]})
    explained = explain_hold(log, crowd, VEHICLE_RADIUS_M, MARGIN_M, area)
    assert len(explained.free_radii_m) == 5  # every 5 s from 0 to 20 s
    assert explained.free_share() == 0.0  # bodies every 1.5 m: at most 1.06 m to a centre, 0.81 m to an edge
    assert max(explained.free_radii_m) < explained.footprint_radius_m
