"""One validated config for the pipeline: defaults, bad values named, YAML loading."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from companion.config import ConfigError, validate_config
from companion.perception.config import PerceptionConfig, SelectionPolicyName, load_perception_config

pytestmark = pytest.mark.unit

REPO_ROOT = Path(__file__).resolve().parent.parent


def nested(path: str, value: Any) -> dict[str, Any]:
    data: dict[str, Any] = {}
    node = data
    parts = path.split(".")
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    node[parts[-1]] = value
    return data


def test_defaults_are_valid_and_documented() -> None:
    config = PerceptionConfig()
    assert config.zones.n_proposals == 10
    assert config.tracking.max_tracks <= config.zones.n_proposals
    assert config.projection.head_height_m == pytest.approx(1.7)
    assert config.selection.policy is SelectionPolicyName.OLDEST
    for section in PerceptionConfig.model_fields.values():
        annotation = section.annotation
        assert annotation is not None
        for name, field in annotation.model_fields.items():
            assert field.description or name in {
                "width_px",
                "height_px",
                "fx_px",
                "fy_px",
                "cx_px",
                "cy_px",
                "offset_frd_m",
                "policy",
            }, f"{name} has no description"


BAD_VALUES = [
    ("zones.n_proposals", 0, "greater than or equal to 1"),
    ("zones.n_proposals", 1000, "less than or equal to 100"),
    ("zones.vehicle_radius_m", -0.5, "greater than 0"),
    ("zones.margin_m", -1, "greater than or equal to 0"),
    ("tracking.max_tracks", 0, "greater than or equal to 1"),
    ("tracking.iou_threshold", 1.5, "less than or equal to 1"),
    ("tracking.iou_threshold", 0.0, "greater than 0"),
    ("tracking.max_misses", 0, "greater than or equal to 1"),
    ("tracking.sigma_a", 0, "greater than 0"),
    ("tracking.measurement_std_position_m", -1, "greater than 0"),
    ("tracking.measurement_std_radius_m", 0, "greater than 0"),
    ("projection.head_height_m", -1, "greater than or equal to 0"),
    ("projection.grid_resolution_m", 0, "greater than 0"),
    ("projection.grid_extent_m", 0.5, "between 8 and 4096 cells"),
    ("occupancy.density_threshold", 0, "greater than 0"),
    ("occupancy.relative_threshold", 2, "less than or equal to 1"),
    ("occupancy.dilation_m", -0.1, "greater than or equal to 0"),
    ("camera.hfov_deg", 180, "less than 179"),
    ("camera.tilt_deg", 120, "less than or equal to 90"),
    ("camera.width_px", 4, "greater than or equal to 16"),
    ("camera.fx_px", 500.0, "fx_px and fy_px must be given together"),
    ("model.providers", [], "at least 1 item"),
    ("selection.policy", "closest", "'biggest', 'oldest', 'nearest' or 'random'"),
    ("selection.seed", -1, "greater than or equal to 0"),
    ("zones.n_proposal", 5, "Extra inputs are not permitted"),
]


@pytest.mark.parametrize(("field", "value", "message"), BAD_VALUES)
def test_bad_values_are_rejected_naming_the_field(field: str, value: Any, message: str) -> None:
    with pytest.raises(ConfigError) as info:
        validate_config(PerceptionConfig, nested(field, value), source="test.yaml", prefix="perception")
    text = str(info.value)
    section = field.rsplit(".", 1)[0]
    assert f"perception.{field}" in text or f"perception.{section}" in text
    assert message in text
    assert "test.yaml" in text


def test_m_p_must_not_exceed_n_p() -> None:
    with pytest.raises(ConfigError, match=r"max_tracks \[M_p\] must be <= zones.n_proposals \[N_p\]"):
        validate_config(PerceptionConfig, {"zones": {"n_proposals": 3}, "tracking": {"max_tracks": 4}})


def test_shipped_perception_config_is_valid_and_equals_the_defaults() -> None:
    config = load_perception_config(REPO_ROOT / "mission_configs" / "perception.yaml")
    assert config == PerceptionConfig()


def test_yaml_errors(tmp_path: Path) -> None:
    missing = tmp_path / "missing.yaml"
    with pytest.raises(ConfigError, match="cannot read file"):
        load_perception_config(missing)
    broken = tmp_path / "broken.yaml"
    broken.write_text("perception: [unclosed")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_perception_config(broken)
    no_section = tmp_path / "empty.yaml"
    no_section.write_text("other: {}\n")
    with pytest.raises(ConfigError, match="perception: missing section"):
        load_perception_config(no_section)
    bad = tmp_path / "bad.yaml"
    bad.write_text("perception:\n  zones:\n    n_proposals: zero\n")
    with pytest.raises(ConfigError, match=r"perception\.zones\.n_proposals: Input should be a valid integer.*'zero'"):
        load_perception_config(bad)


def test_empty_section_means_defaults(tmp_path: Path) -> None:
    path = tmp_path / "defaults.yaml"
    path.write_text("perception:\n")
    assert load_perception_config(path) == PerceptionConfig()


def test_a_replay_takes_the_config_its_flight_ran_with() -> None:
    from companion.app.mission import load_mission_config
    from companion.tools.replay import config_from_header

    today = load_mission_config(Path("mission_configs/sitl.yaml")).model_dump(mode="json")
    assert config_from_header(today).perception.model.min_gsd_m_per_px == pytest.approx(0.045)
    # A header written before frames were shrunk at low altitude has no such field: that flight did not shrink.
    del today["perception"]["model"]["min_gsd_m_per_px"]
    assert config_from_header(today).perception.model.min_gsd_m_per_px == 0.0
