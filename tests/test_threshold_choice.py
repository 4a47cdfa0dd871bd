"""The occupancy threshold is chosen on validation data only (models/eval/threshold.py)."""

from __future__ import annotations

import itertools
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from models.data.generate import Split, generate
from models.data.real_ground import HELDOUT, TRAIN, frame_names, is_validation
from models.density.calibration import fit_floor_for_threshold
from models.eval import threshold
from models.eval.threshold import ThresholdRow, choose

pytestmark = pytest.mark.unit

SHIPPED = "models/density/slz_lite.onnx"


def _row(t: float, miss: float) -> ThresholdRow:
    return ThresholdRow(t, {"2-8": miss, "8-12": miss, "2-40": miss}, {"2-40": 0.1}, {"0.045": 0.05})


def test_the_highest_threshold_that_keeps_the_reference_miss_rate_is_chosen() -> None:
    rows = [_row(0.005, 0.001), _row(0.01, 0.0015), _row(0.02, 0.0016), _row(0.03, 0.004)]
    chosen = choose(rows, max_miss=0.0016)
    assert chosen is not None
    assert chosen.threshold == 0.02
    assert choose(rows, max_miss=0.0005) is None  # none holds it: no choice rather than the least bad


def test_real_validation_frames_are_training_split_frames_never_trained_on() -> None:
    train = frame_names(TRAIN)
    validation = [n for n in train if is_validation(n)]
    assert 4 <= len(validation) <= len(train) // 8
    assert not any(is_validation(n) for n in frame_names(HELDOUT))


def test_the_tool_scores_a_model_against_itself(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    generate(tmp_path, Split.TRAIN, frames=2, first=1600, altitude_range_m=(4.0, 30.0))
    out = tmp_path / "threshold"
    argv = ["threshold", "--model", f"lite={SHIPPED}", "--reference", f"lite={SHIPPED}@0.01"]
    argv += ["--synthetic", str(tmp_path / "train"), "--out", str(out)]
    monkeypatch.setattr(sys, "argv", argv)
    assert threshold.main() == 0
    result = json.loads(out.with_suffix(".json").read_text())
    rows = result["rows"]
    # The same model at the reference's threshold misses exactly what the reference misses: the choice is at or
    # above it, and it misses no more.
    same = next(r for r in rows if r["threshold"] == 0.01)
    assert same["miss"] == result["reference"]["miss"]
    assert result["chosen_threshold"] >= 0.01
    chosen = next(r for r in rows if r["threshold"] == result["chosen_threshold"])
    assert chosen["miss"]["2-40"] <= result["reference"]["miss"]["2-40"]
    # A higher threshold never occupies more real ground, nor misses fewer person pixels.
    for lower, higher in itertools.pairwise(rows):
        for gsd, share in higher["real_occupied"].items():
            assert share <= lower["real_occupied"][gsd] + 1e-9
        assert higher["miss"]["2-40"] >= lower["miss"]["2-40"] - 1e-9
    assert "Chosen for lite" in out.with_suffix(".md").read_text()


def test_a_baked_threshold_keeps_the_occupancy_and_drops_the_floor() -> None:
    rng = np.random.default_rng(4)
    maps = []
    for _ in range(6):  # a floor of about 0.004 everywhere, and 20 people of 0.4 per cell over 4 cells each
        d = np.abs(rng.normal(0.004, 0.001, (60, 80))).astype(np.float32)
        for r, c in rng.integers(0, 58, (20, 2)):
            d[r : r + 2, c : c + 2] += 0.4
        maps.append(d)
    truth = [20] * 6
    floor, scale, mae = fit_floor_for_threshold(maps, truth, operating_threshold=0.02, deployed_threshold=0.01)
    assert 0.0 < floor < 0.02
    assert scale == pytest.approx(0.01 / (0.02 - floor))
    for d in maps:  # the exported map at the deployed threshold is the raw map at the operating threshold
        differ = (scale * np.maximum(d - floor, 0.0) >= 0.01) != (d >= 0.02)
        assert not (differ & (np.abs(d - 0.02) > 1e-6)).any()
    raw_mae = float(np.mean([abs(0.5 * d.sum() - 20) for d in maps]))  # floor 0: scale 0.01 / 0.02
    assert mae < raw_mae
    with pytest.raises(ValueError, match="positive"):
        fit_floor_for_threshold(maps, truth, operating_threshold=0.0, deployed_threshold=0.01)
