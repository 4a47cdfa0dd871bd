"""Evaluate density models on the held-out synthetic split, per altitude band (``models/eval/metrics.py``).

Run::

    .venv/bin/python -m models.eval.evaluate --data data/synth/heldout \
        --model slz-lite=models/density/slz_lite.onnx --model slz-ccnn=models/density/slz_ccnn.onnx \
        --out models/eval/results/heldout

Writes ``OUT.json`` (per-band summaries of every model; with ``--per-frame``, every frame's scores too) and ``OUT.md``
(the table), and prints the table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from companion.perception.config import load_perception_config
from companion.perception.density import OnnxDensityModel, input_scale, predict_downscaled
from models.data.images import read_bgr, read_mask
from models.eval.metrics import (
    ALTITUDE_BANDS_M,
    BandSummary,
    FrameScore,
    frame_gsd_m_per_px,
    score_frame,
    summaries_table,
    summarise,
    write_json,
)


def evaluate_model(
    model: OnnxDensityModel,
    split_dir: Path,
    config_path: Path,
    limit: int | None = None,
    min_gsd_m_per_px: float | None = None,
) -> list[FrameScore]:
    """Score every labelled frame of ``split_dir`` (sorted by stem, at most ``limit``).

    Frames are shrunk as the pipeline shrinks them (``perception.model.min_gsd_m_per_px`` of the config, or
    ``min_gsd_m_per_px`` when given).
    """
    config = load_perception_config(config_path)
    occupancy = config.occupancy
    min_gsd = config.model.min_gsd_m_per_px if min_gsd_m_per_px is None else min_gsd_m_per_px
    scores: list[FrameScore] = []
    labels = sorted(p for p in split_dir.glob("*.json") if p.stem.isdigit())
    if not labels:
        raise FileNotFoundError(f"no labelled frames (NNNNNN.json) in {split_dir}")
    for label_path in labels[:limit]:
        stem = label_path.stem
        label = json.loads(label_path.read_text(encoding="utf-8"))
        image = read_bgr(split_dir / f"{stem}.png")
        mask = read_mask(split_dir / f"{stem}.mask.png")
        density = predict_downscaled(model, image, input_scale(frame_gsd_m_per_px(label), min_gsd))
        heads = np.asarray(label["heads"], np.float32).reshape(-1, 2)
        scores.append(score_frame(stem, density, heads, mask, label, occupancy))
    return scores


def main() -> int:
    parser = argparse.ArgumentParser(description="Evaluate density models on a labelled split, per altitude band.")
    parser.add_argument("--data", type=Path, default=Path("data/synth/heldout"))
    parser.add_argument("--model", action="append", required=True, help="NAME=PATH.onnx (repeatable)")
    parser.add_argument("--config", type=Path, default=Path("mission_configs/perception.yaml"))
    parser.add_argument("--out", type=Path, default=Path("models/eval/results/heldout"))
    parser.add_argument("--limit", type=int, default=None)
    parser.add_argument(
        "--min-gsd", type=float, default=None, help="override perception.model.min_gsd_m_per_px (0: off)"
    )
    parser.add_argument("--per-frame", action="store_true", help="also write every frame's scores to the JSON")
    args = parser.parse_args()
    rows: list[tuple[str, BandSummary]] = []
    payload: dict[str, object] = {"data": str(args.data), "config": str(args.config), "models": {}}
    for spec in args.model:
        name, _, path = spec.partition("=")
        if not path:
            parser.error(f"--model wants NAME=PATH, got {spec!r}")
        start = time.monotonic()
        scores = evaluate_model(OnnxDensityModel(path), args.data, args.config, args.limit, args.min_gsd)
        bands = [summarise(scores, band) for band in ALTITUDE_BANDS_M]
        overall = summarise(scores, (ALTITUDE_BANDS_M[0][0], ALTITUDE_BANDS_M[-1][1]))
        rows += [(name, b) for b in bands] + [(name, overall)]
        models = payload["models"]
        assert isinstance(models, dict)
        models[name] = {"path": path, "bands": bands, "all": overall, **({"frames": scores} if args.per_frame else {})}
        sys.stderr.write(f"{name}: {len(scores)} frames in {time.monotonic() - start:.0f} s\n")
    table = summaries_table(rows)
    # OUT.json and OUT.md; a name such as "heldout_0.045" keeps its dot
    base = args.out.with_suffix("") if args.out.suffix in (".json", ".md") else args.out
    write_json(base.parent / f"{base.name}.json", payload)
    (base.parent / f"{base.name}.md").write_text(table, encoding="utf-8")
    sys.stdout.write(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
