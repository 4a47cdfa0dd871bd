"""The simulated camera and perception.camera must agree, or every projection is silently wrong: refused by name."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from companion.app.mission import camera_mismatches
from companion.perception.config import PerceptionConfig
from sitl.config import SitlCameraConfig
from sitl.harness.mission import MissionError, MissionSpec, write_configs

pytestmark = pytest.mark.unit

REPO_ROOT = Path(__file__).resolve().parent.parent


def test_the_shipped_defaults_agree() -> None:
    assert camera_mismatches(PerceptionConfig(), SitlCameraConfig()) == []


def test_a_focal_length_in_pixels_is_compared_through_its_field_of_view() -> None:
    fx_px = 640 / (2 * math.tan(math.radians(45.0)))  # 90 degrees across 640 px
    perception = PerceptionConfig.model_validate({"camera": {"fx_px": fx_px, "fy_px": fx_px}})
    assert camera_mismatches(perception, SitlCameraConfig()) == []


@pytest.mark.parametrize(
    ("field", "value"), [("width_px", 800), ("height_px", 600), ("hfov_deg", 70.0), ("tilt_deg", 20.0)]
)
def test_each_differing_field_is_named(field: str, value: float) -> None:
    problems = camera_mismatches(PerceptionConfig(), SitlCameraConfig.model_validate({field: value}))
    assert len(problems) == 1
    assert problems[0].startswith(f"perception.camera.{field}:")
    assert f"sitl.camera.{field} = {value:g}" in problems[0]


def test_a_mission_whose_sitl_camera_disagrees_is_refused_before_any_process(tmp_path: Path) -> None:
    spec = MissionSpec(
        seed=1,
        run_dir=tmp_path / "run",
        instance=1,
        mission_config=REPO_ROOT / "mission_configs" / "sitl.yaml",
        sitl_overrides={"camera": {"tilt_deg": 15.0}},
    )
    with pytest.raises(
        MissionError, match=r"perception\.camera\.tilt_deg: 0 does not match sitl\.camera\.tilt_deg = 15"
    ):
        write_configs(spec)
