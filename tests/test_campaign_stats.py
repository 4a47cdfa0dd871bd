"""Campaign statistics, specs and metrics on hand-made data (no processes)."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pytest
import yaml

from companion.config import ConfigError
from sitl.campaign.gate import GateError, check_against, make_baseline, read_baseline
from sitl.campaign.metrics import (
    METRICS_VERSION,
    MissionMetrics,
    mission_metrics,
    nearest_obstacle,
    park_layout,
    stale,
    with_gate_overflight,
    with_obstacles,
)
from sitl.campaign.record import CampaignResult, flown_missions, parse_results
from sitl.campaign.report import PAPER_TABLE1, build_report, completed, paper_comparison, people_density
from sitl.campaign.runner import CampaignError, missions_to_fly, scene_groups, worker_instances
from sitl.campaign.spec import CampaignSpec, load_campaign_spec
from sitl.campaign.stats import bootstrap_mean, holm, mcnemar_exact, paired_mean_difference, rate_difference, wilson
from sitl.campaign.worker import error_result
from sitl.config import SitlConfig
from sitl.testing.helpers import run_python
from sitl.world.park import ObjectKind

pytestmark = pytest.mark.unit

REPO_ROOT = Path(__file__).resolve().parent.parent


def test_wilson_matches_the_textbook_interval() -> None:
    # 97 of 100 (the paper's static/oldest row): Wilson 95 % is [91.5 %, 99.0 %].
    e = wilson(97, 100)
    assert e.value == pytest.approx(0.97)
    assert e.low == pytest.approx(0.9155, abs=5e-4)
    assert e.high == pytest.approx(0.9897, abs=5e-4)
    assert wilson(0, 10).low == 0.0
    assert wilson(10, 10).high == 1.0
    assert math.isnan(wilson(0, 0).value)


def test_the_bootstrap_is_seeded_and_brackets_the_mean() -> None:
    values = [1.0, 2.0, 3.0, 4.0, 10.0, math.nan]
    a, b = bootstrap_mean(values, seed=3), bootstrap_mean(values, seed=3)
    assert a == b
    assert a.n == 5  # NaN left out
    assert a.value == pytest.approx(4.0)
    assert a.low < a.value < a.high


def test_mcnemar_counts_discordant_pairs() -> None:
    a = [True] * 10 + [False] * 2
    b = [True] * 2 + [False] * 8 + [False] * 2
    test = mcnemar_exact(a, b)
    assert (test.n_pairs, test.only_a, test.only_b) == (12, 8, 0)
    assert test.p_value == pytest.approx(2 * 0.5**8)  # exact two-sided binomial
    assert mcnemar_exact([True, False], [True, False]).p_value == 1.0
    assert paired_mean_difference([3.0, 4.0], [1.0, 1.0]).value == pytest.approx(2.5)


def test_two_independent_rates_give_newcombes_interval_and_fishers_p() -> None:
    # Newcombe (1998), Table II, example (a): 56/70 against 48/80, method 10: 0.2000 [0.0524, 0.3339].
    r = rate_difference(56, 70, 48, 80)
    assert r.difference.value == pytest.approx(0.2)
    assert r.difference.low == pytest.approx(0.0524, abs=5e-5)
    assert r.difference.high == pytest.approx(0.3339, abs=5e-5)
    # Fisher's tea-tasting table, 3 of 4 against 1 of 4: two-sided p = 34/70.
    assert rate_difference(3, 4, 1, 4).p_value == pytest.approx(34 / 70)
    assert rate_difference(5, 10, 5, 10).p_value == pytest.approx(1.0)
    with pytest.raises(ValueError, match=r"\[0, n\]"):
        rate_difference(11, 10, 5, 10)


def test_holm_adjusts_step_down_and_keeps_the_order() -> None:
    # Sorted 0.01, 0.03, 0.04 -> 3 x 0.01, 2 x 0.03, max(0.06, 1 x 0.04): monotone.
    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    assert holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])
    assert holm([]) == []


def test_our_success_against_the_papers_counts_row_by_row() -> None:
    def cell(successes: int, n: int) -> dict[str, Any]:
        return {"success": asdict(wilson(successes, n))}

    cells = {"static/biggest": cell(63, 100), "weather/oldest": cell(86, 100), "static/nearest": cell(5, 10)}
    rows = paper_comparison(cells)
    assert [r["cell"] for r in rows] == ["static/biggest", "weather/oldest"]  # the paper has no 'nearest' row
    biggest, oldest = rows
    paper_biggest = round(PAPER_TABLE1[("static", "biggest")][0])
    assert (biggest["ours_successes"], biggest["paper_successes"]) == (63, paper_biggest)
    assert biggest["difference"]["value"] == pytest.approx(0.63 - paper_biggest / 100)
    assert biggest["difference"]["high"] < 0  # 63 of 100 against 99 of 100: lower, whatever the correction
    assert biggest["p_holm"] == pytest.approx(min(1.0, 2 * biggest["p"]))  # the smaller of two p-values
    assert biggest["p_holm"] < 0.05
    assert oldest["difference"]["value"] == pytest.approx(0.0)  # 86 of 100 on both sides
    assert oldest["p"] == pytest.approx(1.0)


def test_every_strategy_of_a_condition_flies_the_same_scenes_from_the_same_start() -> None:
    spec = load_campaign_spec(REPO_ROOT / "mission_configs" / "campaigns" / "paper_table1.yaml")
    plans = spec.missions()
    assert len(plans) == 900
    by_run: dict[tuple[str, int], tuple[int, float, float]] = {}
    for plan in plans:
        key = (plan.condition.name, plan.run)
        _sitl, mission = plan.overrides(spec)
        pose = (plan.seed, mission["start"]["start_north_m"], mission["start"]["takeoff_altitude_m"])
        assert by_run.setdefault(key, pose) == pose
    assert len({seed for seed, _, _ in by_run.values()}) == len(by_run)  # and every scene differs
    policies = spec.policies()  # each mission's selection policy, by id, for checking its result
    assert len(policies) == 900
    assert {policies[p.mission_id] for p in plans if p.strategy.name == "random"} == {"random"}
    assert {policies[p.mission_id] for p in plans if p.strategy.name == "oldest"} == {"oldest"}


def test_a_bad_campaign_spec_names_the_field(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "campaign:\n  name: x\n  master_seed: 1\n  runs: 0\n  conditions: [{name: a}]\n"
        "  strategies: [{name: s, policy: oldest}]\n"
    )
    with pytest.raises(ConfigError, match=r"campaign\.runs"):
        load_campaign_spec(bad)
    bad.write_text(
        "campaign:\n  name: x\n  master_seed: 1\n  runs: 1\n  conditions: [{name: a, scenario: {moving_fraction: 2}}]\n"
        "  strategies: [{name: s, policy: oldest}]\n"
    )
    with pytest.raises(ConfigError, match="moving_fraction"):
        load_campaign_spec(bad)


def _write_mission(
    run_dir: Path, walker_ne: list[tuple[float, float]], gate_waits_s: tuple[float, ...] = (), released_s: float = 0.0
) -> None:
    """A hand-made mission: descent from t = 1 s at (0, 0), touchdown at t = 3 s; one person walking. With
    ``gate_waits_s``, the vehicle waits at the walker gate at those times and goes on at ``released_s``."""
    (run_dir / "flight").mkdir(parents=True)
    (run_dir / "sitl.yaml").write_text("sitl: {seed: 1}\n")
    config = {"perception": {"zones": {"vehicle_radius_m": 0.5}}}
    target = {"north_m": 0.0, "east_m": 0.0, "radius_m": 2.0, "track_id": 4}
    flight = [
        {"t_s": None, "kind": "header", "config": config},
        {
            "t_s": 0.0,
            "kind": "decision",
            "source": "start",
            "state": None,
            "decision": {"phase": "search", "kind": "setpoint", "target": None, "reason": "mission start"},
        },
        {
            "t_s": 1.0,
            "kind": "decision",
            "source": "frame",
            "state": None,
            "decision": {"phase": "descent", "kind": "setpoint", "target": target, "reason": "descend"},
        },
        *[
            {
                "t_s": t,
                "kind": "decision",
                "source": "frame",
                "state": None,
                "decision": {"phase": "descent", "kind": "setpoint", "target": target, "reason": reason},
            }
            for t, reason in [(t, "wait at 4.8 m over zone 4: watching") for t in gate_waits_s]
            + ([(released_s, "descend over zone 4 (offset 0.00 m)")] if gate_waits_s else [])
        ],
        {
            "t_s": 2.5,
            "kind": "decision",
            "source": "frame",
            "state": None,
            "decision": {"phase": "land", "kind": "land", "target": target, "reason": "land"},
        },
        {"t_s": None, "kind": "end", "outcome": {"phase": "done", "reason": "landed", "failsafes": []}},
    ]
    (run_dir / "flight" / "flight.jsonl").write_text("\n".join(json.dumps(r) for r in flight) + "\n")
    header = {
        "kind": "header",
        "seed": 1,
        "positions_ne_m": [[5.0, 0.0], walker_ne[0]],
        "radii_m": [0.25, 0.25],
        "moving": [False, True],
    }
    truth = [header]
    for k, (n, e) in enumerate(walker_ne):
        t = 0.5 + 0.5 * k
        truth.append(
            {
                "kind": "truth",
                "t_s": t,
                "position_ned_m": [0.0, 0.0, -10.0 + 3 * t],
                "mode": "OFFBOARD",
                "landed_state": "IN_AIR",
                "on_ground": t >= 3.0,
                "armed": True,
                "positions_ne_m": [[5.0, 0.0], [n, e]],
            }
        )
    (run_dir / "truth.jsonl").write_text("\n".join(json.dumps(r) for r in truth) + "\n")


def test_no_two_workers_or_instances_share_a_port() -> None:
    # Every port of every instance 0..39, the ground station's 14550 included, is distinct: a campaign's workers,
    # the tests and a replay can fly side by side. Instance 10 is refused (its API link is the ground-station port).
    ports: list[int] = [14550]
    for instance in (*range(10), *range(11, 40)):
        c = SitlConfig(instance=instance)
        ports += [c.api_port_local, c.api_port_remote, c.gcs_port_local, c.control_port, c.frame_port]
    assert len(ports) == len(set(ports))

    assert worker_instances(30, 2) == [30, 31]
    assert worker_instances(11, 29) == list(range(11, 40))
    with pytest.raises(CampaignError, match="lower --instance-base to at most 28"):
        worker_instances(30, 12)
    with pytest.raises(CampaignError, match="ground-station port 14550"):
        worker_instances(5, 8)
    with pytest.raises(CampaignError, match="at least 1"):
        worker_instances(30, 0)


def test_a_person_under_the_descending_vehicle_is_not_a_success(tmp_path: Path) -> None:
    # The walker passes under the vehicle at t = 2 s (during the final descent), then leaves: touchdown is clear.
    _write_mission(tmp_path / "a", [(9.0, 9.0), (4.0, 0.0), (0.3, 0.0), (2.5, 0.0), (4.0, 0.0), (6.0, 0.0)])
    m = mission_metrics(tmp_path / "a", "c/s/0000", "c", "s", 0, 1)
    assert m.landed
    assert not m.success
    assert m.nearest_person_min_m == pytest.approx(0.05)
    assert m.touchdown_nearest_m == pytest.approx(4.75)  # the person standing 5 m away
    assert not m.warning_1_5m
    assert m.zone_area_m2 == pytest.approx(math.pi * 4.0)
    # The same flight with the walker kept away: a success; a warning when it ends 1.2 m from the touchdown point.
    _write_mission(tmp_path / "b", [(9.0, 9.0), (4.0, 0.0), (3.0, 0.0), (2.5, 0.0), (2.0, 0.0), (1.45, 0.0)])
    m = mission_metrics(tmp_path / "b", "c/s/0000", "c", "s", 0, 1)
    assert m.success
    assert m.warning_1_5m
    assert not m.warning_1m
    assert m.people_within_1_5m == 1
    assert 0.0 <= m.zone_iou <= 1.0
    # What lies under the touchdown point (0, 0) comes from the park of the SITL's seed (sitl.yaml).
    distance_m, kind = nearest_obstacle(park_layout(1, 30.0), 0.0, 0.0)
    assert m.obstacle_distance_m == pytest.approx(distance_m)
    assert m.obstacle_kind == kind
    assert m.touched_obstacle == (distance_m < 0.5)


def test_a_walker_under_the_vehicle_waiting_at_the_gate_is_reported_not_counted(tmp_path: Path) -> None:
    # The vehicle waits at the walker gate from t = 1.2 s to 2.1 s while the walker passes under it (t = 1.5 s), and
    # goes on once they are 2.5 m away: the landing descent (from 2.1 s) is clear, so a success, with the overflight
    # reported; the final descent's nearest person still sees the walker.
    walker = [(9.0, 9.0), (4.0, 0.0), (0.3, 0.0), (2.5, 0.0), (4.0, 0.0), (6.0, 0.0)]
    _write_mission(tmp_path / "waited", walker, gate_waits_s=(1.2, 1.5, 1.8), released_s=2.1)
    m = mission_metrics(tmp_path / "waited", "c/s/0000", "c", "s", 0, 1)
    assert m.success
    assert m.overflown_above_gate
    assert m.nearest_person_min_m == pytest.approx(0.05)
    # Released before the walker came (t = 1.3 s): the walker passed under the descending vehicle, not a success.
    _write_mission(tmp_path / "early", walker, gate_waits_s=(1.1, 1.2), released_s=1.3)
    m = mission_metrics(tmp_path / "early", "c/s/0000", "c", "s", 0, 1)
    assert not m.success
    assert not m.overflown_above_gate
    # A result of version 5 that landed and is not a success may be one now: flown again; its successes are not.
    v5 = {"mission_id": "c/s/0000", "landed": True, "success": False, "metrics_version": 5}
    assert stale(v5)
    assert not stale(v5 | {"success": True})
    assert not stale(v5 | {"landed": False})
    assert not stale(v5 | {"metrics_version": METRICS_VERSION})
    assert not stale(v5, "random")  # the blind baseline lands without the walker gate
    # Completed without a flight where the field follows: a success had nobody under it in its whole final descent.
    assert with_gate_overflight(v5 | {"success": True})["overflown_above_gate"] is False
    assert with_gate_overflight(v5 | {"landed": False})["overflown_above_gate"] is False
    assert "overflown_above_gate" not in with_gate_overflight(v5)  # stale: flown again
    assert with_gate_overflight(v5, "random")["overflown_above_gate"] is False  # no gate: nothing above it


def test_a_touchdown_under_a_tree_crown_is_on_an_obstacle_though_nobody_is_near() -> None:
    objects = park_layout(7, 30.0)
    tree = next(o for o in objects if o.kind is ObjectKind.TREE)
    radius_m = tree.size_m / 2
    assert radius_m >= 1.5  # crowns are 3 to 6 m across
    # Seen from above: inside the crown is distance 0; 0.3 m beyond its edge, the 0.5 m footprint still overlaps it.
    assert tree.footprint_distance_m(tree.north_m + 0.5 * radius_m, tree.east_m) == 0.0
    assert tree.footprint_distance_m(tree.north_m, tree.east_m + radius_m + 0.3) == pytest.approx(0.3)
    blob = next(o for o in objects if o.kind is ObjectKind.DARK_BLOB)
    assert blob.footprint_distance_m(blob.north_m, blob.east_m) == math.inf  # paint on the ground: no obstacle
    # A stored result of version 2 (no obstacle fields) is completed from its seed and touchdown point.
    v2 = {"mission_id": "c/s/0000", "landed": True, "metrics_version": 2, "success": True}
    under = with_obstacles(v2 | {"touchdown_north_m": tree.north_m, "touchdown_east_m": tree.east_m}, objects, 0.5)
    assert under["touched_obstacle"]
    assert under["success"]
    assert (under["obstacle_distance_m"], under["obstacle_kind"]) == (0.0, "tree")
    held = with_obstacles(v2 | {"landed": False, "touchdown_north_m": None, "touchdown_east_m": None}, objects, 0.5)
    assert (held["touched_obstacle"], held["obstacle_distance_m"], held["obstacle_kind"]) == (False, None, None)
    assert with_obstacles(under | {"touched_obstacle": False}, objects, 0.5)["touched_obstacle"] is False  # kept


def test_the_report_completes_earlier_results_from_the_campaigns_own_scenes() -> None:
    spec = load_campaign_spec(REPO_ROOT / "mission_configs" / "campaigns" / "paper_table1.yaml")
    plan = next(p for p in spec.missions() if p.mission_id == "moving_20/oldest/0035")
    assert plan.vehicle_radius_m(spec) == pytest.approx(0.5)
    assert plan.scenario().moving_fraction == pytest.approx(0.2)
    tree = next(o for o in park_layout(plan.seed, plan.scenario().roi_side_m) if o.kind is ObjectKind.TREE)
    stored = {
        "mission_id": plan.mission_id,
        "landed": True,
        "touchdown_north_m": tree.north_m,
        "touchdown_east_m": tree.east_m,
        "metrics_version": 2,
    }
    error = {"mission_id": plan.mission_id, "error": "no SITL"}
    done = completed(spec, [stored, error])
    assert done[0]["touched_obstacle"]
    assert done[0]["obstacle_kind"] == "tree"
    assert done[1] == error


def _write_hold(run_dir: Path, truth_until_s: float) -> None:
    """A hand-made mission that never lands: the companion holds at 10 m at t = 3 s and lets go; the SITL's ground
    truth runs on until ``truth_until_s`` (when it was stopped, a wall-clock matter) while a walker comes under it."""
    (run_dir / "flight").mkdir(parents=True)
    (run_dir / "sitl.yaml").write_text("sitl: {seed: 1}\n")
    config = {"perception": {"zones": {"vehicle_radius_m": 0.5}}}
    search = {"phase": "search", "kind": "setpoint", "target": None, "reason": "search"}
    flight = [
        {"t_s": None, "kind": "header", "config": config},
        {"t_s": 0.0, "kind": "decision", "source": "start", "state": None, "decision": search},
        {"t_s": 0.0, "kind": "command", "command": "setpoint"},
        {"t_s": 2.0, "kind": "command", "command": "setpoint"},
        {
            "t_s": 3.0,
            "kind": "decision",
            "source": "time",
            "state": None,
            "decision": {"phase": "failsafe", "kind": "hold", "target": None, "reason": "no landing: hold"},
        },
        {"t_s": 3.0, "kind": "command", "command": "hold"},
        {"t_s": None, "kind": "end", "outcome": {"phase": "failsafe", "reason": "no landing: hold", "failsafes": []}},
    ]
    (run_dir / "flight" / "flight.jsonl").write_text("\n".join(json.dumps(r) for r in flight) + "\n")
    header = {"kind": "header", "seed": 1, "positions_ne_m": [[8.0, 0.0]], "radii_m": [0.25], "moving": [True]}
    truth: list[dict[str, Any]] = [header]
    for k in range(round(truth_until_s / 0.1) + 1):
        t = 0.1 * k
        walker_n = 8.0 - max(0.0, t - 3.0) * 4.0  # still until the hold, then it walks under the vehicle
        truth.append(
            {
                "kind": "truth",
                "t_s": t,
                "position_ned_m": [0.5 * min(t, 3.0) + 0.01 * max(0.0, t - 3.0), 0.0, -10.0],  # drifts after
                "mode": "HOLD" if t >= 3.0 else "OFFBOARD",
                "landed_state": "IN_AIR",
                "on_ground": False,
                "armed": True,
                "positions_ne_m": [[walker_n, 0.0]],
            }
        )
    (run_dir / "truth.jsonl").write_text("\n".join(json.dumps(r) for r in truth) + "\n")


def test_a_mission_without_touchdown_ends_at_the_companions_last_record_not_at_the_end_of_the_truth(
    tmp_path: Path,
) -> None:
    # The same mission, its SITL stopped 0.1 s or 1.5 s (simulated) after the companion let go: the same metrics.
    _write_hold(tmp_path / "soon", truth_until_s=3.1)
    _write_hold(tmp_path / "late", truth_until_s=4.5)
    soon = mission_metrics(tmp_path / "soon", "c/s/0000", "c", "s", 0, 1)
    late = mission_metrics(tmp_path / "late", "c/s/0000", "c", "s", 0, 1)
    assert soon.to_json() == late.to_json()
    assert not soon.landed
    assert not soon.success
    assert soon.path_length_m == pytest.approx(1.5)  # 0.5 m/s for 3 s; the drift after the hold is not counted
    assert soon.nearest_person_min_m == pytest.approx(8.0 - 1.5 - 0.25)  # at the hold, before the walker came
    assert soon.people_cells == [[28, 20, 1]]  # the walker 8 m north (row 8 + 20) when the companion let go
    assert soon.metrics_version == METRICS_VERSION


def test_a_result_of_an_earlier_metrics_definition_is_flown_again_on_resume() -> None:
    spec = CampaignSpec.model_validate(
        {
            "name": "x",
            "master_seed": 1,
            "runs": 2,
            "conditions": [{"name": "a"}],
            "strategies": [{"name": "s", "policy": "oldest"}],
        }
    )
    first, second = spec.missions()
    landed_v1 = {"mission_id": first.mission_id, "landed": True, "success": True}  # touched down: unchanged since
    held_v1 = {"mission_id": second.mission_id, "landed": False}  # version 1, no touchdown: stale
    assert not stale(landed_v1)
    assert stale(held_v1)
    assert not stale(held_v1 | {"metrics_version": 2})
    assert missions_to_fly(spec.missions(), {first.mission_id: landed_v1, second.mission_id: held_v1}) == [second]
    assert missions_to_fly(spec.missions(), {first.mission_id: landed_v1 | {"error": "x"}}) == [first, second]
    assert (
        missions_to_fly(
            spec.missions(), {m.mission_id: {"landed": False, "metrics_version": 2} for m in (first, second)}
        )
        == []
    )


def test_a_scene_s_missions_go_to_one_worker_together_run_by_run() -> None:
    spec = load_campaign_spec(REPO_ROOT / "mission_configs" / "campaigns" / "paper_table1_roi_sample.yaml")
    todo = missions_to_fly(spec.missions(), {})
    groups = scene_groups(todo)
    assert sorted(p.mission_id for group in groups for p in group) == sorted(p.mission_id for p in todo)
    for group in groups:  # one scene each: one condition, one run, so one seed; each strategy once
        assert len({(p.condition.name, p.run, p.seed) for p in group}) == 1
        assert len({p.strategy.name for p in group}) == len(group)
    assert [len(g) for g in groups[:4]] == [3, 2, 2, 2]  # static flies random too
    assert [g[0].run for g in groups] == sorted(g[0].run for g in groups)  # a stopped campaign: cells even
    assert len(groups) == 4 * spec.runs


def test_random_baseline_results_drawn_around_the_vehicle_are_flown_again() -> None:
    spec = CampaignSpec.model_validate(
        {
            "name": "x",
            "master_seed": 1,
            "runs": 1,
            "conditions": [{"name": "a"}],
            "strategies": [{"name": "blind", "policy": "random"}, {"name": "s", "policy": "oldest"}],
        }
    )
    blind, oldest = spec.missions()
    v3 = {"landed": True, "success": True, "metrics_version": 3}
    assert stale(v3, "random")  # version 4 draws the point around the search area's centre
    assert not stale(v3, "oldest")
    assert not stale(v3 | {"metrics_version": 4}, "random")
    assert missions_to_fly(spec.missions(), {blind.mission_id: v3, oldest.mission_id: v3}) == [blind]


# -- the regression gate (sitl/campaign/gate.py) ------------------------------------------------------------------


def _gate_spec(tmp_path: Path, runs: int) -> Path:
    path = tmp_path / "gate.yaml"
    path.write_text(
        f"campaign:\n  name: gate_check\n  master_seed: 3\n  runs: {runs}\n"
        "  mission_config: mission_configs/sitl.yaml\n"
        "  conditions:\n    - name: static\n  strategies:\n    - {name: oldest, policy: oldest}\n"
        "    - {name: nearest, policy: nearest}\n"
    )
    return path


def _results(spec: CampaignSpec, failed: dict[str, set[int]]) -> list[dict[str, Any]]:
    """Hand-made results: every mission lands safely except runs ``failed[strategy]`` (over a person)."""
    rows = []
    for plan in spec.missions():
        bad = plan.run in failed.get(plan.strategy.name, set())
        rows.append(
            MissionMetrics(
                plan.mission_id, plan.condition.name, plan.strategy.name, plan.run, plan.seed, "done", "landed",
                landed=True, success=not bad, warning_1m=bad, warning_1_5m=bad, people_within_1m=int(bad),
                people_within_1_5m=int(bad), touchdown_nearest_m=0.3 if bad else 4.0, zone_area_m2=20.0,
                nearest_person_mean_m=0.5 if bad else 4.0, nearest_person_min_m=0.3 if bad else 4.0, zone_iou=0.8,
                time_to_land_s=40.0, path_length_m=30.0, reselections=0, aborts=0, failsafes=0,
                touchdown_north_m=1.0, touchdown_east_m=2.0, obstacle_distance_m=5.0, obstacle_kind="bench",
                touched_obstacle=False, people_cells=[], hold_cause=None, zones_chosen=1, ending="zone",
                sites_flown_to=0, first_zone_north_m=1.0, first_zone_east_m=2.0,
            ).to_json()
        )  # fmt: skip
    return rows


def _records(spec: CampaignSpec, failed: dict[str, set[int]]) -> list[CampaignResult]:
    """:func:`_results` read back as typed records."""
    return parse_results(_results(spec, failed))


def test_a_partial_campaigns_report_says_how_many_missions_are_not_flown_yet(tmp_path: Path) -> None:
    spec = load_campaign_spec(_gate_spec(tmp_path, runs=4))
    rows = _results(spec, {})
    summary = build_report(spec, [*rows[:5], error_result(spec.missions()[5], "no SITL")], tmp_path / "partial")
    assert (summary["missions"], summary["errors"]) == (6, 1)
    text = (tmp_path / "partial" / "report.md").read_text()
    assert "5 missions flown of 8 planned (4 per cell, master seed 3). 3 not flown yet (1 of them cut off" in text
    build_report(spec, rows, tmp_path / "whole")
    text = (tmp_path / "whole" / "report.md").read_text()
    assert "8 missions flown of 8 planned (4 per cell, master seed 3). Intervals are 95 %" in text
    assert "not flown yet" not in text


def test_the_people_map_averages_the_missions_that_carry_one() -> None:
    # Two missions with a map (2 people in one cell, then 1 there and 1 elsewhere) and one restored from results.csv
    # without: the mean is over the two, not diluted by the third as if its park were empty.
    line = MissionMetrics(
        "static/oldest/0000", "static", "oldest", 0, 1, "done", "landed", landed=True, success=True, warning_1m=False,
        warning_1_5m=False, people_within_1m=0, people_within_1_5m=0, touchdown_nearest_m=4.0, zone_area_m2=20.0,
        nearest_person_mean_m=4.0, nearest_person_min_m=4.0, zone_iou=0.8, time_to_land_s=40.0, path_length_m=30.0,
        reselections=0, aborts=0, failsafes=0, touchdown_north_m=1.0, touchdown_east_m=2.0, obstacle_distance_m=5.0,
        obstacle_kind="bench", touched_obstacle=False, people_cells=None, hold_cause=None, zones_chosen=1,
        ending="zone", sites_flown_to=0, first_zone_north_m=1.0, first_zone_east_m=2.0,
    ).to_json()  # fmt: skip
    del line["people_cells"]  # as restored from results.csv
    rows = flown_missions(
        parse_results(
            [line | {"people_cells": [[28, 20, 2]]}, line | {"people_cells": [[28, 20, 1], [0, 39, 1]]}, line]
        )
    )
    assert rows[2].people_cells is None  # a detail a stored result may leave out
    density = people_density(rows)
    assert density.shape == (40, 40)
    assert (density[28, 20], density[0, 39], density.sum()) == (1.5, 0.5, 2.0)
    assert people_density(rows[2:]).sum() == 0.0


def test_the_gate_fails_a_strategy_significantly_worse_on_the_same_scenes(tmp_path: Path) -> None:
    spec = load_campaign_spec(_gate_spec(tmp_path, runs=12))
    baseline = make_baseline(spec, _records(spec, {}), commit="abc")
    # 7 of 12 paired scenes got worse for `nearest`, none better: p = 0.5 ** 7 = 0.0078 one-sided, Holm over 6 checks
    # 0.047 < 0.05. One worse scene for `oldest` is chance.
    report = check_against(spec, _records(spec, {"nearest": set(range(7)), "oldest": {0}}), baseline, 0.05)
    by_check = {(c.strategy, c.metric): c for c in report.checks}
    worse = by_check["nearest", "success"]
    assert (worse.pairs, worse.worse, worse.better) == (12, 7, 0)
    assert worse.p_value == pytest.approx(0.5**7)
    assert worse.p_adjusted == pytest.approx(6 * 0.5**7)
    assert worse.failed
    assert by_check["nearest", "warning_1m"].failed
    assert not by_check["oldest", "success"].failed
    assert by_check["oldest", "success"].worse == 1
    assert report.failed
    text = report.to_markdown()
    assert "# Regression gate: FAILED" in text
    assert "| nearest | success | 12 | 100.0 % | 41.7 % | 7 | 0 |" in text
    assert "- static/nearest/0000: success True -> False, warning_1m False -> True, warning_1_5m False -> True" in text
    # Six worse scenes are not enough after the adjustment (6 * 0.5 ** 6 = 0.094): no false alarm on weak evidence.
    assert not check_against(spec, _records(spec, {"nearest": set(range(6))}), baseline, 0.05).failed
    # Improvements never fail the gate.
    improved = check_against(spec, _records(spec, {}), make_baseline(spec, _records(spec, {"oldest": {1, 2}})))
    assert not improved.failed
    assert improved.checks[0].better + improved.checks[3].better == 2


def test_the_gate_refuses_a_baseline_of_other_scenes(tmp_path: Path) -> None:
    spec = load_campaign_spec(_gate_spec(tmp_path, runs=2))
    other = make_baseline(spec, _records(spec, {})) | {"master_seed": 4}
    with pytest.raises(GateError, match="not the same scenes"):
        check_against(spec, _records(spec, {}), other)
    (tmp_path / "junk.json").write_text("{}")
    with pytest.raises(GateError, match="is not a campaign baseline"):
        read_baseline(tmp_path / "junk.json")


def test_slz_campaign_check_against_exits_1_with_a_readable_diff(tmp_path: Path) -> None:
    spec_path = _gate_spec(tmp_path, runs=12)
    spec = load_campaign_spec(spec_path)
    out = tmp_path / "campaign"
    out.mkdir()
    (out / "results.jsonl").write_text(
        "".join(json.dumps(r) + "\n" for r in _results(spec, {"nearest": set(range(8))}))
    )
    baseline = tmp_path / "baseline.json"
    baseline.write_text(json.dumps(make_baseline(spec, _records(spec, {}))))
    command = ["campaign", "--spec", str(spec_path), "--out", str(out), "--report-only", "--check-against"]
    done = run_python("-m", "companion.cli", *command, str(baseline))
    assert done.returncode == 1, done.stdout + done.stderr[-2000:]
    assert "# Regression gate: FAILED" in done.stdout
    assert "| nearest | success | 12 | 100.0 % | 33.3 % | 8 | 0 |" in done.stdout
    assert json.loads((out / "gate.json").read_text())["failed"] is True


def test_report_only_refuses_a_folder_of_another_campaign_and_leaves_it_as_it_was(tmp_path: Path) -> None:
    spec_path = _gate_spec(tmp_path, runs=4)
    spec = load_campaign_spec(spec_path)
    out = tmp_path / "campaign"
    out.mkdir()
    other = spec.model_dump(mode="json")
    other["name"] = "someone_elses"
    (out / "spec.yaml").write_text(yaml.safe_dump(other, sort_keys=False))
    (out / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in _results(spec, {})))
    before = sorted(p.name for p in out.iterdir())
    done = run_python("-m", "companion.cli", "campaign", "--spec", str(spec_path), "--out", str(out), "--report-only")
    assert done.returncode == 1, done.stdout + done.stderr[-2000:]
    assert "holds another campaign's results (someone_elses differs from" in done.stderr
    assert sorted(p.name for p in out.iterdir()) == before  # no report written over it


def test_the_roi_table_flies_the_same_scenes_with_every_zone_in_the_roi() -> None:
    shipped = load_campaign_spec(REPO_ROOT / "mission_configs" / "campaigns" / "paper_table1.yaml")
    roi = load_campaign_spec(REPO_ROOT / "mission_configs" / "campaigns" / "paper_table1_roi.yaml")
    pairs = list(zip(shipped.missions(), roi.missions(), strict=True))
    assert all(a.mission_id == b.mission_id and a.seed == b.seed for a, b in pairs)  # paired mission by mission
    assert all(a.overrides(shipped)[0] == b.overrides(roi)[0] for a, b in pairs)  # the same SITL: scenes, starts
    for plan in (p for _, p in pairs if p.run == 0):
        half_m = plan.scenario().roi_side_m / 2
        mission = plan.overrides(roi)[1]
        assert mission["perception"]["zones"]["landing_area_ne_m"] == [
            [-half_m, -half_m],
            [-half_m, half_m],
            [half_m, half_m],
            [half_m, -half_m],
        ]
        assert plan.vehicle_radius_m(roi) == pytest.approx(0.5)  # the whole companion config validates
