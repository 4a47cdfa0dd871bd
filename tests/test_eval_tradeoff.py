"""The recall / false-occupied curve of models/eval/tradeoff.py on density maps whose answer is known."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from companion.perception.config import load_perception_config
from companion.perception.density import DensityMap
from models.eval.tradeoff import Tradeoff, TradeoffPoint, curve, tradeoff_table

pytestmark = pytest.mark.unit

REPO_ROOT = Path(__file__).resolve().parent.parent
STRIDE = 8


def _frame(person_density: float, ground_density: float) -> tuple[str, DensityMap, np.ndarray]:
    """A 64x48-cell map (512x384 px): one person box at cells (10..12, 10..12), a patch of ground density far off."""
    values = np.zeros((48, 64), np.float32)
    values[10:12, 10:12] = person_density
    values[30:40, 40:60] = ground_density  # 200 of the ~3000 free cells
    box = np.array([[10 * STRIDE, 10 * STRIDE, 12 * STRIDE, 12 * STRIDE]], np.float64)
    return "frame", DensityMap(values, 64 * STRIDE, 48 * STRIDE), box


def test_the_curve_finds_the_person_until_the_threshold_passes_its_density_and_the_ground_until_its_own() -> None:
    occupancy = load_perception_config(REPO_ROOT / "mission_configs" / "perception.yaml").occupancy
    occupancy = occupancy.model_copy(update={"relative_threshold": 0.0})
    frames = [_frame(0.012, 0.005), _frame(0.025, 0.005)]
    points = curve(frames, occupancy, thresholds=(0.004, 0.006, 0.015, 0.03))
    assert [p.recall for p in points] == [1.0, 1.0, 0.5, 0.0]  # the fainter person is lost above 0.012
    ground_share = points[0].median_false_occupied
    assert 200 / 3072 < ground_share < 200 / 2900  # the ground patch over the free cells
    assert [p.median_false_occupied for p in points[1:]] == [0.0, 0.0, 0.0]
    tradeoff = Tradeoff("m", "set", 1.0, points)
    best = tradeoff.at_target_recall
    assert best is not None
    assert best.threshold == 0.006  # the highest threshold that still finds every person: no ground left there
    table = tradeoff_table([tradeoff])
    assert "| set | 1 | m |" in table
    assert "0.0 % (0.006)" in table


def test_a_curve_that_never_reaches_the_recall_target_says_so() -> None:
    points = [TradeoffPoint(0.01, 0.9, 0.02), TradeoffPoint(0.02, 0.8, 0.01)]
    tradeoff = Tradeoff("m", "set", 0.5, points)
    assert tradeoff.at_target_recall is None
    assert "| none |" in tradeoff_table([tradeoff])
