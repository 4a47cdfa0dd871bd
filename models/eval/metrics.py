"""Evaluation metrics of a density model on labelled frames (no PyTorch: it runs the shipped ONNX files).

Per frame:

- **count**: predicted count (sum of the density map) against the visible heads.
- **localization**: heads detected as local maxima of the density mass in 3x3 cells holding at least half a
  person, at the mass centroid; matched one-to-one (Hungarian, on pixel distance) with the labelled heads; a match
  within 4 px or 8 px is a true positive.
- **occupancy** (what landing depends on): the density map goes through the companion's own
  :class:`~companion.perception.occupancy.OccupancyMapper` (threshold and dilation in metres at the frame's finest
  ground sampling distance). *Miss rate*: person pixels (ground-truth mask) that the occupancy map calls free.
  *False-occupied fraction*: occupied share of person-free ground, i.e. pixels farther from every person than the
  dilation margin plus two density cells.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from companion.geometry import PinholeCamera, Pose
from companion.perception.config import OccupancyConfig, ProjectionConfig
from companion.perception.density import DensityMap
from companion.perception.errors import PerceptionError
from companion.perception.occupancy import OccupancyMapper
from companion.perception.projection import OCCUPIED, HeadPlaneProjector

F32Array = npt.NDArray[np.float32]
ALTITUDE_BANDS_M: tuple[tuple[float, float], ...] = ((2.0, 8.0), (8.0, 12.0), (12.0, 16.0), (16.0, 28.0), (28.0, 40.0))
MATCH_RADII_PX = (4.0, 8.0)


def detect_heads(density: DensityMap, min_mass: float = 0.5) -> F32Array:
    """Head positions, shape (K, 2) of (u, v) frame pixels, from a density map (see the module docstring).

    Local maxima of the 3x3 mass at or above ``min_mass`` people, strongest first, one per 3x3 neighbourhood.
    """
    d = np.nan_to_num(density.values.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    mass = cv2.boxFilter(d, -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
    peaks = (mass >= min_mass) & (mass >= cv2.dilate(mass, np.ones((3, 3), np.uint8)))
    rows, cols = np.nonzero(peaks)
    order = np.argsort(-mass[rows, cols], kind="stable")
    kept: list[tuple[int, int]] = []
    for r, c in zip(rows[order], cols[order], strict=True):  # plateaus: one peak per 3x3 neighbourhood
        if all(max(abs(int(r) - kr), abs(int(c) - kc)) > 1 for kr, kc in kept):
            kept.append((int(r), int(c)))
    out = np.zeros((len(kept), 2), np.float32)
    h, w = d.shape
    for k, (r, c) in enumerate(kept):
        r0, r1, c0, c1 = max(0, r - 1), min(h, r + 2), max(0, c - 1), min(w, c + 2)
        window = d[r0:r1, c0:c1]
        total = float(window.sum())
        rr, cc = np.mgrid[r0:r1, c0:c1]
        out[k] = (
            (float((window * cc).sum()) / total + 0.5) * density.stride_x,
            (float((window * rr).sum()) / total + 0.5) * density.stride_y,
        )
    return out


def match_count(predicted: F32Array, truth: F32Array, radius_px: float) -> int:
    """True positives of a one-to-one matching (Hungarian on distance) with pairs no farther than ``radius_px``."""
    if len(predicted) == 0 or len(truth) == 0:
        return 0
    dist = np.hypot(predicted[:, None, 0] - truth[None, :, 0], predicted[:, None, 1] - truth[None, :, 1])
    cost = np.where(dist <= radius_px, dist, 1e6)
    rows, cols = linear_sum_assignment(cost)
    return int((dist[rows, cols] <= radius_px).sum())


@dataclass
class FrameScore:
    """Scores of one frame."""

    stem: str
    altitude_m: float
    true_count: int
    predicted_count: float
    predicted_heads: int
    matched: dict[str, int]
    person_px: int
    missed_person_px: int
    free_ground_px: int
    false_occupied_px: int


def frame_gsd_m_per_px(label: dict[str, object]) -> float:
    """The finest ground sampling distance on the head plane (m per pixel) of a generated frame (its JSON label).

    Below about 2.2 m the head plane is closer to the camera than ``min_depth_m``: then the ground plane's.
    """
    cam = label["camera"]
    assert isinstance(cam, dict)
    camera = PinholeCamera(
        int(cam["width_px"]), int(cam["height_px"]), cam["fx_px"], cam["fy_px"], cam["cx_px"], cam["cy_px"]
    )
    pose = Pose(np.asarray(label["T_world_body"], np.float64))
    T_body_camera = np.asarray(label["T_body_camera"], np.float64)
    try:
        return HeadPlaneProjector(camera, T_body_camera, ProjectionConfig()).finest_gsd_m_per_px(pose)
    except PerceptionError:
        ground = ProjectionConfig(head_height_m=0.0)
        return HeadPlaneProjector(camera, T_body_camera, ground).finest_gsd_m_per_px(pose)


def score_frame(
    stem: str,
    density: DensityMap,
    heads_px: F32Array,
    person_mask: npt.NDArray[np.bool_],
    label: dict[str, object],
    occupancy: OccupancyConfig,
) -> FrameScore:
    """Score one frame (``label`` is the generator's JSON: camera, poses, altitude)."""
    gsd = frame_gsd_m_per_px(label)
    occ = OccupancyMapper(occupancy).compute(density, gsd)
    h, w = person_mask.shape
    occupied = cv2.resize(occ.values, (w, h), interpolation=cv2.INTER_NEAREST) == OCCUPIED
    margin_px = occ.dilation_px * max(density.stride_x, density.stride_y) + 2 * max(density.stride_x, density.stride_y)
    if person_mask.any():
        dist = cv2.distanceTransform((~person_mask).astype(np.uint8), cv2.DIST_L2, 5)
        ground = dist > margin_px
    else:
        ground = np.ones_like(person_mask)
    predicted = detect_heads(density)
    return FrameScore(
        stem=stem,
        altitude_m=float(label["altitude_m"]),  # type: ignore[arg-type]
        true_count=len(heads_px),
        predicted_count=float(np.nansum(density.values)),
        predicted_heads=len(predicted),
        matched={f"{r:g}px": match_count(predicted, heads_px, r) for r in MATCH_RADII_PX},
        person_px=int(person_mask.sum()),
        missed_person_px=int((person_mask & ~occupied).sum()),
        free_ground_px=int(ground.sum()),
        false_occupied_px=int((ground & occupied).sum()),
    )


@dataclass
class BandSummary:
    """Aggregates over the frames of one altitude band (pixel rates pooled over frames)."""

    band_m: tuple[float, float]
    frames: int
    mean_true_count: float
    count_mae: float
    count_rmse: float
    count_bias: float
    precision: dict[str, float] = field(default_factory=dict)
    recall: dict[str, float] = field(default_factory=dict)
    occupancy_miss_rate: float = math.nan
    false_occupied_fraction: float = math.nan


def summarise(scores: list[FrameScore], band_m: tuple[float, float]) -> BandSummary:
    """Summary of the frames whose altitude lies in ``[band_m[0], band_m[1])`` (the top band includes its end)."""
    lo, hi = band_m
    chosen = [s for s in scores if lo <= s.altitude_m < hi or (hi == ALTITUDE_BANDS_M[-1][1] and s.altitude_m == hi)]
    if not chosen:
        return BandSummary(band_m, 0, math.nan, math.nan, math.nan, math.nan)
    err = np.array([s.predicted_count - s.true_count for s in chosen])
    predicted = sum(s.predicted_heads for s in chosen)
    truth = sum(s.true_count for s in chosen)
    summary = BandSummary(
        band_m=band_m,
        frames=len(chosen),
        mean_true_count=float(np.mean([s.true_count for s in chosen])),
        count_mae=float(np.abs(err).mean()),
        count_rmse=float(np.sqrt((err**2).mean())),
        count_bias=float(err.mean()),
    )
    for key in chosen[0].matched:
        tp = sum(s.matched[key] for s in chosen)
        summary.precision[key] = tp / predicted if predicted else math.nan
        summary.recall[key] = tp / truth if truth else math.nan
    person = sum(s.person_px for s in chosen)
    ground = sum(s.free_ground_px for s in chosen)
    summary.occupancy_miss_rate = sum(s.missed_person_px for s in chosen) / person if person else math.nan
    summary.false_occupied_fraction = sum(s.false_occupied_px for s in chosen) / ground if ground else math.nan
    return summary


def summaries_table(rows: list[tuple[str, BandSummary]]) -> str:
    """A Markdown table, one line per (model, band)."""
    head = (
        "| model | altitude (m) | frames | heads/frame | count MAE | count RMSE | bias | P@4px | R@4px | P@8px "
        "| R@8px | occupancy miss rate | false-occupied ground |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for name, s in rows:
        lines.append(
            f"| {name} | {s.band_m[0]:g}-{s.band_m[1]:g} | {s.frames} | {s.mean_true_count:.1f} | {s.count_mae:.2f} "
            f"| {s.count_rmse:.2f} | {s.count_bias:+.2f} | {s.precision.get('4px', math.nan):.3f} "
            f"| {s.recall.get('4px', math.nan):.3f} | {s.precision.get('8px', math.nan):.3f} "
            f"| {s.recall.get('8px', math.nan):.3f} | {100 * s.occupancy_miss_rate:.2f} % "
            f"| {100 * s.false_occupied_fraction:.2f} % |"
        )
    return head + "\n".join(lines) + "\n"


def write_json(path: Path, payload: dict[str, object]) -> None:
    """Write results as indented JSON (dataclasses converted)."""

    def convert(obj: object) -> object:
        if isinstance(obj, (FrameScore, BandSummary)):
            return asdict(obj)
        raise TypeError(f"cannot serialise {type(obj).__name__}")

    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(payload, indent=2, default=convert) + "\n", encoding="utf-8")
