"""Hostile and careless config files are refused with one short message naming the field; shipped configs load."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.app.mission import load_mission_config
from companion.config import ConfigError
from companion.perception.config import load_perception_config
from sitl.campaign.spec import load_campaign_spec
from sitl.harness.process import REPO_ROOT
from sitl.testing.hostile_configs import HostileConfig, fly_dry_run, hostile_configs

pytestmark = pytest.mark.unit

HOSTILE = hostile_configs()


def test_there_are_thirty_and_more_distinct_hostile_files() -> None:
    assert len(HOSTILE) >= 30
    assert len({h.name for h in HOSTILE}) == len(HOSTILE)


@pytest.mark.parametrize("hostile", HOSTILE, ids=[h.name for h in HOSTILE])
def test_a_hostile_config_is_refused_with_a_short_message_naming_what_is_wrong(
    hostile: HostileConfig, tmp_path: Path
) -> None:
    path = tmp_path / f"{hostile.name}.yaml"
    path.write_bytes(hostile.content)
    with pytest.raises(ConfigError) as refused:
        load_mission_config(path)
    message = str(refused.value)
    assert hostile.refusal_problem(message) is None, hostile.refusal_problem(message)
    assert len(message) < 2000  # a megabyte value is quoted by its first characters only
    assert all(len(line) < 600 for line in message.splitlines())


@pytest.mark.parametrize("name", ["sitl.yaml", "px4_serial.yaml", "px4_udp.yaml"])
def test_the_shipped_mission_configs_are_accepted(name: str) -> None:
    load_mission_config(REPO_ROOT / "mission_configs" / name)


def test_the_shipped_perception_and_campaign_configs_are_accepted() -> None:
    load_perception_config(REPO_ROOT / "mission_configs" / "perception.yaml")
    for spec in sorted((REPO_ROOT / "mission_configs" / "campaigns").rglob("*.yaml")):
        load_campaign_spec(spec)


def test_slz_fly_refuses_them_with_exit_2_and_no_traceback(tmp_path: Path) -> None:
    chosen = {"alias_bomb_lists", "geofence_nan_corner", "binary_junk", "empty", "deep_flow_sequence", "tab_indent"}
    for hostile in (h for h in HOSTILE if h.name in chosen):
        path = tmp_path / f"{hostile.name}.yaml"
        path.write_bytes(hostile.content)
        run = fly_dry_run(path)  # its own process, with a deadline: a refusal comes before anything is started
        assert run.returncode == 2, (hostile.name, run.stderr[-500:])
        assert "Traceback" not in run.stderr
        assert hostile.refusal_problem(run.stderr) is None, (hostile.name, hostile.refusal_problem(run.stderr))
        assert str(path) in run.stderr  # the document is named
