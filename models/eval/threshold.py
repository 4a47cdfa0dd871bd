"""Choose a model's occupancy threshold on validation data only: no held-out frame, no SDD frame.

The threshold (``perception.occupancy.density_threshold``, people per density cell) trades safety (person pixels the
map calls free) against availability (empty ground it calls occupied). It is chosen here, for a candidate model, on:

- **synthetic validation frames**: training-style scenes the model was never trained on (``models/data/generate.py
  --split train --first 1600 --altitude-m 2 40``: scenes 200 and up, the training styles, 2-40 m), run as the
  companion runs them (frames shrunk to ``min_gsd_m_per_px``, the 0.5 m dilation);
- **real validation ground**: the Caliterra training-split frames whose number ends in 2
  (:func:`models.data.real_ground.is_validation`; nobody in them, never trained on), at 0.045 and 0.09 m/px, no
  dilation, as ``models/eval/real.py`` scores real frames.

**The rule**: the highest threshold of the grid at which the candidate misses no more person pixels of the synthetic
validation frames (2-40 m pooled) than the reference model (today's default) at its own threshold; the real
validation ground then says how much empty ground that threshold keeps. Nothing is tuned on the frames the model is
judged on.

Run::

    .venv/bin/python -m models.eval.threshold --model slz-lite-real=runs/train/lite_real.onnx \\
        --reference slz-lite=models/density/slz_lite.onnx@0.01 --synthetic data/synth_val/train \\
        --out models/eval/results/threshold_slz-lite-real

Writes ``OUT.json`` and ``OUT.md`` and prints the table.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from companion.perception.config import OccupancyConfig, load_perception_config
from companion.perception.density import DensityMap, OnnxDensityModel, input_scale, predict_downscaled
from models.data.images import read_bgr, read_mask
from models.data.real_ground import GROUND_DIR, TRAIN, RealGround, is_validation, load_ground
from models.eval.metrics import frame_gsd_m_per_px, score_frame, summarise
from models.eval.real import occupied_cells, tiled_density

THRESHOLDS = (0.002, 0.003, 0.004, 0.005, 0.006, 0.007, 0.008, 0.01, 0.012, 0.015, 0.02, 0.025, 0.03, 0.04, 0.05)
REAL_SCALES = (1.0, 0.5)
BANDS_M = ((2.0, 8.0), (8.0, 12.0), (2.0, 40.0))


@dataclass(frozen=True)
class ThresholdRow:
    """Validation scores of one model at one threshold (rates as fractions)."""

    threshold: float
    miss: dict[str, float]
    false_occupied: dict[str, float]
    real_occupied: dict[str, float]


@dataclass
class _Synthetic:
    stem: str
    density: DensityMap
    heads_px: np.ndarray
    mask: np.ndarray
    label: dict[str, object]


def _band(band_m: tuple[float, float]) -> str:
    return f"{band_m[0]:g}-{band_m[1]:g}"


def synthetic_frames(model: OnnxDensityModel, split_dir: Path, min_gsd_m_per_px: float) -> list[_Synthetic]:
    """Every labelled frame of ``split_dir`` with the model's density, shrunk as the companion shrinks it."""
    labels = sorted(p for p in split_dir.glob("*.json") if p.stem.isdigit())
    if not labels:
        raise FileNotFoundError(f"no labelled frames (NNNNNN.json) in {split_dir}")
    out = []
    for path in labels:
        label = json.loads(path.read_text(encoding="utf-8"))
        image = read_bgr(split_dir / f"{path.stem}.png")
        density = predict_downscaled(model, image, input_scale(frame_gsd_m_per_px(label), min_gsd_m_per_px))
        heads = np.asarray(label["heads"], np.float32).reshape(-1, 2)
        out.append(_Synthetic(path.stem, density, heads, read_mask(split_dir / f"{path.stem}.mask.png"), label))
    return out


def real_validation_frames(root: Path) -> list[RealGround]:
    """The real validation frames of a real-ground folder (:func:`models.data.real_ground.is_validation`)."""
    frames = [g for g in load_ground(TRAIN, root) if is_validation(g.name)]
    if not frames:
        raise FileNotFoundError(f"no real validation frame (training-split number ending in 2) in {root}")
    return frames


def real_densities(model: OnnxDensityModel, frames: list[RealGround]) -> dict[float, list[DensityMap]]:
    """Densities of the real validation frames at every scale of :data:`REAL_SCALES`."""
    out: dict[float, list[DensityMap]] = {s: [] for s in REAL_SCALES}
    for frame in frames:
        for scale in REAL_SCALES:
            image = frame.image_bgr
            if scale != 1.0:
                image = np.asarray(cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA), np.uint8)
            out[scale].append(tiled_density(model, image))
    return out


