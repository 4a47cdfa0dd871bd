"""A mission on a scarce pack (issue 53): the SITL's battery drains with thrust, the companion reads it over MAVLink
and, with its energy budget on, ends the search and brings the vehicle home while the pack still covers the way,
before PX4's own low-battery failsafe has to act. Real SITL and companion processes, lockstep."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from companion.flightlog.flight_log import FlightLog
from companion.guidance.vocabulary import DecisionEvent
from companion.tools.replay import replay
from sitl.campaign.metrics import mission_metrics
from sitl.campaign.spec import load_campaign_spec
from sitl.campaign.worker import mission_spec
from sitl.harness.instances import leased_instance
from sitl.harness.mission import fly
from sitl.testing.helpers import as_schema_2
from sitl.vehicle.truth import read_truth, touchdown

pytestmark = pytest.mark.sitl

RESERVE = 0.25


def _spec(home_n: float, home_e: float) -> str:
    """A one-mission campaign on a scarce pack, home at (home_n, home_e) local NED."""
    return f"""
campaign:
  name: energy
  master_seed: 2026
  runs: 1
  mission_config: {Path(__file__).resolve().parent.parent / "mission_configs" / "sitl.yaml"}
  timeout_s: 300.0
  mission:
    guidance:
      mission_time_limit_s: 300.0
      energy: {{enabled: true, capacity_mah: 5000.0, reserve_fraction: {RESERVE}}}
  conditions:
    - name: scarce                     # a pack 29 % full: the way home is all it has above the reserve
      sitl: {{battery: {{initial_fraction: 0.29}}, params: {{COM_LOW_BAT_ACT: 3}}, home_ne_m: [{home_n}, {home_e}]}}
  strategies:
    - {{name: oldest, policy: oldest}}
"""


@pytest.mark.parametrize("home_ne_m", [(0.0, 0.0), (22.0, -5.0)], ids=["home_in_the_crowd", "home_clear"])
def test_a_scarce_pack_ends_the_search_and_brings_the_vehicle_home_above_the_reserve(
    tmp_path: Path, home_ne_m: tuple[float, float]
) -> None:
    """Home where the crowd is (the scenes' default) and a launch point outside the region of interest: the budget
    reads home from the autopilot (HOME_POSITION) and the return lands there."""
    (tmp_path / "energy.yaml").write_text(_spec(*home_ne_m))
    spec = load_campaign_spec(tmp_path / "energy.yaml")
    plan = spec.missions()[0]
    run_dir = tmp_path / "run"
    with leased_instance() as lease:
        fly(mission_spec(spec, plan, run_dir, lease.instance, record_frames=True))
    decisions = FlightLog.read(run_dir / "flight").decisions()
    final = decisions[-1]
    ended = next(d for d in decisions if d.event is DecisionEvent.ENERGY_LOW)
    assert ended.kind == "return", ended.reason
    assert "energy budget used up" in ended.reason
    assert ended.source == "energy"
    started = next(d.t_s for d in decisions if d.source == "start")
    assert ended.t_s - started < 60.0  # the budget, not the 300 s time limit, ended the search
    assert final.t_s >= ended.t_s
    records = [r for r in FlightLog.read(run_dir / "flight").records if r.get("source") == "energy"]
    assert len(records) == 1
    assert records[0]["stimulus"]["remaining"] >= RESERVE  # decided above the reserve, far above PX4's critical 7 %
    # The vehicle came home (the autopilot's return lands it at its launch point) and touched down there.
    _, truth = read_truth(run_dir / "truth.jsonl")
    down = touchdown(truth)
    assert down is not None
    assert math.hypot(down.position_ned_m[0] - home_ne_m[0], down.position_ned_m[1] - home_ne_m[1]) < 2.0
    metrics = mission_metrics(run_dir, plan.mission_id, plan.condition.name, plan.strategy.name, plan.run, plan.seed)
    assert metrics.landed  # at home: the return, not a zone (the report's outcome kinds are issue 53's next step)
    # The budget's decision replays from the log as flown (its stimulus is recorded).
    again = replay(run_dir / "flight")
    assert again.identical, again.differences
    assert again.decisions == len(decisions)
    older = replay(as_schema_2(run_dir / "flight", run_dir / "as_schema_2"))  # the log as schema 2 wrote it
    assert (older.identical, older.decisions) == (True, len(decisions)), older.differences
