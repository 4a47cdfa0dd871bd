"""The height map of real photograph pairs against hand labels (issue 64): how much of each labelled class the map
calls above the ground.

Run: ``.venv/bin/python -m models.eval.height_pairs [--labels models/eval/data/height_pairs.json]
[--out models/eval/results/height_pairs] [--overlays docs/images/height]``. For each pair of ``--labels`` (two
overlapping photographs of a real site and rectangles of classes on the first) it runs ``slz height-map``'s
measurement (:mod:`companion.app.height_pair`) and counts, per class, over the cells of the labelled rectangles that
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

from companion.app.height_pair import (
    ground_homography,
    overlay,
    pair_geometry,
    pair_height_map,
    photo_meta,
    read_frame,
)
from companion.perception.config import MotionHeightConfig
from companion.perception.motion_height import CELL_PX, HeightState

FLAT = ("lawn", "asphalt")
STANDING = ("tree", "car", "building")
COLOURS = {"lawn": (0, 255, 0), "asphalt": (255, 255, 0), "tree": (0, 128, 255), "car": (255, 0, 255)}


def score_pair(source: Path, pair: dict[str, Any], width_px: int, overlays: Path | None) -> dict[str, dict[str, int]]:
    """Cells per class of one pair: labelled and seen by both, flagged, flat, unknown."""
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
    args = parser.parse_args()
    labels = json.loads(args.labels.read_text(encoding="utf-8"))
    source = (args.labels.parent / labels["source"]).resolve()
    if not source.is_dir():
        source = Path(labels["source"]).resolve()
    if not source.is_dir():
        sys.stderr.write(f"error: {labels['source']} is not here (the photographs are not in the repository)\n")
        return 2
    per_pair = {}
    total: dict[str, dict[str, int]] = defaultdict(lambda: {"cells": 0, "flagged": 0, "flat": 0, "unknown": 0})
    for pair in labels["pairs"]:
        counts = score_pair(source, pair, int(labels["width_px"]), args.overlays)
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
