"""Real ground for training and evaluation: the CC0 Caliterra drone frames, derived into the repository.

Source: ``OpenDroneMap/odm_data_caliterra`` on GitHub (CC0 1.0, ``license.html`` there): 77 nadir photographs of a
construction site in Dripping Springs, Texas (dirt, gravel roads, grass, tree crowns, concrete pipes, machinery),
4000x3000 px, Canon PowerShot SX260 HS at 4.5 mm. Nobody is in them, except perhaps one blob in ``IMG_9417`` that may
be a worker: that frame is left out. Two frames of the repository (``IMG_9421``, ``IMG_9422``) were not available
here; 74 frames are used.

Ground sampling distance of the source: 0.015 m per pixel, estimated here (the camera's GPS altitude drifts by
100 m over the flight while the scale of the pictures does not): the image displacement between consecutive
frames (ORB features, a RANSAC similarity) against their GPS displacement gives a median of 0.0156 m/px over 68
pairs (interquartile 0.013-0.022, consumer GPS noise), and the 8-ft (2.44 m) concrete pipe sections span about 180
px (0.0136 m/px).

Derived files (``sitl/world/ground/caliterra/``, written by :func:`prepare`; the SITL paints real ground from them,
``sitl/world/ground.py``): every used frame resampled to
:data:`STORED_GSD_M_PER_PX` (0.045 m/px, the companion's working GSD, ``perception.model.min_gsd_m_per_px``;
1333x1000 px), JPEG quality 85, and ``index.json`` (source, licence, GSD, split of each frame). About 12 MB.

**Split**: frames whose number ends in 4 or 9 (every fifth by name: ``IMG_9354``, ``IMG_9359``, ...) are held out:
never trained on, scored by ``make eval-real`` at 0.045 and 0.09 m/px. Of the rest, frames whose number ends in 2 are
validation (:func:`is_validation`): never trained on either, they choose checkpoints and the occupancy threshold.
Consecutive frames overlap by about 80 %, so the held-out frames show ground the training frames also show (from
another position, in other light): they test the site's kinds of ground, not an unseen site. SDD (another site,
people annotated) is the independent real check.

Use: :func:`load_ground` (frames of a split in memory), :func:`ground_crop` (a random square crop at a requested
GSD), :func:`composite` (synthetic people, their masks and shadows, pasted onto a real crop).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from models.data.images import read_bgr
from sitl.world.ground import (
    GROUND_DIR,
    HELDOUT,
    STORED_GSD_M_PER_PX,
    TRAIN,
    RealGround,
    frame_names,
    load_ground,
    read_index,
    split_of,
)

__all__ = [
    "GROUND_DIR",
    "HELDOUT",
    "STORED_GSD_M_PER_PX",
    "TRAIN",
    "RealGround",
    "composite",
    "frame_names",
    "ground_crop",
    "load_ground",
    "prepare",
    "read_index",
    "split_of",
    "split_validation",
]

U8Image = npt.NDArray[np.uint8]
BoolMask = npt.NDArray[np.bool_]

SOURCE = "https://github.com/OpenDroneMap/odm_data_caliterra (images/), Dennis Baldwin"
LICENCE = "CC0 1.0 Universal"
SOURCE_GSD_M_PER_PX = 0.015
EXCLUDED = {"IMG_9417": "one blob that may be a worker"}
JPEG_QUALITY = 85


def prepare(source_dir: Path, out_dir: Path = GROUND_DIR) -> dict[str, object]:
    """Write the derived frames and ``index.json`` from the source repository's ``images/`` folder.

    Returns the index. Frames of :data:`EXCLUDED` are listed with their reason and not written.
    """
    sources = sorted(source_dir.glob("IMG_*.jpg"))
    if not sources:
        raise FileNotFoundError(f"no IMG_*.jpg in {source_dir} (the images/ folder of {SOURCE})")
    out_dir.mkdir(parents=True, exist_ok=True)
    factor = SOURCE_GSD_M_PER_PX / STORED_GSD_M_PER_PX
    frames = []
    for path in sources:
        name = path.stem
        if name in EXCLUDED:
            continue
        image = read_bgr(path)
        h, w = image.shape[:2]
        size = (round(w * factor), round(h * factor))
        small = np.asarray(cv2.resize(image, size, interpolation=cv2.INTER_AREA), np.uint8)
        cv2.imwrite(str(out_dir / f"{name}.jpg"), small, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        frames.append({"name": name, "split": split_of(name), "width_px": size[0], "height_px": size[1]})
    index: dict[str, object] = {
        "source": SOURCE,
        "licence": LICENCE,
        "source_gsd_m_per_px": SOURCE_GSD_M_PER_PX,
        "gsd_m_per_px": STORED_GSD_M_PER_PX,
        "excluded": EXCLUDED,
        "frames": frames,
    }
    (out_dir / "index.json").write_text(json.dumps(index, indent=1) + "\n", encoding="utf-8")
    return index


def is_validation(name: str) -> bool:
    """Real validation frames: training-split frames whose number ends in 2 (every tenth by name). Never trained on;
    watched during training and used to choose the occupancy threshold (``models/eval/threshold.py``)."""
    return split_of(name) == TRAIN and name.endswith("2")


def split_validation(frames: list[RealGround]) -> tuple[list[RealGround], list[RealGround]]:
    """(training, validation) frames of a list of training-split frames (:func:`is_validation`)."""
    return [f for f in frames if not is_validation(f.name)], [f for f in frames if is_validation(f.name)]


def ground_crop(ground: RealGround, rng: np.random.Generator, size_px: int, gsd_m_per_px: float) -> U8Image:
    """A random (size_px, size_px, 3) crop of ``ground`` at ``gsd_m_per_px``, turned by a random quarter and mirrored
    half the time. A GSD finer than the stored one is an upsampled (softer) crop."""
    factor = ground.gsd_m_per_px / gsd_m_per_px  # output px per stored px
    side = min(math.ceil(size_px / factor), *ground.image_bgr.shape[:2])
    h, w = ground.image_bgr.shape[:2]
    y0, x0 = int(rng.integers(0, h - side + 1)), int(rng.integers(0, w - side + 1))
    patch = ground.image_bgr[y0 : y0 + side, x0 : x0 + side]
    interpolation = cv2.INTER_AREA if factor < 1 else cv2.INTER_LINEAR
    crop = np.asarray(cv2.resize(patch, (size_px, size_px), interpolation=interpolation), np.uint8)
    crop = np.rot90(crop, int(rng.integers(4)))
    if rng.random() < 0.5:
        crop = crop[:, ::-1]
    out: U8Image = np.ascontiguousarray(crop, np.uint8)
    return out


def composite(
    people_bgr: U8Image,
    person_mask: BoolMask,
    background_bgr: U8Image,
    rng: np.random.Generator,
    gsd_m_per_px: float,
    real_detail: bool = False,
) -> U8Image:
    """Synthetic people (the pixels of ``person_mask`` in ``people_bgr``) pasted onto a real ``background_bgr`` of the
    same size and GSD, with what makes them belong there: a soft edge, a shadow cast on the real ground (one sun per
    crop: 0-1.2 m long, darkening 15-45 %), the people's brightness pulled halfway to the ground's, half the time
    duller and darker people (grey clothes, shade), and a blur of up to 0.8 px. Noise, colour and JPEG come later,
    on the whole crop (``models.density.dataset``).

    With ``real_detail`` the people also carry the real photograph's fine texture: the high-pass part (detail finer
    than about 1.5 px) of the same real crop at another place, 40-100 % of it, added to their pixels. Rendered people
    are smooth where real ones (and the real ground) carry the camera's grain and the fabric's folds; without it a
    network can learn "photographic texture is nobody", which real people on real ground also have."""
    if people_bgr.shape != background_bgr.shape or people_bgr.shape[:2] != person_mask.shape:
        raise ValueError(f"shapes differ: {people_bgr.shape}, {background_bgr.shape}, {person_mask.shape}")
    if not person_mask.any():
        return np.array(background_bgr, np.uint8)
    out = background_bgr.astype(np.float32)
    mask = person_mask.astype(np.float32)
    # Shadow: the mask shifted away from the sun, softened (the people are pasted over it).
    length_px = float(rng.uniform(0.0, 1.2)) / gsd_m_per_px
    angle = float(rng.uniform(0.0, 2.0 * math.pi))
    dx, dy = length_px * math.cos(angle), length_px * math.sin(angle)
    h, w = mask.shape
    shadow = np.zeros_like(mask)
    for step in (0.33, 0.66, 1.0):  # the shadow joins the feet
        shift = np.array([[1.0, 0.0, dx * step], [0.0, 1.0, dy * step]], np.float32)
        moved = cv2.warpAffine(mask, shift, (w, h), flags=cv2.INTER_LINEAR, borderValue=0.0)
        shadow = np.maximum(shadow, np.asarray(moved, np.float32))
    shadow = np.asarray(cv2.GaussianBlur(shadow, (0, 0), max(0.5, 0.15 / gsd_m_per_px)), np.float32)
    darkening = float(rng.uniform(0.15, 0.45))
    out *= (1.0 - darkening * np.clip(shadow, 0.0, 1.0))[:, :, None]
    # The people: brightness halfway to the real ground's, a slight blur, a soft edge.
    people = people_bgr.astype(np.float32)
    ground_mean = float(background_bgr.mean())
    synthetic_ground = people_bgr[~person_mask]
    synthetic_mean = float(synthetic_ground.mean()) if synthetic_ground.size else ground_mean
    people *= float(np.clip(math.sqrt(max(ground_mean, 1.0) / max(synthetic_mean, 1.0)), 0.75, 1.25))
    if rng.random() < 0.5:  # real clothes are often grey, and people stand in shade: duller, darker people
        grey = people.mean(axis=2, keepdims=True)
        people = grey + (people - grey) * float(rng.uniform(0.2, 1.0))
        people *= float(rng.uniform(0.55, 1.1))
    if real_detail:
        ground = background_bgr.astype(np.float32)
        detail = ground - np.asarray(cv2.GaussianBlur(ground, (0, 0), 1.5), np.float32)
        offset_px = (int(rng.integers(h // 4, h - h // 4 + 1)), int(rng.integers(w // 4, w - w // 4 + 1)))
        people += np.roll(detail, offset_px, axis=(0, 1)) * float(rng.uniform(0.4, 1.0))
    sigma = float(rng.uniform(0.0, 0.8))
    if sigma > 0.2:
        people = np.asarray(cv2.GaussianBlur(people, (0, 0), sigma), np.float32)
    alpha = np.asarray(cv2.GaussianBlur(mask, (0, 0), 0.6), np.float32)[:, :, None]
    out = out * (1.0 - alpha) + people * alpha
    return np.asarray(np.clip(out + 0.5, 0, 255), np.uint8)


def main() -> int:
    parser = argparse.ArgumentParser(description="Derive the real-ground frames from the Caliterra images.")
    parser.add_argument("--source", type=Path, required=True, help="the images/ folder of odm_data_caliterra")
    parser.add_argument("--out", type=Path, default=GROUND_DIR)
    args = parser.parse_args()
    index = prepare(args.source, args.out)
    frames = index["frames"]
    assert isinstance(frames, list)
    held = sum(f["split"] == HELDOUT for f in frames)
    sys.stdout.write(f"wrote {len(frames)} frames ({held} held out) to {args.out}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
