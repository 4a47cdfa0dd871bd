"""How a density model does on real aerial frames with annotated people: safety, availability and counts.

Every real set (a folder in any layout :func:`models.data.loaders.load_real_set` reads; by default every folder of
``../shared/datasets`` and the real ground of every site in ``sitl/world/ground`` (:func:`ground_sets`: all frames of a
site the model never trained on, so that each real-ground figure is a held-out *site*), stored at 0.045 m/px so that
scales 1 and 0.5 are 0.045 and 0.09 m/px) is scored at its native scale and at half scale,
per altitude band when the set records the altitude. Frames larger than the model's input are covered by
overlapping input-sized tiles at the scale being scored, their density averaged where tiles overlap. Occupancy is
the companion's own :class:`~companion.perception.occupancy.OccupancyMapper` with the perception config's thresholds
and **no dilation**. Per frame:

- **person recall** (the safety side): an annotated box is found when at least one occupied density cell overlaps it;
- **false-occupied fraction** (availability): occupied share of the person-free cells, the cells that overlap no box
  grown by half its longer side (boxes can be a few pixels off, and a density blob spreads past its head);
- **count ratio**: the density sum over the number of annotated boxes (frames with at least one box). Sets that
  annotate only moving people (SDD) make the box count a lower bound.

A summary pools recall over boxes and takes medians of the other two over frames; the false-occupied fraction of
frames with nobody annotated is summarised on its own. Targets (issue 22): recall >= 0.97, median false-occupied
<= 0.05 (<= 0.02 on frames with nobody), median count ratio in [1/3, 3].

Real sets under non-commercial licences (SDD) are evaluation data: read from where they lie, never copied into the
repository, never trained on. Overlays (occupied cells in red, found boxes in green, missed boxes in magenta) go to
``--overlays`` (by default under ``runs/``, which git ignores).

Run (``make eval-real``)::

    .venv/bin/python -m models.eval.real --model slz-lite=models/density/slz_lite.onnx --out models/eval/results/real
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from companion.perception.config import OccupancyConfig, load_perception_config
from companion.perception.density import DensityMap, OnnxDensityModel
from companion.perception.occupancy import OccupancyMapper
from companion.perception.projection import OCCUPIED
from models.data.images import read_bgr
from models.data.loaders import BoxedImage, DatasetError, load_real_ground, load_real_set
from models.density.onnx_files import TRAINING_KEY, read_metadata
from sitl.world.ground import GROUND_ROOT

F64Array = npt.NDArray[np.float64]
U8Image = npt.NDArray[np.uint8]
BoolGrid = npt.NDArray[np.bool_]

SCALES = (1.0, 0.5)
REAL_ALTITUDE_BANDS_M: tuple[tuple[float, float], ...] = (
    (2.0, 8.0),
    (8.0, 12.0),
    (12.0, 20.0),
    (20.0, 40.0),
    (40.0, 140.0),
)
PERSON_MARGIN_FRACTION = 0.5
TARGET_RECALL = 0.97
TARGET_FALSE_OCCUPIED = 0.05
TARGET_FALSE_OCCUPIED_EMPTY = 0.02
TARGET_COUNT_RATIO = (1.0 / 3.0, 3.0)


def _starts(length: int, tile: int) -> list[int]:
    if length <= tile:
        return [0]
    n = math.ceil(length / tile)
    return [round(i * (length - tile) / (n - 1)) for i in range(n)]


def tiled_density(model: OnnxDensityModel, image_bgr: U8Image) -> DensityMap:
    """Density of a frame of any size at its resolution: overlapping tiles of the model's input size, averaged.

    Frames smaller than a tile are padded with their edge pixels (the padding's density is cut off).

    Returns
    -------
    DensityMap
        Cells of ``stride`` frame pixels, shape (ceil(H / stride), ceil(W / stride)), people per cell.
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


def occupied_cells(density: DensityMap, occupancy: OccupancyConfig) -> BoolGrid:
    """Occupied density cells, shape of ``density.values``, by the config's thresholds and without dilation."""
    mapper = OccupancyMapper(occupancy.model_copy(update={"dilation_m": 0.0}))
    return np.asarray(mapper.compute(density, 1.0).values == OCCUPIED, np.bool_)


def _cell_range(lo_px: float, hi_px: float, stride: float, n: int) -> tuple[int, int]:
    """Cells [first, last) that overlap the pixel interval [lo_px, hi_px)."""
    first = max(0, math.floor(lo_px / stride))
    last = min(n, max(first + 1, math.ceil(hi_px / stride)))
    return first, last


def box_cells(box_xyxy: F64Array, density: DensityMap, margin_px: float = 0.0) -> tuple[slice, slice]:
    """(rows, cols) slices of the density cells that overlap a box (x0, y0, x1, y1 frame pixels) grown by
    ``margin_px`` on every side."""
    x0, y0, x1, y1 = (float(v) for v in box_xyxy)
    rows, cols = density.values.shape
    r0, r1 = _cell_range(y0 - margin_px, y1 + margin_px, density.stride_y, rows)
    c0, c1 = _cell_range(x0 - margin_px, x1 + margin_px, density.stride_x, cols)
    return slice(r0, r1), slice(c0, c1)


@dataclass(frozen=True)
class RealFrameScore:
    """Scores of one real frame at one scale (module docstring)."""

    image: str
    scale: float
    altitude_m: float | None
    boxes: int
    found_boxes: int
    free_cells: int
    false_occupied_cells: int
    predicted_count: float

    @property
    def false_occupied_fraction(self) -> float:
        return self.false_occupied_cells / self.free_cells if self.free_cells else math.nan

    @property
    def count_ratio(self) -> float:
        return self.predicted_count / self.boxes if self.boxes else math.nan


def score_real_frame(
    image: str,
    scale: float,
    altitude_m: float | None,
    density: DensityMap,
    occupied: BoolGrid,
    boxes_xyxy: F64Array,
) -> RealFrameScore:
    """Score one frame: ``occupied`` (cells, shape of ``density.values``), boxes (N, 4) in the frame's pixels."""
    near_person = np.zeros_like(occupied)
    found = 0
    for box in boxes_xyxy:
        found += bool(occupied[box_cells(box, density)].any())
        margin_px = PERSON_MARGIN_FRACTION * max(box[2] - box[0], box[3] - box[1])
        near_person[box_cells(box, density, margin_px)] = True
    free = ~near_person
    return RealFrameScore(
        image=image,
        scale=scale,
        altitude_m=altitude_m,
        boxes=len(boxes_xyxy),
        found_boxes=found,
        free_cells=int(free.sum()),
        false_occupied_cells=int((free & occupied).sum()),
        predicted_count=float(np.nansum(density.values)),
    )


@dataclass(frozen=True)
class RealSummary:
    """One (model, set, scale, altitude band) line."""

    model: str
    dataset: str
    scale: float
    band: str
    frames: int
    boxes: int
    recall: float
    median_false_occupied: float
    empty_frames: int
    median_false_occupied_empty: float
    median_count_ratio: float

    @property
    def meets_targets(self) -> bool:
        """All targets of the module docstring that apply (a metric with no frames does not count)."""
        lo, hi = TARGET_COUNT_RATIO
        checks = [
            math.isnan(self.recall) or self.recall >= TARGET_RECALL,
            math.isnan(self.median_false_occupied) or self.median_false_occupied <= TARGET_FALSE_OCCUPIED,
            math.isnan(self.median_false_occupied_empty)
            or self.median_false_occupied_empty <= TARGET_FALSE_OCCUPIED_EMPTY,
            math.isnan(self.median_count_ratio) or lo <= self.median_count_ratio <= hi,
        ]
        return all(checks)


def band_name(altitude_m: float | None) -> str:
    """The altitude band of a frame, ``"2-8"`` etc., or ``"unknown"``."""
    if altitude_m is None:
        return "unknown"
    for lo, hi in REAL_ALTITUDE_BANDS_M:
        if lo <= altitude_m < hi:
            return f"{lo:g}-{hi:g}"
    return "other"


def _median(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.median(finite)) if finite else math.nan


def summarise_real(model: str, dataset: str, scale: float, band: str, scores: list[RealFrameScore]) -> RealSummary:
    """Pooled recall, medians of false-occupied fraction and count ratio (module docstring)."""
    boxes = sum(s.boxes for s in scores)
    empty = [s for s in scores if s.boxes == 0]
    return RealSummary(
        model=model,
        dataset=dataset,
        scale=scale,
        band=band,
        frames=len(scores),
        boxes=boxes,
        recall=sum(s.found_boxes for s in scores) / boxes if boxes else math.nan,
        median_false_occupied=_median([s.false_occupied_fraction for s in scores]),
        empty_frames=len(empty),
        median_false_occupied_empty=_median([s.false_occupied_fraction for s in empty]),
        median_count_ratio=_median([s.count_ratio for s in scores if s.boxes]),
    )


def resize_frame(image_bgr: U8Image, boxes_xyxy: F64Array, scale: float) -> tuple[U8Image, F64Array]:
    """The frame and its boxes at ``scale`` (area interpolation when shrinking)."""
    if scale == 1.0:
        return image_bgr, boxes_xyxy
    h, w = image_bgr.shape[:2]
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    interpolation = cv2.INTER_AREA if scale < 1.0 else cv2.INTER_LINEAR
    resized = np.asarray(cv2.resize(image_bgr, size, interpolation=interpolation), np.uint8)
    factor = np.array([size[0] / w, size[1] / h, size[0] / w, size[1] / h])
    return resized, boxes_xyxy * factor


def overlay(image_bgr: U8Image, density: DensityMap, occupied: BoolGrid, score_boxes: F64Array) -> U8Image:
    """The frame darkened, occupied cells in red, boxes green when found and magenta when missed."""
    h, w = image_bgr.shape[:2]
    cells = cv2.resize(
        occupied.astype(np.uint8), (density.frame_width_px, density.frame_height_px), interpolation=cv2.INTER_NEAREST
    )[:h, :w].astype(bool)
    out = (image_bgr.astype(np.float32) * 0.65).astype(np.uint8)
    out[cells] = (0.5 * out[cells] + np.array([0, 0, 127], np.float32)).astype(np.uint8)
    for box in score_boxes:
        colour = (0, 255, 0) if occupied[box_cells(box, density)].any() else (255, 0, 255)
        cv2.rectangle(out, (int(box[0]), int(box[1])), (math.ceil(box[2]), math.ceil(box[3])), colour, 2)
    return out


def evaluate_set(
    name: str,
    model: OnnxDensityModel,
    frames: list[BoxedImage],
    occupancy: OccupancyConfig,
    dataset: str,
    scales: tuple[float, ...] = SCALES,
    overlays_dir: Path | None = None,
) -> list[RealFrameScore]:
    """Score every frame of one real set at every scale; writes overlays (native scale) when asked."""
    scores: list[RealFrameScore] = []
    for frame in frames:
        original = read_bgr(frame.image_path)
        for scale in scales:
            image, boxes = resize_frame(original, frame.boxes_xyxy, scale)
            density = tiled_density(model, image)
            occupied = occupied_cells(density, occupancy)
            scores.append(score_real_frame(frame.image_path.name, scale, frame.altitude_m, density, occupied, boxes))
            if overlays_dir is not None and scale == scales[0]:
                overlays_dir.mkdir(parents=True, exist_ok=True)
                picture = overlay(image, density, occupied, boxes)
                longest = max(picture.shape[:2])
                if longest > 1280:
                    f = 1280 / longest
                    picture = np.asarray(cv2.resize(picture, None, fx=f, fy=f, interpolation=cv2.INTER_AREA), np.uint8)
                path = overlays_dir / f"{name}__{dataset}__{frame.image_path.stem}.jpg"
                cv2.imwrite(str(path), picture, [cv2.IMWRITE_JPEG_QUALITY, 85])
    return scores


def summaries_for(model: str, dataset: str, scores: list[RealFrameScore]) -> list[RealSummary]:
    """Per scale: every altitude band that has frames, then all frames of the scale."""
    out = []
    for scale in sorted({s.scale for s in scores}, reverse=True):
        at_scale = [s for s in scores if s.scale == scale]
        bands = sorted({band_name(s.altitude_m) for s in at_scale})
        if bands != ["unknown"]:
            for band in bands:
                out.append(
                    summarise_real(
                        model, dataset, scale, band, [s for s in at_scale if band_name(s.altitude_m) == band]
                    )
                )
        out.append(summarise_real(model, dataset, scale, "all", at_scale))
    return out


def _fmt(value: float, pattern: str) -> str:
    return "n/a" if math.isnan(value) else format(value, pattern)


def summary_table(summaries: list[RealSummary]) -> str:
    """Markdown, one line per summary, grouped so that models sit beside each other on the same frames."""
    head = (
        "| set | scale | altitude (m) | model | frames | boxes | person recall | median false-occupied "
        "| median false-occupied, nobody (frames) | median count ratio | targets |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    ordered = sorted(summaries, key=lambda s: (s.dataset, -s.scale, s.band == "all", s.band))
    lines = [
        f"| {s.dataset} | {s.scale:g} | {s.band} | {s.model} | {s.frames} | {s.boxes} | {_fmt(s.recall, '.3f')} "
        f"| {_fmt(100 * s.median_false_occupied, '.1f')} % "
        f"| {_fmt(100 * s.median_false_occupied_empty, '.1f')}{' %' if s.empty_frames else ''} ({s.empty_frames}) "
        f"| {_fmt(s.median_count_ratio, '.1f')} | {'met' if s.meets_targets else 'missed'} |"
        for s in ordered
    ]
    return head + "\n".join(lines) + "\n"


def default_sets(root: Path) -> dict[str, list[BoxedImage]]:
    """Every folder under ``root`` that :func:`load_real_set` recognises, loaded, by folder name (sorted)."""
    if not root.is_dir():
        return {}
    found = {}
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        try:
            found[folder.name] = load_real_set(folder)
        except DatasetError:
            continue
    return found


def training_sites(model_path: Path) -> frozenset[str]:
    """The real-ground sites a model trained on, from its ``slz.training`` metadata: ``real_ground_sites`` (names) or
    ``real_ground`` (one site's folder); none for a model that trained on rendered frames only."""
    training = json.loads(read_metadata(model_path).get(TRAINING_KEY, "{}"))
    sites = set(training.get("real_ground_sites") or [])
    if training.get("real_ground"):
        sites.add(Path(str(training["real_ground"])).name)
    return frozenset(str(site) for site in sites)


def ground_sets(trained_on: frozenset[str], root: Path = GROUND_ROOT) -> dict[str, list[BoxedImage]]:
    """The real ground of every derived site under ``root`` (``sitl/world/ground/<site>``), as a model that trained on
    ``trained_on`` may be scored on it: every frame of a site it never saw (``"garfield (site held out)"``: transfer),
    the held-out frames of a site it trained on (``"caliterra (trained-on site)"``: memory of that site, never
    quoted as a real-ground figure)."""
    out: dict[str, list[BoxedImage]] = {}
    for folder in sorted(p for p in root.iterdir() if (p / "index.json").is_file()):
        if folder.name in trained_on:
            out[f"{folder.name} (trained-on site)"] = load_real_ground(folder, "heldout")
        else:
            out[f"{folder.name} (site held out)"] = load_real_ground(folder, None)
    return out


def add_real_set_arguments(parser: argparse.ArgumentParser, out: Path, data_help: str) -> None:
    """The arguments of every command that scores models on the real sets (this one, ``models.eval.tradeoff``): the
    models, the sets, the perception config, the scales and the report's path (default ``out``)."""
    parser.add_argument("--model", action="append", required=True, help="NAME=PATH.onnx (repeatable)")
    parser.add_argument("--data", type=Path, action="append", help=data_help)
    parser.add_argument("--datasets", type=Path, default=Path("../shared/datasets"), help="used without --data")
    parser.add_argument("--config", type=Path, default=Path("mission_configs/perception.yaml"))
    parser.add_argument("--scales", type=float, nargs="+", default=list(SCALES))
    parser.add_argument("--out", type=Path, default=out)


def named_models(parser: argparse.ArgumentParser, specs: list[str]) -> list[tuple[str, str]]:
    """(name, path) of each ``--model NAME=PATH``; a spec without ``=PATH`` is the parser's error (exit 2)."""
    named = []
    for spec in specs:
        name, _, path = spec.partition("=")
        if not path:
            parser.error(f"--model wants NAME=PATH, got {spec!r}")
        named.append((name, path))
    return named


def write_report(out: Path, payload: dict[str, object], table: str) -> None:
    """``OUT.json`` (NaN as null) and ``OUT.md`` beside each other (``OUT`` may end in ``.json``/``.md``, and keeps any
    other dot: ``real_0.5``), and the table on standard output."""
    base = out.with_suffix("") if out.suffix in (".json", ".md") else out
    base.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(payload, indent=2, allow_nan=True).replace("NaN", "null")
    (base.parent / f"{base.name}.json").write_text(text + "\n", encoding="utf-8")
    (base.parent / f"{base.name}.md").write_text(table, encoding="utf-8")
    sys.stdout.write(table)


def main() -> int:
    parser = argparse.ArgumentParser(description="Density models on real aerial frames with annotated people.")
    add_real_set_arguments(parser, Path("models/eval/results/real"), "a real set's folder (repeatable)")
    parser.add_argument("--overlays", type=Path, default=Path("runs/eval/real"))
    parser.add_argument("--no-real-ground", action="store_true", help="without --data: no real ground")
    args = parser.parse_args()
    models = named_models(parser, args.model)
    try:
        loaded = {folder.name: load_real_set(folder) for folder in args.data or []}
        given = bool(loaded)
        if not given:  # every set under --datasets; each model adds the real ground of the sites (ground_sets)
            loaded = default_sets(args.datasets)
        trained_on = {name: training_sites(Path(path)) for name, path in models}
        grounds = {name: {} if given or args.no_real_ground else ground_sets(trained_on[name]) for name, _ in models}
    except DatasetError as exc:
        sys.stderr.write(f"error: {exc}\n")
        return 2
    if not loaded and not any(grounds.values()):
        sys.stderr.write(f"error: no real set found (give --data, or put sets under {args.datasets})\n")
        return 2
    occupancy = load_perception_config(args.config).occupancy
    summaries: list[RealSummary] = []
    payload: dict[str, object] = {
        "config": str(args.config),
        "occupancy": occupancy.model_dump(),
        "targets": {
            "recall": TARGET_RECALL,
            "median_false_occupied": TARGET_FALSE_OCCUPIED,
            "median_false_occupied_empty": TARGET_FALSE_OCCUPIED_EMPTY,
            "median_count_ratio": TARGET_COUNT_RATIO,
        },
        "models": {},
    }
    for name, path in models:
        model = OnnxDensityModel(path)
        per_set: dict[str, object] = {}
        for dataset, frames in (loaded | grounds[name]).items():
            start = time.monotonic()
            scores = evaluate_set(name, model, frames, occupancy, dataset, tuple(args.scales), args.overlays)
            found = summaries_for(name, dataset, scores)
            summaries += found
            per_set[dataset] = {
                "summaries": [asdict(s) | {"meets_targets": s.meets_targets} for s in found],
                "frames": [
                    asdict(s) | {"false_occupied_fraction": s.false_occupied_fraction, "count_ratio": s.count_ratio}
                    for s in scores
                ],
            }
            sys.stderr.write(f"{name} on {dataset}: {len(frames)} frames in {time.monotonic() - start:.1f} s\n")
        scored = payload["models"]
        assert isinstance(scored, dict)
        scored[name] = {"path": path, "trained_on_sites": sorted(trained_on[name]), "sets": per_set}
    write_report(args.out, payload, summary_table(summaries))
    return 0


if __name__ == "__main__":
    sys.exit(main())
