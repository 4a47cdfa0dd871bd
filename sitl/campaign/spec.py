"""A campaign spec (``mission_configs/campaigns/<name>.yaml``): conditions x strategies x runs, one master seed.

Every mission gets its own seed, derived from the master seed, the condition and the run index only, so every
strategy in a condition flies the same scenes from the same start poses: strategies are compared pairwise.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import Field, model_validator

from companion.app.mission import MissionConfig
from companion.config import StrictModel, load_yaml_config, read_yaml_file, validate_config
from companion.perception.config import SelectionPolicyName
from sitl.harness.mission import DEFAULT_MISSION_CONFIG, deep_merge
from sitl.world.scenario import ScenarioConfig


class ConditionSpec(StrictModel):
    """One scenario condition: overrides of the SITL's scenario and config (e.g. walkers, weather, faults)."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    scenario: dict[str, Any] = Field(default_factory=dict, description="Merged into sitl.scenario.")
    sitl: dict[str, Any] = Field(default_factory=dict, description="Merged into the SITL config.")

    @model_validator(mode="after")
    def _valid_scenario(self) -> ConditionSpec:
        ScenarioConfig.model_validate(self.scenario)  # a bad override fails at load, named
        return self


class StrategySpec(StrictModel):
    """A landing strategy: a selection policy and any overrides of the companion's mission config."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    policy: SelectionPolicyName
    mission: dict[str, Any] = Field(default_factory=dict, description="Merged into the mission config.")


class CampaignSpec(StrictModel):
    """Conditions x strategies x ``runs`` missions."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    master_seed: int = Field(ge=0)
    runs: int = Field(ge=1, le=100_000, description="Missions per condition and strategy.")
    workers: int = Field(
        default=2, ge=1, le=40, description="Parallel missions (each a SITL and a companion, on instances 0 to 39)."
    )
    mission_config: Path = Field(default=DEFAULT_MISSION_CONFIG, description="The companion's base config.")
    mission: dict[str, Any] = Field(default_factory=dict, description="Overrides for every mission's config.")
    conditions: list[ConditionSpec] = Field(min_length=1)
    strategies: list[StrategySpec] = Field(min_length=1)
    cells: list[tuple[str, str]] | None = Field(
        default=None, description="Only these (condition, strategy) pairs (the paper's table is not a full grid)."
    )
    timeout_s: float = Field(default=300.0, gt=0.0, le=3600.0, description="Wall limit of one mission.")

    @model_validator(mode="after")
    def _names(self) -> CampaignSpec:
        for kind, names in (
            ("condition", [c.name for c in self.conditions]),
            ("strategy", [s.name for s in self.strategies]),
        ):
            if len(set(names)) != len(names):
                raise ValueError(f"{kind} names must be unique, got {names}")
        if self.cells is not None:
            conditions = {c.name for c in self.conditions}
            strategies = {s.name for s in self.strategies}
            for condition, strategy in self.cells:
                if condition not in conditions or strategy not in strategies:
                    raise ValueError(f"cell ({condition}, {strategy}) names an unknown condition or strategy")
        return self

    def cell_names(self) -> list[tuple[str, str]]:
        """(condition, strategy) pairs in order."""
        if self.cells is not None:
            return list(self.cells)
        return [(c.name, s.name) for c in self.conditions for s in self.strategies]

    def missions(self) -> list[MissionPlan]:
        """Every mission of the campaign, in a fixed order."""
        conditions = {c.name: (i, c) for i, c in enumerate(self.conditions)}
        strategies = {s.name: s for s in self.strategies}
        plans = []
        for condition_name, strategy_name in self.cell_names():
            index, condition = conditions[condition_name]
            for run in range(self.runs):
                plans.append(
                    MissionPlan(condition, strategies[strategy_name], run, mission_seed(self.master_seed, index, run))
                )
        return plans

    def policies(self) -> dict[str, str]:
        """The selection policy (its value) of every mission, by mission id: what a result is checked against
        (:func:`sitl.campaign.metrics.stale`, :func:`sitl.campaign.metrics.with_gate_overflight`)."""
        return {plan.mission_id: plan.strategy.policy.value for plan in self.missions()}


def mission_seed(master_seed: int, condition_index: int, run: int) -> int:
    """The scene seed of one run of one condition (the same for every strategy)."""
    return int(np.random.SeedSequence([master_seed, condition_index, run]).generate_state(1)[0])


@dataclass(frozen=True)
class MissionPlan:
    """One mission of a campaign."""

    condition: ConditionSpec
    strategy: StrategySpec
    run: int
    seed: int

    @property
    def mission_id(self) -> str:
        """``<condition>/<strategy>/<run>``: the key of its result."""
        return f"{self.condition.name}/{self.strategy.name}/{self.run:04d}"

    def start_pose(
        self, roi_side_m: float, altitude_low_m: float, altitude_high_m: float
    ) -> tuple[float, float, float]:
        """The random start pose (north, east, altitude m) in the region of interest, from the seed alone."""
        rng = np.random.default_rng([self.seed, 11])
        half = roi_side_m / 2.0
        north, east = (float(v) for v in rng.uniform(-half, half, size=2))
        return north, east, float(rng.uniform(altitude_low_m, altitude_high_m))

    def overrides(self, spec: CampaignSpec) -> tuple[dict[str, Any], dict[str, Any]]:
        """(SITL overrides, mission overrides) of this mission."""
        scenario = ScenarioConfig.model_validate(self.condition.scenario)
        north, east, altitude = self.start_pose(
            scenario.roi_side_m, scenario.start_altitude_m.low, scenario.start_altitude_m.high
        )
        sitl = deep_merge({"scenario": self.condition.scenario}, self.condition.sitl)
        mission = deep_merge(
            {
                "start": {"takeoff_altitude_m": altitude, "start_north_m": north, "start_east_m": east},
                "guidance": {"search_altitude_m": altitude},
                "perception": {"selection": {"policy": self.strategy.policy.value, "seed": self.seed}},
            },
            deep_merge(spec.mission, self.strategy.mission),
        )
        return sitl, mission

    def scenario(self) -> ScenarioConfig:
        """The scenario the SITL flies: the condition's overrides (of its scenario, then of its SITL config)."""
        sitl = deep_merge({"scenario": self.condition.scenario}, self.condition.sitl)
        return ScenarioConfig.model_validate(sitl.get("scenario", {}))

    def vehicle_radius_m(self, spec: CampaignSpec) -> float:
        """The companion's footprint radius (m, propellers included) in this mission's config."""
        base = read_yaml_file(spec.mission_config)
        config = validate_config(MissionConfig, deep_merge(base, self.overrides(spec)[1]), source=self.mission_id)
        return config.perception.zones.vehicle_radius_m


def load_campaign_spec(path: str | Path) -> CampaignSpec:
    """Load and validate a campaign spec (a bad value is named with its allowed range)."""
    return load_yaml_config(CampaignSpec, path, section="campaign")
