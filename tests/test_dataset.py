"""The synthetic dataset generator: files, labels that match what was rendered, a style split."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from models.data.generate import WEATHER, Split, generate
from sitl.world.crowd import HELDOUT_ONLY_TYPES, BodyType, Crowd
from sitl.world.scenario import ScenarioConfig, Style

pytestmark = pytest.mark.integration


def test_frames_masks_and_head_labels_agree(tmp_path: Path) -> None:
    written = generate(tmp_path, Split.TRAIN, frames=4, width_px=320, height_px=240)
    assert len(written) == 4
    split_dir = tmp_path / "train"
    index = [json.loads(line) for line in (split_dir / "index.jsonl").read_text().splitlines()]
    assert [row["stem"] for row in index] == [f.stem for f in written]
    total_heads = 0
    for frame in written:
        image = cv2.imread(str(split_dir / f"{frame.stem}.png"))
        mask = cv2.imread(str(split_dir / f"{frame.stem}.mask.png"), cv2.IMREAD_GRAYSCALE)
        assert image is not None
        assert mask is not None
        label = json.loads((split_dir / f"{frame.stem}.json").read_text())
        assert image.shape == (240, 320, 3)
        assert mask.shape == (240, 320)
        assert 8.0 <= label["altitude_m"] <= 40.0
        assert label["weather"]["kind"] in {k.value for k in WEATHER[Split.TRAIN]}
        assert len(label["heads"]) <= label["people_in_view"]
        for u, v in label["heads"]:
            ui, vi = int(u), int(v)
            assert mask[max(0, vi - 1) : vi + 2, max(0, ui - 1) : ui + 2].max() == 255  # labelled heads are visible
        total_heads += len(label["heads"])
    assert total_heads > 20


def test_same_arguments_same_dataset(tmp_path: Path) -> None:
    def digest(root: Path) -> str:
        h = hashlib.sha1()
        for path in sorted((root / "heldout").iterdir()):
            h.update(path.name.encode())
            h.update(path.read_bytes())
        return h.hexdigest()

    generate(tmp_path / "a", Split.HELDOUT, frames=2, width_px=160, height_px=120)
    generate(tmp_path / "b", Split.HELDOUT, frames=2, width_px=160, height_px=120)
    assert digest(tmp_path / "a") == digest(tmp_path / "b")


def test_the_held_out_style_never_appears_in_training() -> None:
    train_bodies: set[BodyType] = set()
    heldout_bodies: set[BodyType] = set()
    train_hues: list[int] = []
    heldout_hues: list[int] = []
    for seed in range(6):
        for style, bodies, hues in (
            (Style.TRAIN, train_bodies, train_hues),
            (Style.HELDOUT, heldout_bodies, heldout_hues),
        ):
            crowd = Crowd(ScenarioConfig(style=style), seed)
            for a in crowd.appearances:
                bodies.add(a.body)
                hsv = cv2.cvtColor(np.array([[a.top_bgr]], dtype=np.uint8), cv2.COLOR_BGR2HSV)[0, 0]
                hues.append(int(hsv[0]))
    assert not train_bodies & set(HELDOUT_ONLY_TYPES)
    assert heldout_bodies & set(HELDOUT_ONLY_TYPES)
    assert max(train_hues) < 50 <= 85 < min(heldout_hues)  # warm versus cool clothing
    assert not set(WEATHER[Split.TRAIN]) & set(WEATHER[Split.HELDOUT])


def test_a_split_rendered_in_chunks_equals_one_run(tmp_path: Path) -> None:
    generate(tmp_path / "one", Split.TRAIN, frames=3, width_px=160, height_px=120, frames_per_scene=2)
    generate(tmp_path / "chunk", Split.TRAIN, frames=2, width_px=160, height_px=120, frames_per_scene=2, first=1)
    assert (tmp_path / "chunk" / "train" / "index.1.jsonl").is_file()
    for stem in ("000001", "000002"):  # frame 1 ends scene 0, frame 2 starts scene 1
        for suffix in (".png", ".mask.png", ".json"):
            one = (tmp_path / "one" / "train" / f"{stem}{suffix}").read_bytes()
            assert one == (tmp_path / "chunk" / "train" / f"{stem}{suffix}").read_bytes()
    assert not (tmp_path / "chunk" / "train" / "000000.png").exists()
