"""Real ground for the SITL and for training: real nadir frames of four sites, derived into this package.

``ground/caliterra/`` (CC0: a construction site in Texas, nobody in the frames; ``models/data/real_ground.py`` derives
it and explains the GSD estimate), ``ground/garfield/`` (CC0: a park in Ohio), ``ground/boruszyn/`` (CC BY 3.0: a
village in Poland) and ``ground/neon/`` (CC0: NEON's forest and savanna orthophotos, for training only; the SITL paints
no park from it; ``models/data/real_sites.py`` derives the last three), each resampled to
:data:`STORED_GSD_M_PER_PX` with ``index.json`` (source, licence, GSD, split of each frame) and ``SOURCES.md``.

**Split**: frames whose number ends in 4 or 9 (every fifth by name) are held out from training within a site. The
SITL paints its real ground (:func:`real_ground_texture`) from frames no shipped model trained on
(:func:`painted_frames`): Caliterra's held-out frames, every frame of the other two sites; so a mission over real ground
never flies over ground a shipped density model was trained on.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

U8Image = npt.NDArray[np.uint8]

GROUND_ROOT = Path(__file__).resolve().parent / "ground"
GROUND_DIR = GROUND_ROOT / "caliterra"
STORED_GSD_M_PER_PX = 0.045
TRAIN = "train"
HELDOUT = "heldout"


def split_of(name: str) -> str:
    """``heldout`` for frames whose number ends in 4 or 9 (every fifth by name), else ``train``."""
    digits = "".join(ch for ch in name if ch.isdigit())
    if not digits:
        raise ValueError(f"frame name without a number: {name!r}")
    return HELDOUT if int(digits) % 5 == 4 else TRAIN


@dataclass(frozen=True)
class RealGround:
    """One real frame in memory: (H, W, 3) uint8 BGR at ``gsd_m_per_px`` metres per pixel, nobody in it."""

    name: str
    image_bgr: U8Image
    gsd_m_per_px: float


def read_index(root: Path = GROUND_DIR) -> dict[str, object]:
    """``index.json`` of a derived real-ground folder."""
    path = root / "index.json"
    data = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise ValueError(f"{path}: expected an object with a 'frames' list")
    return data


def frame_names(split: str, root: Path = GROUND_DIR) -> list[str]:
    """Names of the frames of ``split`` (``train`` or ``heldout``), sorted."""
    frames = read_index(root)["frames"]
    assert isinstance(frames, list)
    return sorted(str(f["name"]) for f in frames if f["split"] == split)


def _read(path: Path) -> U8Image:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise FileNotFoundError(f"real-ground frame missing or unreadable: {path}")
    return np.asarray(image, np.uint8)


def load_ground(split: str, root: Path = GROUND_DIR) -> list[RealGround]:
    """The frames of ``split`` in memory, at the stored GSD."""
    gsd = float(read_index(root)["gsd_m_per_px"])  # type: ignore[arg-type]
    return [RealGround(name, _read(root / f"{name}.jpg"), gsd) for name in frame_names(split, root)]


def painted_frames(site: str) -> list[str]:
    """The frames of ``site`` the SITL paints its real ground from: frames no shipped model trained on. Caliterra's
    held-out split (``slz_lite_wide_real`` trained on the rest); every frame of the other sites."""
    root = GROUND_ROOT / site
    if site == GROUND_DIR.name:
        return frame_names(HELDOUT, root)
    frames = read_index(root)["frames"]
    assert isinstance(frames, list)
    return sorted(str(f["name"]) for f in frames)


def real_ground_texture(
    rng: np.random.Generator, size_px: int, texture_res_m: float, site: str = GROUND_DIR.name
) -> U8Image:
    """A (size_px, size_px, 3) ground texture at ``texture_res_m`` metres per pixel from the real frames of ``site``
    (:func:`painted_frames`): a 2 x 2 mosaic of random crops of four of them, each turned by a random quarter and
    mirrored half the time, blended over a short seam."""
    frames = painted_frames(site)  # sorted
    root = GROUND_ROOT / site
    chosen = rng.choice(len(frames), size=4, replace=False)
    half = size_px // 2
    seam = max(2, round(1.0 / texture_res_m))  # a metre of blending
    piece = half + seam
    factor = STORED_GSD_M_PER_PX / texture_res_m
    canvas = np.zeros((size_px + seam, size_px + seam, 3), np.float32)
    weight = np.zeros((size_px + seam, size_px + seam, 1), np.float32)
    ramp = np.minimum(1.0, (np.arange(piece, dtype=np.float32) + 1.0) / seam)
    taper = np.minimum(ramp, ramp[::-1])
    window = (taper[:, None] * taper[None, :])[:, :, None]
    for k, index in enumerate(chosen):
        image = _read(root / f"{frames[int(index)]}.jpg")
        scaled = cv2.resize(
            image, None, fx=factor, fy=factor, interpolation=cv2.INTER_AREA if factor < 1 else cv2.INTER_LINEAR
        )
        h, w = scaled.shape[:2]
        side = min(piece, h, w)
        y0, x0 = int(rng.integers(0, h - side + 1)), int(rng.integers(0, w - side + 1))
        crop = np.rot90(scaled[y0 : y0 + side, x0 : x0 + side], int(rng.integers(4)))
        if rng.random() < 0.5:
            crop = crop[:, ::-1]
        if side < piece:
            crop = cv2.resize(np.ascontiguousarray(crop), (piece, piece), interpolation=cv2.INTER_LINEAR)
        r, c = divmod(k, 2)
        y, x = r * half, c * half
        canvas[y : y + piece, x : x + piece] += crop.astype(np.float32) * window
        weight[y : y + piece, x : x + piece] += window
    texture = canvas / np.maximum(weight, 1e-6)
    offset = seam // 2
    out: U8Image = np.clip(texture[offset : offset + size_px, offset : offset + size_px] + 0.5, 0, 255).astype(np.uint8)
    return out
