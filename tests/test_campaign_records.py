"""Campaign results as typed records (sitl/campaign/record.py): every stored result reads back as one, a field that is
not a result's is named instead of reported as "n/a", and the fields' own metadata says what the report summarises,
what the gate checks and what two flights of a mission are compared on."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from bench.campaign_sample import NOT_METRICS, differences
from sitl.campaign.gate import GATED
from sitl.campaign.metric_fields import Summary, field_infos, fields_of
from sitl.campaign.metrics import METRICS_VERSION, MissionMetrics
from sitl.campaign.record import FlownMission, MissionFailure, ResultError, compared_fields, parse_result
from sitl.campaign.report import MEANS, RATES
from sitl.campaign.runner import read_results
from sitl.testing.helpers import run_python

pytestmark = pytest.mark.unit

REPO_ROOT = Path(__file__).resolve().parent.parent


def _line(**changes: Any) -> dict[str, Any]:
    """One stored result line of today's metrics version, as a campaign writes it."""
    line = MissionMetrics(
        "static/oldest/0003", "static", "oldest", 3, 77, "done", "landed", landed=True, success=True, warning_1m=False,
        warning_1_5m=False, people_within_1m=0, people_within_1_5m=1, touchdown_nearest_m=2.5, zone_area_m2=20.0,
        nearest_person_mean_m=4.0, nearest_person_min_m=2.5, zone_iou=0.8, time_to_land_s=40.0, path_length_m=30.0,
        reselections=1, aborts=0, failsafes=0, touchdown_north_m=1.0, touchdown_east_m=2.0,
        obstacle_distance_m=math.nan, obstacle_kind=None, touched_obstacle=False, people_cells=[[20, 21, 1]],
        hold_cause=None, zones_chosen=1, ending="zone", sites_flown_to=0, first_zone_north_m=1.0, first_zone_east_m=2.0,
    ).to_json()  # fmt: skip
    run = {"wall_s": 12.5, "node": "vm", "segment": 1, "commit": "abc", "finished_utc": "2026-11-28T12:00:00Z"}
    return line | run | changes


def test_every_committed_campaign_result_reads_back_typed_and_writes_back_the_same() -> None:
    folders = sorted((REPO_ROOT / "docs" / "results").rglob("results.jsonl"))
    assert folders, "no committed campaign results found"
    read = 0
    for path in folders:
        for line in read_results(path):
            record = parse_result(line)
            if isinstance(record, FlownMission):
                written = record.to_json()
                assert {k: written[k] for k in line} == line, f"{path}: {line['mission_id']}"
            else:
                assert isinstance(record, MissionFailure)
                assert record.error == line["error"]
            read += 1
    assert read > 1000


def test_a_result_reads_back_with_its_types_and_nan_where_a_metric_does_not_apply() -> None:
    record = parse_result(_line())
    assert isinstance(record, FlownMission)
    assert (record.mission_id, record.run, record.success, record.reselections) == ("static/oldest/0003", 3, True, 1)
    assert math.isnan(record.obstacle_distance_m)  # stored as null: no obstacle anywhere near
    assert (record.wall_s, record.segment, record.commit) == (12.5, 1, "abc")
    assert record.metrics_version == METRICS_VERSION


def test_a_field_that_is_not_a_results_is_named_not_read_as_missing() -> None:
    with pytest.raises(ResultError, match=r"static/oldest/0003: unknown field\(s\) sucess"):
        parse_result(_line(sucess=True))
    broken = _line()
    del broken["zone_iou"]
    with pytest.raises(ResultError, match=r"missing field zone_iou \(metrics version"):
        parse_result(broken)
    with pytest.raises(ResultError, match="success must be true or false"):
        parse_result(_line(success="yes"))
    with pytest.raises(ResultError, match="reselections must be an integer"):
        parse_result(_line(reselections=1.5))


def test_an_older_result_lacks_what_later_versions_added_and_reads_it_as_not_applying() -> None:
    version_2 = {k: v for k, v in _line(metrics_version=2).items() if field_infos(FlownMission)[k].since <= 2}
    record = parse_result(version_2)
    assert isinstance(record, FlownMission)
    assert math.isnan(record.obstacle_distance_m)
    assert (record.obstacle_kind, record.touched_obstacle, record.hold_cause, record.zones_chosen) == (
        None,
        False,
        None,
        0,
    )
    assert record.overflown_above_gate is False


def test_an_error_line_is_a_failure_record() -> None:
    line = {"mission_id": "static/oldest/0001", "condition": "static", "strategy": "oldest", "run": 1, "seed": 5}
    record = parse_result(line | {"error": "SITL did not start", "segment": 2})
    assert record == MissionFailure("static/oldest/0001", "static", "oldest", 1, 5, "SITL did not start", segment=2)
    with pytest.raises(ResultError, match="unknown field"):
        parse_result(line | {"error": "x", "success": False})


def test_the_fields_metadata_drives_the_report_the_gate_and_the_comparison() -> None:
    infos = field_infos(FlownMission)
    # The report's columns and each mean's bootstrap seed follow the fields' order metadata: the committed reports'.
    assert fields_of(MissionMetrics, Summary.MEAN) == (
        "zone_area_m2", "nearest_person_mean_m", "nearest_person_min_m", "touchdown_nearest_m", "zone_iou",
        "time_to_land_s", "path_length_m", "reselections", "aborts", "failsafes", "people_within_1m",
        "people_within_1_5m",
    )  # fmt: skip
    assert fields_of(MissionMetrics, Summary.RATE) == (
        "success", "landed", "warning_1m", "warning_1_5m", "touched_obstacle"
    )  # fmt: skip
    assert (fields_of(MissionMetrics, Summary.MEAN), fields_of(MissionMetrics, Summary.RATE)) == (MEANS, RATES)
    assert all(infos[name].summary is Summary.RATE for name in GATED)
    assert {"wall_s", "node", "segment", "commit", "finished_utc", "metrics_version"} == NOT_METRICS
    assert set(compared_fields()) == set(infos) - NOT_METRICS
    # Two flights of one mission on different machines: the run's facts differ, no outcome does.
    elsewhere = _line(wall_s=30.0, node="other", segment=4, commit="def", finished_utc="2026-11-29T00:00:00Z")
    assert differences(elsewhere, _line()) == []
    assert differences(_line(aborts=1), _line()) == ["aborts"]
    with pytest.raises(ResultError, match="aborst"):
        differences(_line(aborst=1), _line())


def test_slz_campaign_report_names_a_misspelt_field_and_fails(tmp_path: Path) -> None:
    spec_path = tmp_path / "records.yaml"
    spec_path.write_text(
        "campaign:\n  name: records\n  master_seed: 3\n  runs: 1\n  mission_config: mission_configs/sitl.yaml\n"
        "  conditions:\n    - name: static\n  strategies:\n    - {name: oldest, policy: oldest}\n"
    )
    out = tmp_path / "campaign"
    out.mkdir()
    line = _line(mission_id="static/oldest/0000", run=0)
    line["zone_area"] = line.pop("zone_area_m2")
    (out / "results.jsonl").write_text(json.dumps(line) + "\n")
    done = run_python("-m", "companion.cli", "campaign", "--spec", str(spec_path), "--out", str(out), "--report-only")
    assert done.returncode == 1, done.stdout + done.stderr[-2000:]
    assert "unknown field(s) zone_area" in done.stderr
    assert not (out / "report.md").exists()
