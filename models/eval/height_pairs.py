"""The height map of real photograph pairs against hand labels (issue 64): how much of each labelled class the map
calls above the ground.

Run: ``.venv/bin/python -m models.eval.height_pairs [--labels models/eval/data/height_pairs.json]
[--out models/eval/results/height_pairs] [--overlays docs/images/height]``. For each pair of ``--labels`` (two
overlapping photographs of a real site and rectangles of classes on the first) it runs ``slz height-map``'s
measurement (:mod:`companion.tools.height_pair`) and counts, per class, over the cells of the labelled rectangles that
the second photograph also shows: the share flagged above the ground (standing or moving), the share measured flat,
and the share unknown. Flat classes (lawn, asphalt) should not be flagged; standing ones (trees, cars, buildings)
should. Writes ``OUT.json`` and ``OUT.md`` and an overlay of each pair with its labels.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from companion.perception.config import MotionHeightConfig, OccupancyConfig, load_perception_config
from companion.perception.density import OnnxDensityModel
from companion.perception.motion_height import CELL_PX, HeightState
from companion.tools.height_pair import (
    ground_homography,
    overlay,
    pair_geometry,
    pair_height_map,
    photo_meta,
    read_frame,
)
from models.eval.real import occupied_cells, tiled_density

FLAT = ("lawn", "asphalt")
STANDING = ("tree", "car", "building")
DENSITY_GSD_M_PER_PX = 0.045
"""The finer of the two scales the real-ground checks run at (models/eval/real.py), the search's ground sampling."""
COLOURS = {"lawn": (0, 255, 0), "asphalt": (255, 255, 0), "tree": (0, 128, 255), "car": (255, 0, 255)}


def density_occupied(
    model: OnnxDensityModel,
    occupancy: OccupancyConfig,
    frame_bgr: npt.NDArray[np.uint8],
    gsd_m_per_px: float,
    cells: tuple[int, int],
) -> npt.NDArray[np.bool_]:
    """The density map's occupied cells of a frame (no dilation), on the height map's grid ``cells`` (rows, cols):
    the frame run at the finest ground sampling distance the models are checked at (:data:`DENSITY_GSD_M_PER_PX`), in
    tiles of the model's input size (:func:`models.eval.real.tiled_density`)."""
    scale = min(1.0, gsd_m_per_px / DENSITY_GSD_M_PER_PX)
    h, w = frame_bgr.shape[:2]
    small = np.asarray(
        cv2.resize(frame_bgr, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA),
        np.uint8,
    )
    occupied = occupied_cells(tiled_density(model, small), occupancy).astype(np.uint8)
    rows, cols = cells
    return np.asarray(cv2.resize(occupied, (cols, rows), interpolation=cv2.INTER_NEAREST) > 0, np.bool_)


