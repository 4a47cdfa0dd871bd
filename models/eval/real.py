"""Counts on real aerial frames (the Stanford Drone Dataset reference frames in ``../shared/datasets/sdd-reference``).

Those frames are evaluation data under a non-commercial licence: they are read from where they lie, never copied
into the repository, never trained on. Each frame is covered at its native resolution by overlapping 640x480 tiles
(the model's input size; people there are about as large as in our 10-30 m frames); overlapping density is averaged.
The predicted count is printed beside the dataset's median and maximum people per frame, which count only moving
people and are an order of magnitude, not an exact truth. Overlays (density and detected heads over the frame) go
to ``--overlays`` (by default under ``runs/``, which git ignores).

Run::

    .venv/bin/python -m models.eval.real --model slz-lite=models/density/slz_lite.onnx \
        --data ../shared/datasets/sdd-reference --out models/eval/results/sdd.json
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from companion.perception.density import DensityMap, OnnxDensityModel
from models.data.images import read_bgr
from models.eval.metrics import detect_heads


def _starts(length: int, tile: int) -> list[int]:
    if length <= tile:
        return [0]
    n = math.ceil(length / tile)
    return [round(i * (length - tile) / (n - 1)) for i in range(n)]


def tiled_density(model: OnnxDensityModel, image_bgr: npt.NDArray[np.uint8]) -> DensityMap:
    """Density of a frame of any size at native resolution: overlapping tiles of the model's input size, averaged.

    Frames smaller than a tile are padded with their edge pixels (the padding's density is cut off).
    """
    c = model.contract
    tw, th, s = c.input_width_px, c.input_height_px, c.output_stride
    h, w = image_bgr.shape[:2]
    H, W = max(h, th), max(w, tw)
    H, W = H + (-H) % s, W + (-W) % s
    padded = np.asarray(cv2.copyMakeBorder(image_bgr, 0, H - h, 0, W - w, cv2.BORDER_REPLICATE), np.uint8)
    total = np.zeros((H // s, W // s), np.float64)
    weight = np.zeros_like(total)
    for y0 in _starts(H, th):
        for x0 in _starts(W, tw):
            tile = np.ascontiguousarray(padded[y0 : y0 + th, x0 : x0 + tw])
            d = model.predict(tile).values
            ys, xs = y0 // s, x0 // s
            total[ys : ys + d.shape[0], xs : xs + d.shape[1]] += d
            weight[ys : ys + d.shape[0], xs : xs + d.shape[1]] += 1.0
    values = (total / np.maximum(weight, 1.0)).astype(np.float32)
    values = values[: math.ceil(h / s), : math.ceil(w / s)]
    return DensityMap(values, frame_width_px=values.shape[1] * s, frame_height_px=values.shape[0] * s)


def overlay(image_bgr: npt.NDArray[np.uint8], density: DensityMap) -> npt.NDArray[np.uint8]:
    """The frame darkened, density in red, detected heads circled in yellow."""
    h, w = image_bgr.shape[:2]
    heat = cv2.resize(
        density.values, (density.frame_width_px, density.frame_height_px), interpolation=cv2.INTER_NEAREST
    )
    heat = heat[:h, :w]
    out = (image_bgr.astype(np.float32) * 0.6).astype(np.float32)
    red = np.clip(heat / 0.05, 0.0, 1.0)
    out[:, :, 2] = np.maximum(out[:, :, 2], 255.0 * red)
    result = np.clip(out, 0, 255).astype(np.uint8)
    for u, v in detect_heads(density):
        cv2.circle(result, (int(u), int(v)), 8, (0, 255, 255), 2)
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description="Predicted people counts on real aerial frames, beside the reference.")
    parser.add_argument("--model", action="append", required=True, help="NAME=PATH.onnx (repeatable)")
    parser.add_argument("--data", type=Path, default=Path("../shared/datasets/sdd-reference"))
    parser.add_argument("--out", type=Path, default=Path("models/eval/results/sdd.json"))
    parser.add_argument("--overlays", type=Path, default=Path("runs/eval/sdd"))
    args = parser.parse_args()
    counts_csv = args.data / "people_counts.csv"
    if not counts_csv.is_file():
        sys.stderr.write(f"error: {counts_csv} not found (the SDD reference frames are not on this machine)\n")
        return 2
    with counts_csv.open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    results: dict[str, object] = {"data": str(args.data), "models": {}}
    lines = ["| image | people median (max) | " + " | ".join(s.partition("=")[0] for s in args.model) + " |"]
    lines.append("|---|---|" + "---|" * len(args.model))
    per_image: dict[str, list[str]] = {r["image"]: [] for r in rows}
    for spec in args.model:
        name, _, path = spec.partition("=")
        model = OnnxDensityModel(path)
        entries = []
        for row in rows:
            image = read_bgr(args.data / row["image"])
            density = tiled_density(model, image)
            predicted = float(density.values.sum())
            median = float(row["people_per_frame_median"])
            entries.append(
                {
                    "image": row["image"],
                    "size_px": [image.shape[1], image.shape[0]],
                    "predicted_count": predicted,
                    "detected_heads": len(detect_heads(density)),
                    "reference_median": median,
                    "reference_max": float(row["people_per_frame_max"]),
                    "ratio_to_median": predicted / median if median else math.nan,
                }
            )
            per_image[row["image"]].append(f"{predicted:.1f}")
            args.overlays.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(args.overlays / f"{name}_{Path(row['image']).stem}.jpg"), overlay(image, density))
        ratios = [float(str(e["ratio_to_median"])) for e in entries]
        models = results["models"]
        assert isinstance(models, dict)
        models[name] = {
            "path": path,
            "images": entries,
            "median_ratio_to_median": float(np.median(ratios)),
            "total_predicted": float(sum(float(str(e["predicted_count"])) for e in entries)),
            "total_reference_median": float(sum(float(r["people_per_frame_median"]) for r in rows)),
        }
    for row in rows:
        lines.append(
            f"| {row['image']} | {row['people_per_frame_median']} ({row['people_per_frame_max']}) | "
            + " | ".join(per_image[row["image"]])
            + " |"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    sys.stdout.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
