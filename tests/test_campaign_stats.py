"""Campaign statistics, specs and metrics on hand-made data (no processes)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from companion.config import ConfigError
from sitl.campaign.metrics import mission_metrics
from sitl.campaign.spec import load_campaign_spec
from sitl.campaign.stats import bootstrap_mean, mcnemar_exact, paired_mean_difference, wilson

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


def _write_mission(run_dir: Path, walker_ne: list[tuple[float, float]]) -> None:
    """A hand-made mission: descent from t = 1 s at (0, 0), touchdown at t = 3 s; one person walking."""
    (run_dir / "flight").mkdir(parents=True)
    config = {"perception": {"zones": {"vehicle_radius_m": 0.5}}}
    target = {"north_m": 0.0, "east_m": 0.0, "radius_m": 2.0, "track_id": 4}
    flight = [
        {"t_s": None, "kind": "header", "config": config},
        {
            "t_s": 0.0,
            "kind": "decision",
            "source": "start",
            "decision": {"phase": "search", "kind": "setpoint", "target": None, "reason": "mission start"},
        },
        {
            "t_s": 1.0,
            "kind": "decision",
            "source": "frame",
            "decision": {"phase": "descent", "kind": "setpoint", "target": target, "reason": "descend"},
        },
        {
            "t_s": 2.5,
            "kind": "decision",
            "source": "frame",
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