def scores_at(
    threshold: float,
    synthetic: list[_Synthetic],
    real: dict[float, list[DensityMap]],
    occupancy: OccupancyConfig,
    real_gsd_m_per_px: float,
) -> ThresholdRow:
    """Validation scores at one threshold (the rest of the occupancy config as given)."""
    config = occupancy.model_copy(update={"density_threshold": threshold})
    scored = [score_frame(f.stem, f.density, f.heads_px, f.mask, f.label, config) for f in synthetic]
    miss, false_occupied = {}, {}
    for band in BANDS_M:
        summary = summarise(scored, band)
        miss[_band(band)] = summary.occupancy_miss_rate
        false_occupied[_band(band)] = summary.false_occupied_fraction
    real_occupied = {
        f"{real_gsd_m_per_px / scale:.3f}": float(np.median([occupied_cells(d, config).mean() for d in maps]))
        for scale, maps in real.items()
    }
    return ThresholdRow(threshold, miss, false_occupied, real_occupied)


def choose(rows: list[ThresholdRow], max_miss: float) -> ThresholdRow | None:
    """The highest threshold whose 2-40 m miss rate is at most ``max_miss`` (None when none is)."""
    allowed = [r for r in rows if r.miss["2-40"] <= max_miss]
    return max(allowed, key=lambda r: r.threshold) if allowed else None


def _pct(value: float) -> str:
    return "n/a" if math.isnan(value) else f"{100 * value:.2f} %"


def table(name: str, rows: list[ThresholdRow], reference: ThresholdRow, reference_name: str) -> str:
    """Markdown: every threshold's row, the reference's row, the choice."""
    gsds = list(reference.real_occupied)
    head = (
        "| model | threshold | miss 2-8 m | miss 8-12 m | miss 2-40 m | false-occupied 2-40 m | "
        + " | ".join(f"real ground occupied, {g} m/px" for g in gsds)
        + " |\n|"
        + "---|" * (6 + len(gsds))
        + "\n"
    )

    def line(model: str, r: ThresholdRow) -> str:
        cells = [model, f"{r.threshold:g}", _pct(r.miss["2-8"]), _pct(r.miss["8-12"]), _pct(r.miss["2-40"])]
        cells += [_pct(r.false_occupied["2-40"])] + [_pct(r.real_occupied[g]) for g in gsds]
        return "| " + " | ".join(cells) + " |\n"

    body = line(f"{reference_name} (reference)", reference) + "".join(line(name, r) for r in rows)
    chosen = choose(rows, reference.miss["2-40"])
    verdict = (
        f"\nChosen for {name}: **{chosen.threshold:g}**, the highest threshold that misses no more person pixels of "
        f"the synthetic validation frames than {reference_name} at {reference.threshold:g} "
        f"({_pct(chosen.miss['2-40'])} against {_pct(reference.miss['2-40'])}).\n"
        if chosen
        else f"\nNo threshold of the grid holds {reference_name}'s miss rate ({_pct(reference.miss['2-40'])}).\n"
    )
    return head + body + verdict


def main() -> int:
    parser = argparse.ArgumentParser(description="Choose an occupancy threshold on validation data (module docstring).")
    parser.add_argument("--model", required=True, help="NAME=PATH.onnx: the candidate")
    parser.add_argument("--reference", required=True, help="NAME=PATH.onnx@THRESHOLD: today's default")
    parser.add_argument("--synthetic", type=Path, default=Path("data/synth_val/train"))
    parser.add_argument("--real-ground", type=Path, default=GROUND_DIR)
    parser.add_argument("--config", type=Path, default=Path("mission_configs/perception.yaml"))
    parser.add_argument("--out", type=Path, required=True, help="OUT.json and OUT.md are written")
    args = parser.parse_args()
    name, _, path = args.model.partition("=")
    ref_name, _, ref_spec = args.reference.partition("=")
    ref_path, _, ref_threshold = ref_spec.rpartition("@")
    if not path or not ref_path or not ref_threshold:
        parser.error("--model wants NAME=PATH and --reference NAME=PATH@THRESHOLD")
    config = load_perception_config(args.config)
    real_frames = real_validation_frames(args.real_ground)
    gsd = real_frames[0].gsd_m_per_px

    def measure(model_path: str) -> tuple[list[_Synthetic], dict[float, list[DensityMap]]]:
        model = OnnxDensityModel(model_path)
        synthetic = synthetic_frames(model, args.synthetic, config.model.min_gsd_m_per_px)
        return synthetic, real_densities(model, real_frames)

    ref_synthetic, ref_real = measure(ref_path)
    reference = scores_at(float(ref_threshold), ref_synthetic, ref_real, config.occupancy, gsd)
    synthetic, real = measure(path)
    rows = [scores_at(t, synthetic, real, config.occupancy, gsd) for t in THRESHOLDS]
    text = table(name, rows, reference, ref_name)
    chosen = choose(rows, reference.miss["2-40"])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "model": {"name": name, "path": path},
        "reference": {"name": ref_name, "path": ref_path, **asdict(reference)},
        "synthetic": str(args.synthetic),
        "synthetic_frames": len(synthetic),
        "real_ground": str(args.real_ground),
        "rows": [asdict(r) for r in rows],
        "chosen_threshold": chosen.threshold if chosen else None,
    }
    args.out.with_suffix(".json").write_text(json.dumps(payload, indent=1) + "\n", encoding="utf-8")
    args.out.with_suffix(".md").write_text(text, encoding="utf-8")
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
