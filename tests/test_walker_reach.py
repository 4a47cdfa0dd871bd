"""scripts/walker_reach.py: the waits it reports come from the crowd's true walkers and end when none is in reach."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from sitl.world.crowd import Crowd
from sitl.world.scenario import ScenarioConfig

REPO_ROOT = Path(__file__).resolve().parent.parent


def load_script() -> ModuleType:
    """scripts/walker_reach.py as a module (scripts/ is not a package)."""
    spec = importlib.util.spec_from_file_location("slz_walker_reach", REPO_ROOT / "scripts" / "walker_reach.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


walker_reach = load_script()


@pytest.mark.unit
def test_a_wait_lasts_until_the_first_moment_nobody_is_in_reach() -> None:
    near = np.array([True, True, False, True, True, True])
    assert walker_reach.waits_s(near, range(0, 6)) == [1.0, 0.5, 0.0, 1.5, 1.0, 0.5]  # 0.5 s steps; the end cuts short


@pytest.mark.unit
def test_walkers_near_a_point_are_the_moving_people_only() -> None:
    times_s = np.arange(0.0, 10.0, walker_reach.STEP_S)
    standing = Crowd(ScenarioConfig(moving_fraction=0.0), 5)
    point = standing.positions_ne_m[0].copy()  # on a standing person: nobody walks, so nobody is near
    assert not walker_reach.walker_near(standing, point, 3.0, times_s).any()
    walking = Crowd(ScenarioConfig(moving_fraction=1.0), 5)
    start = walking.positions_ne_m[0].copy()  # where a walker starts: near at first, and a small reach is left
    near = walker_reach.walker_near(walking, start, 0.1, times_s)
    assert near[0]
    assert not near.all()
