"""Evaluation on real frames with person boxes (models/eval/real.py): the scores, and a whole run on a written set
with the shipped model (real onnxruntime)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.perception.config import OccupancyConfig
from companion.perception.density import DensityMap, OnnxDensityModel
from models.data.loaders import load_real_set
from models.data.real_ground import GROUND_DIR, HELDOUT, frame_names
from models.eval import real
from models.eval.real import (
    RealFrameScore,
    band_name,
    ground_sets,
    occupied_cells,
    resize_frame,
    score_real_frame,
    summarise_real,
    tiled_density,
    training_sites,
)

pytestmark = pytest.mark.unit

SHIPPED = Path("models/density/slz_lite.onnx")


def _grid(occupied_rc: list[tuple[int, int]], rows: int = 30, cols: int = 40) -> tuple[DensityMap, np.ndarray]:
    d = np.zeros((rows, cols), np.float32)
    for r, c in occupied_rc:
        d[r, c] = 0.5
    density = DensityMap(d, cols * 4, rows * 4)
    return density, occupied_cells(density, OccupancyConfig(density_threshold=0.01, dilation_m=0.5))


def test_a_box_is_found_when_an_occupied_cell_overlaps_it() -> None:
    density, occupied = _grid([(5, 5), (20, 30)])
    assert occupied.sum() == 2  # no dilation, whatever the config says
    boxes = np.array([[18.0, 18.0, 24.0, 26.0], [80.0, 40.0, 90.0, 50.0]])  # cell (5, 5) is px 20-24: in box 1 only
    score = score_real_frame("f.jpg", 1.0, None, density, occupied, boxes)
    assert (score.boxes, score.found_boxes) == (2, 1)
    # Cell (20, 30) lies far from both boxes: false-occupied; cell (5, 5) is inside a box: not counted.
    assert score.false_occupied_cells == 1
    # Boxes grown by half their longer side: px 14-28 x 14-30 (cells 3-6 x 3-7) and 75-95 x 35-55 (18-23 x 8-13).
    assert score.free_cells == 30 * 40 - 4 * 5 - 6 * 6
    assert score.false_occupied_fraction == pytest.approx(1 / score.free_cells)
    assert score.count_ratio == pytest.approx(1.0 / 2)


def test_a_frame_with_nobody_has_no_recall_and_no_count_ratio() -> None:
    density, occupied = _grid([(1, 1)])
    score = score_real_frame("empty.jpg", 0.5, 12.0, density, occupied, np.zeros((0, 4)))
    assert score.free_cells == 30 * 40
    assert score.false_occupied_fraction == pytest.approx(1 / 1200)
    assert math.isnan(score.count_ratio)


def _score(boxes: int, found: int, false_occupied: int, count: float, altitude: float | None = None) -> RealFrameScore:
    return RealFrameScore("x", 1.0, altitude, boxes, found, 100, false_occupied, count)


def test_summary_pools_recall_and_takes_medians_and_judges_the_targets() -> None:
    scores = [_score(10, 10, 1, 10.0), _score(20, 19, 3, 40.0), _score(0, 0, 1, 0.5), _score(5, 5, 2, 5.0)]
    s = summarise_real("m", "set", 1.0, "all", scores)
    assert (s.frames, s.boxes, s.empty_frames) == (4, 35, 1)
    assert s.recall == pytest.approx(34 / 35)
    assert s.median_false_occupied == pytest.approx(0.015)  # 1, 1, 2, 3 % of 100 cells
    assert s.median_false_occupied_empty == pytest.approx(0.01)
    assert s.median_count_ratio == pytest.approx(1.0)  # 1, 2, 1: frames with nobody left out
    assert s.meets_targets
    assert not summarise_real("m", "set", 1.0, "all", [_score(10, 9, 1, 10.0)]).meets_targets  # recall 0.9
    assert not summarise_real("m", "set", 1.0, "all", [_score(10, 10, 10, 10.0)]).meets_targets  # 10 % occupied
    assert not summarise_real("m", "set", 1.0, "all", [_score(10, 10, 1, 40.0)]).meets_targets  # 4x the people
    assert not summarise_real("m", "set", 1.0, "all", [_score(0, 0, 3, 0.0)]).meets_targets  # 3 % with nobody


def test_altitude_bands() -> None:
    assert [band_name(a) for a in (None, 2.0, 7.9, 8.0, 39.0, 100.0, 500.0)] == [
        "unknown",
        "2-8",
        "2-8",
        "8-12",
        "20-40",
        "40-140",
        "other",
    ]


def test_half_scale_shrinks_the_frame_and_its_boxes() -> None:
    image = np.zeros((100, 60, 3), np.uint8)
    small, boxes = resize_frame(image, np.array([[10.0, 20.0, 30.0, 40.0]]), 0.5)
    assert small.shape == (50, 30, 3)
    np.testing.assert_allclose(boxes, [[5.0, 10.0, 15.0, 20.0]])


def test_tiles_cover_a_large_frame_and_equal_the_model_on_one_tile() -> None:
    model = OnnxDensityModel(SHIPPED, intra_op_threads=1)
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 255, size=(480, 640, 3), dtype=np.uint8)
    np.testing.assert_allclose(tiled_density(model, frame).values, model.predict(frame).values, atol=1e-6)
    big = rng.integers(0, 255, size=(701, 1001, 3), dtype=np.uint8)
    assert tiled_density(model, big).values.shape == (math.ceil(701 / 4), math.ceil(1001 / 4))
    small = rng.integers(0, 255, size=(300, 500, 3), dtype=np.uint8)
    assert tiled_density(model, small).values.shape == (75, 125)


def _write_set(root: Path) -> None:
    """Two frames of grass-like noise with dark 'people' (ellipses with a head) and their boxes."""
    rng = np.random.default_rng(3)
    images = {}
    for name, people in (("crowd.jpg", [(200, 150), (400, 300), (600, 200)]), ("empty.jpg", [])):
        image = np.clip(rng.normal(110, 12, size=(520, 760, 3)), 0, 255).astype(np.uint8)
        image[:, :, 1] = np.clip(image[:, :, 1].astype(int) + 40, 0, 255)
        boxes = []
        for u, v in people:
            cv2.ellipse(image, (u, v), (7, 12), 0, 0, 360, (40, 40, 160), -1)
            cv2.circle(image, (u, v - 4), 4, (20, 20, 20), -1)
            boxes.append([u - 9, v - 14, u + 9, v + 14])
        cv2.imwrite(str(root / name), image)
        images[name] = {"people_boxes_xyxy": boxes}
    (root / "boxes.json").write_text(json.dumps({"images": images}), encoding="utf-8")


@pytest.mark.integration
def test_a_whole_run_scores_every_model_on_the_same_frames(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    data = tmp_path / "datasets" / "tiny-set"
    data.mkdir(parents=True)
    _write_set(data)
    out = tmp_path / "results" / "real"
    argv = [
        "real",
        *("--model", f"shipped={SHIPPED}", "--model", "placeholder=models/blob_detector/blob_detector.onnx"),
        *("--datasets", str(tmp_path / "datasets"), "--out", str(out), "--overlays", str(tmp_path / "overlays")),
        "--no-real-ground",
    ]
    monkeypatch.setattr(sys, "argv", argv)
    assert real.main() == 0
    payload = json.loads(out.with_suffix(".json").read_text(encoding="utf-8"))
    for name in ("shipped", "placeholder"):
        entry = payload["models"][name]["sets"]["tiny-set"]
        assert [(f["image"], f["scale"]) for f in entry["frames"]] == [
            ("crowd.jpg", 1.0),
            ("crowd.jpg", 0.5),
            ("empty.jpg", 1.0),
            ("empty.jpg", 0.5),
        ]
        summaries = {(s["scale"], s["band"]): s for s in entry["summaries"]}
        assert set(summaries) == {(1.0, "all"), (0.5, "all")}
        for s in summaries.values():
            assert (s["frames"], s["boxes"], s["empty_frames"]) == (2, 3, 1)
            assert 0.0 <= s["recall"] <= 1.0
            assert 0.0 <= s["median_false_occupied"] <= 1.0
    table = out.with_suffix(".md").read_text(encoding="utf-8")
    assert table.count("| tiny-set |") == 4  # two models x two scales
    assert len(list((tmp_path / "overlays").glob("*.jpg"))) == 4  # two models x two frames, native scale


def test_a_run_without_any_set_says_so(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    argv = ["real", "--model", f"shipped={SHIPPED}", "--datasets", str(tmp_path / "nothing"), "--no-real-ground"]
    monkeypatch.setattr(sys, "argv", argv)
    assert real.main() == 2


def test_the_real_ground_held_out_from_training_is_a_real_set_with_nobody_in_it() -> None:
    frames = load_real_set(GROUND_DIR)
    assert len(frames) == len(frame_names(HELDOUT)) == 16
    assert all(f.boxes_xyxy.shape == (0, 4) for f in frames)
    assert {f.image_path.stem for f in frames} == set(frame_names(HELDOUT))


def test_the_shipped_models_name_the_real_sites_they_trained_on() -> None:
    assert training_sites(Path("models/density/slz_lite.onnx")) == frozenset()  # rendered frames only
    assert training_sites(Path("models/density/slz_lite_wide_real.onnx")) == {"caliterra"}


def test_a_model_is_scored_on_every_frame_of_a_site_it_never_saw_and_only_the_held_out_frames_of_its_own() -> None:
    unseen = ground_sets(frozenset())
    assert set(unseen) == {
        "boruszyn (site held out)",
        "caliterra (site held out)",
        "garfield (site held out)",
        "neon (site held out)",
    }
    assert len(unseen["caliterra (site held out)"]) == 74  # every frame: the model never trained on this site
    assert len(unseen["garfield (site held out)"]) == 28
    seen = ground_sets(frozenset({"caliterra"}))
    assert set(seen) == {
        "boruszyn (site held out)",
        "caliterra (trained-on site)",
        "garfield (site held out)",
        "neon (site held out)",
    }
    assert {f.image_path.stem for f in seen["caliterra (trained-on site)"]} == set(frame_names(HELDOUT))
    assert all(f.boxes_xyxy.shape == (0, 4) for frames in seen.values() for f in frames)
