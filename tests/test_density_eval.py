"""Evaluation metrics of the density models and the procedural hard negatives (no PyTorch needed)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from companion.perception.config import OccupancyConfig
from companion.perception.density import DensityMap
from models.data.distractors import DistractorKind, draw, paste
from models.data.generate import Split, generate
from models.data.images import read_mask
from models.eval.metrics import ALTITUDE_BANDS_M, detect_heads, match_count, score_frame, summarise

pytestmark = pytest.mark.unit


def _blob_density(points_cells: list[tuple[int, int]], mass: float = 1.0) -> DensityMap:
    d = np.zeros((120, 160), np.float32)
    for r, c in points_cells:  # a person's mass spread over a 2x2 block
        d[r : r + 2, c : c + 2] += mass / 4
    return DensityMap(d, 640, 480)


def test_heads_are_found_at_the_mass_centre() -> None:
    density = _blob_density([(10, 20), (60, 100), (100, 30)])
    found = detect_heads(density)
    assert len(found) == 3
    expected = np.array([[21 * 4, 11 * 4], [101 * 4, 61 * 4], [31 * 4, 101 * 4]], np.float32)  # block centres, px
    for e in expected:
        assert float(np.min(np.hypot(*(found - e).T))) < 0.5
    assert len(detect_heads(_blob_density([(50, 50)], mass=0.3))) == 0  # less than half a person: not a head


def test_matching_is_one_to_one_within_the_radius() -> None:
    truth = np.array([[100.0, 100.0], [110.0, 100.0]], np.float32)
    one = np.array([[105.0, 100.0]], np.float32)
    assert match_count(one, truth, 8.0) == 1  # one prediction cannot match two heads
    assert match_count(one, truth, 4.0) == 0
    both = np.array([[101.0, 100.0], [108.0, 101.0], [300.0, 300.0]], np.float32)
    assert match_count(both, truth, 4.0) == 2
    assert match_count(np.zeros((0, 2), np.float32), truth, 8.0) == 0


def test_occupancy_scores_on_a_generated_frame(tmp_path: Path) -> None:
    written = generate(tmp_path, Split.HELDOUT, frames=1)
    stem = written[0].stem
    label = json.loads((tmp_path / "heldout" / f"{stem}.json").read_text())
    mask = read_mask(tmp_path / "heldout" / f"{stem}.mask.png")
    heads = np.asarray(label["heads"], np.float32).reshape(-1, 2)
    assert mask.any()
    config = OccupancyConfig()
    # A perfect density (each visible head one person) and an empty one.
    perfect = np.zeros((120, 160), np.float32)
    for u, v in heads:
        perfect[min(119, int(v // 4)), min(159, int(u // 4))] += 1.0
    good = score_frame(stem, DensityMap(perfect, 640, 480), heads, mask, label, config)
    empty = score_frame(stem, DensityMap(np.zeros_like(perfect), 640, 480), heads, mask, label, config)
    assert empty.missed_person_px == empty.person_px
    assert empty.false_occupied_px == 0
    assert good.missed_person_px < 0.2 * good.person_px  # dilated heads cover most of the bodies
    assert good.false_occupied_px < 0.05 * good.free_ground_px
    assert good.predicted_count == pytest.approx(len(heads))
    assert good.matched["8px"] >= 0.9 * len(heads)
    band = next(b for b in ALTITUDE_BANDS_M if b[0] <= good.altitude_m < b[1])
    summary = summarise([good], band)
    assert summary.frames == 1
    assert summary.count_mae == pytest.approx(0.0, abs=1e-3)
    assert 0.0 <= summary.occupancy_miss_rate <= 1.0


@pytest.mark.parametrize("kind", list(DistractorKind))
def test_distractors_are_drawn_and_never_cover_people(kind: DistractorKind) -> None:
    rng = np.random.default_rng(7)
    colour, alpha = draw(kind, 64, rng)
    assert colour.shape == (64, 64, 3)
    assert alpha.shape == (64, 64)
    assert float(alpha.max()) > 0.1
    assert float(alpha.min()) >= 0.0
    assert float(alpha.max()) <= 1.0
    image = np.full((120, 160, 3), 128, np.uint8)
    people = np.zeros((120, 160), bool)
    people[40:80, 60:100] = True
    out = paste(image, people, np.random.default_rng(1), 40, 100)
    assert np.array_equal(out[people], image[people])
    assert not np.array_equal(out, image)
