"""How a density model trades person recall against false-occupied ground on real frames, over a grid of thresholds.

One threshold (``models/eval/real.py``) says where a model stands; the curve says whether a candidate *ranks* real
people above real ground better than another, or only moves along the same curve (fewer false positives bought
with fewer people found). Per (model, set, scale) over :data:`THRESHOLDS` (people per density cell, in the
perception config's units: a file with a baked operating threshold maps 0.01 to its own), pooled recall and median
false-occupied fraction exactly as ``models/eval/real.py`` scores them (no dilation), and the summary that compares
models at the same safety: the median false-occupied fraction at the **highest threshold whose recall is at least**
:data:`models.eval.real.TARGET_RECALL` (0.97).

**A diagnostic, never a way to choose.** SDD is a test set: a threshold read off this curve would be tuned to it.
Thresholds are chosen on validation data only (``models/eval/threshold.py``); this says what a choice cost.

Run::

    .venv/bin/python -m models.eval.tradeoff --model slz-lite=models/density/slz_lite.onnx \\
        --model wide-real=models/density/slz_lite_wide_real.onnx --out models/eval/results/tradeoff

Writes ``OUT.json`` and ``OUT.md`` and prints the table. Sets: every folder under ``../shared/datasets`` that has
boxes (frames with nobody have no recall to trade), or ``--data``.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from companion.perception.config import OccupancyConfig, load_perception_config
from companion.perception.density import DensityMap, OnnxDensityModel
from models.data.images import read_bgr
from models.data.loaders import BoxedImage, DatasetError, load_real_set
from models.eval.real import (
    TARGET_RECALL,
    add_real_set_arguments,
    default_sets,
    named_models,
    occupied_cells,
    resize_frame,
    score_real_frame,
    summarise_real,
    tiled_density,
    write_report,
)

THRESHOLDS = (0.002, 0.003, 0.004, 0.005, 0.006, 0.008, 0.01, 0.012, 0.015, 0.02, 0.03)


@dataclass(frozen=True)
class TradeoffPoint:
    """One threshold of one curve: pooled person recall and median false-occupied fraction (fractions)."""

    threshold: float
    recall: float
    median_false_occupied: float


@dataclass(frozen=True)
class Tradeoff:
    """One model's curve on one set at one scale, and its false-occupied fraction at matched recall."""

    model: str
    dataset: str
    scale: float
    points: list[TradeoffPoint]

    @property
    def at_target_recall(self) -> TradeoffPoint | None:
        """The point of the highest threshold whose recall is at least :data:`TARGET_RECALL` (None: no such)."""
        safe = [p for p in self.points if p.recall >= TARGET_RECALL]
        return max(safe, key=lambda p: p.threshold) if safe else None


def curve(
    frames: list[tuple[str, DensityMap, np.ndarray]],
    occupancy: OccupancyConfig,
    thresholds: tuple[float, ...] = THRESHOLDS,
) -> list[TradeoffPoint]:
    """Recall and median false-occupied at each threshold, for frames given as (name, density, boxes (N, 4) xyxy
    in the density's frame pixels); the rest of ``occupancy`` as configured (its relative threshold included)."""
    points = []
    for threshold in thresholds:
        config = occupancy.model_copy(update={"density_threshold": threshold})
        scores = [
            score_real_frame(name, 1.0, None, density, occupied_cells(density, config), boxes)
            for name, density, boxes in frames
        ]
        summary = summarise_real("", "", 1.0, "all", scores)
        points.append(TradeoffPoint(threshold, summary.recall, summary.median_false_occupied))
    return points


def densities(
    model: OnnxDensityModel, frames: list[BoxedImage], scale: float
) -> list[tuple[str, DensityMap, np.ndarray]]:
    """Each boxed frame's density at ``scale`` (tiled as ``models/eval/real.py`` does), with its boxes scaled."""
    out = []
    for frame in frames:
        image, boxes = resize_frame(read_bgr(frame.image_path), frame.boxes_xyxy, scale)
        out.append((frame.image_path.name, tiled_density(model, image), boxes))
    return out


def _pct(value: float) -> str:
    return "n/a" if math.isnan(value) else f"{100 * value:.1f} %"


def tradeoff_table(curves: list[Tradeoff]) -> str:
    """Markdown: per curve, recall / false-occupied at each threshold, then the point at matched recall."""
    thresholds = [p.threshold for p in curves[0].points]
    head = (
        "| set | scale | model | "
        + " | ".join(f"{t:g}" for t in thresholds)
        + f" | false-occupied at recall >= {TARGET_RECALL:g} (threshold) |\n"
        + "|---" * (4 + len(thresholds))
        + "|\n"
    )
    lines = []
    for c in sorted(curves, key=lambda c: (c.dataset, -c.scale)):
        cells = " | ".join(f"{p.recall:.3f} / {_pct(p.median_false_occupied)}" for p in c.points)
        best = c.at_target_recall
        matched = "none" if best is None else f"{_pct(best.median_false_occupied)} ({best.threshold:g})"
        lines.append(f"| {c.dataset} | {c.scale:g} | {c.model} | {cells} | {matched} |")
    return head + "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description="Recall against false-occupied ground on real frames (diagnostic).")
    add_real_set_arguments(parser, Path("models/eval/results/tradeoff"), "a real set's folder with boxes (repeatable)")
    args = parser.parse_args()
    try:
        loaded = {folder.name: load_real_set(folder) for folder in args.data or []} or default_sets(args.datasets)
    except DatasetError as exc:
        sys.stderr.write(f"error: {exc}\n")
        return 2
    boxed = {name: frames for name, frames in loaded.items() if any(len(f.boxes_xyxy) for f in frames)}
    if not boxed:
        sys.stderr.write(f"error: no real set with annotated people (give --data, or put sets under {args.datasets})\n")
        return 2
    occupancy = load_perception_config(args.config).occupancy
    curves: list[Tradeoff] = []
    for name, path in named_models(parser, args.model):
        model = OnnxDensityModel(path)
        for dataset, frames in boxed.items():
            for scale in args.scales:
                points = curve(densities(model, frames, scale), occupancy)
                curves.append(Tradeoff(name, dataset, scale, points))
    payload: dict[str, object] = {
        "config": str(args.config),
        "target_recall": TARGET_RECALL,
        "curves": [asdict(c) | {"at_target_recall": c.at_target_recall and asdict(c.at_target_recall)} for c in curves],
    }
    write_report(args.out, payload, tradeoff_table(curves))
    return 0


if __name__ == "__main__":
    sys.exit(main())