def score_pair(
    source: Path,
    pair: dict[str, Any],
    width_px: int,
    overlays: Path | None,
    models: dict[str, OnnxDensityModel] | None = None,
    occupancy: OccupancyConfig | None = None,
) -> dict[str, dict[str, int]]:
    """Cells per class of one pair: labelled and seen by both, flagged, flat, unknown; with ``models``, per model the
    cells its density map calls occupied (``density:NAME``) and those the fused map does (``fused:NAME``: occupied or
    above the ground, as ``perception.motion_height.fuse`` makes them)."""
    a_bgr, b_bgr = read_frame(source / pair["a"], width_px), read_frame(source / pair["b"], width_px)
    a = np.asarray(cv2.cvtColor(a_bgr, cv2.COLOR_BGR2GRAY), np.uint8)
    b = np.asarray(cv2.cvtColor(b_bgr, cv2.COLOR_BGR2GRAY), np.uint8)
    H, inliers = ground_homography(a, b)
    geometry = pair_geometry(
        a,
        b,
        photo_meta(source / pair["a"], width_px),
        photo_meta(source / pair["b"], width_px),
        H,
        inliers,
        None,
        None,
        None,
    )
    height = pair_height_map(a, b, geometry, H, MotionHeightConfig(enabled=True))
    occupied = {
        name: density_occupied(
            model, occupancy or OccupancyConfig(), a_bgr, geometry.altitude_m / geometry.focal_px, height.state.shape
        )
        for name, model in (models or {}).items()
    }
    h, w = a.shape
    seen = cv2.warpPerspective(np.full_like(b, 255), H, (w, h), flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP)
    rows, cols = height.state.shape
    seen_cells = cv2.resize(seen, (cols, rows), interpolation=cv2.INTER_AREA) == 255
    counts: dict[str, dict[str, int]] = defaultdict(lambda: {"cells": 0, "flagged": 0, "flat": 0, "unknown": 0})
    picture = overlay(a_bgr, height)
    for region in pair["regions"]:
        x0, y0, x1, y1 = region["box"]
        box = np.zeros((rows, cols), bool)
        box[y0 // CELL_PX : y1 // CELL_PX, x0 // CELL_PX : x1 // CELL_PX] = True
        cells = box & seen_cells
        c = counts[region["class"]]
        c["cells"] += int(cells.sum())
        c["flagged"] += int((height.not_ground & cells).sum())
        c["flat"] += int(((height.state == HeightState.GROUND) & cells).sum())
        c["unknown"] += int(((height.state == HeightState.UNKNOWN) & cells).sum())
        for name, by_density in occupied.items():
            c[f"density:{name}"] = c.get(f"density:{name}", 0) + int((by_density & cells).sum())
            c[f"fused:{name}"] = c.get(f"fused:{name}", 0) + int(((by_density | height.not_ground) & cells).sum())
        cv2.rectangle(picture, (x0, y0), (x1, y1), COLOURS.get(region["class"], (255, 255, 255)), 2)
        cv2.putText(picture, region["class"], (x0 + 3, y0 + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
    if overlays is not None:
        overlays.mkdir(parents=True, exist_ok=True)
        name = Path(pair["a"]).stem
        small = cv2.resize(picture, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(overlays / f"{name}.jpg"), small, [cv2.IMWRITE_JPEG_QUALITY, 80])
    return dict(counts)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--labels", type=Path, default=Path("models/eval/data/height_pairs.json"))
    parser.add_argument("--out", type=Path, default=Path("models/eval/results/height_pairs"))
    parser.add_argument("--overlays", type=Path, default=Path("docs/images/height"))
    parser.add_argument(
        "--density",
        nargs="*",
        default=[],
        metavar="NAME=MODEL.onnx",
        help="density models whose occupied cells are counted on the labels, alone and fused with the height map",
    )
    args = parser.parse_args()
    models = {spec.split("=", 1)[0]: OnnxDensityModel(spec.split("=", 1)[1]) for spec in args.density}
    occupancy = load_perception_config(Path("mission_configs/perception.yaml")).occupancy
    labels = json.loads(args.labels.read_text(encoding="utf-8"))
    source = (args.labels.parent / labels["source"]).resolve()
    if not source.is_dir():
        source = Path(labels["source"]).resolve()
    if not source.is_dir():
        sys.stderr.write(f"error: {labels['source']} is not here (the photographs are not in the repository)\n")
        return 2
    per_pair = {}
    total: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for pair in labels["pairs"]:
        counts = score_pair(source, pair, int(labels["width_px"]), args.overlays, models, occupancy)
        per_pair[pair["a"]] = counts
        for name, c in counts.items():
            for key, value in c.items():
                total[name][key] += value
    lines = [
        f"# Height map of real pairs against hand labels ({labels['site']})",
        "",
        "| class | kind | cells seen in both | flagged above the ground | measured flat | unknown |",
        "|---|---|---|---|---|---|",
    ]
    for name, c in sorted(total.items()):
        kind = "flat" if name in FLAT else "standing" if name in STANDING else "other"
        n = max(c["cells"], 1)
        lines.append(
            f"| {name} | {kind} | {c['cells']} | {100 * c['flagged'] / n:.1f} % | {100 * c['flat'] / n:.1f} % "
            f"| {100 * c['unknown'] / n:.1f} % |"
        )
    if models:
        lines += [
            "",
            "Occupied by the density map alone and fused with the height map (occupied or above the ground), on the "
            f"same cells, the frame run at {DENSITY_GSD_M_PER_PX} m/px or coarser:",
            "",
            "| class | kind | " + " | ".join(f"{m}: density alone | {m}: fused" for m in models) + " |",
            "|---|---|" + "---|---|" * len(models),
        ]
        for name, c in sorted(total.items()):
            kind = "flat" if name in FLAT else "standing" if name in STANDING else "other"
            n = max(c["cells"], 1)
            shares = " | ".join(
                f"{100 * c[f'density:{m}'] / n:.1f} % | {100 * c[f'fused:{m}'] / n:.1f} %" for m in models
            )
            lines.append(f"| {name} | {kind} | {shares} |")
    lines.append("")
    for pair_name, counts in per_pair.items():
        shares = ", ".join(f"{k} {100 * c['flagged'] / max(c['cells'], 1):.0f} %" for k, c in sorted(counts.items()))
        lines.append(f"- {pair_name}: flagged {shares}")
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".md").write_text(text, encoding="utf-8")
    args.out.with_suffix(".json").write_text(
        json.dumps({"labels": str(args.labels), "total": total, "pairs": per_pair}, indent=1) + "\n", encoding="utf-8"
    )
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
