"""Training data for the density models: frames of ``models/data/generate.py`` with augmentation (PyTorch).

Each sample is a random crop of a random frame, rescaled (altitude), flipped and rotated (a nadir view has no up),
recoloured, veiled (low contrast towards one colour), blurred, noised and JPEG-compressed (real cameras), with
procedural hard negatives
(``models/data/distractors.py``) pasted away from the people.

With real ground (``models/data/real_ground.py``, the training frames only), a share of the samples is real:

- **real negatives**: a crop of real ground at a GSD drawn in a range (by default the companion's working range),
  nobody in it;
- **composites**: the synthetic crop rescaled to such a GSD and its people (mask, soft edge, a shadow) pasted onto a
  real crop of the same size and GSD, the heads kept. Below the real frames' stored GSD the composite is made at the
  stored GSD and then enlarged as a whole, so that people and ground share one softness (the network cannot tell a
  person by being sharper than the ground around it). A share of the composites' people carry the real crop's fine
  texture (``real_detail_fraction``).

Both then go through the same colour, blur, noise and JPEG augmentation as every sample.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import torch
from torch.utils.data import Dataset

from models.data.distractors import paste
from models.data.images import read_bgr, read_mask
from models.data.real_ground import RealGround, composite, ground_crop
from models.density.preprocess import OUTPUT_STRIDE, to_input

# The GSDs the model sees in the companion: frames finer than perception.model.min_gsd_m_per_px (0.045) are shrunk to
# it, and 40 m (the highest search altitude) over a 90-degree 640 px camera gives 0.125 m/px.
WORKING_GSD_M_PER_PX = (0.045, 0.13)


@dataclass(frozen=True)
class LabelledFrame:
    """One frame in memory: BGR image (H, W, 3) uint8, person mask (H, W) bool, heads (K, 2) (u, v) pixels, and
    its nadir ground sampling distance (altitude over the focal length in pixels, m/px; 0 when unknown)."""

    stem: str
    image_bgr: npt.NDArray[np.uint8]
    person_mask: npt.NDArray[np.bool_]
    heads_px: npt.NDArray[np.float32]
    altitude_m: float
    gsd_m_per_px: float = 0.0


def load_frames(split_dir: Path, limit: int | None = None, last: int | None = None) -> list[LabelledFrame]:
    """Read a split written by the generator (``NNNNNN.png`` or ``.jpg``, ``.mask.png``, ``.json``), sorted by stem.

    ``limit`` keeps the first frames, ``last`` the last ones.
    """
    labels = sorted(p for p in split_dir.glob("*.json") if p.stem.isdigit())
    if not labels:
        raise FileNotFoundError(f"no labelled frames (NNNNNN.json) in {split_dir}")
    labels = labels[:limit]
    if last is not None:
        labels = labels[-last:]
    frames: list[LabelledFrame] = []
    for label_path in labels:
        stem = label_path.stem
        image_path = split_dir / f"{stem}.png"
        if not image_path.is_file():
            image_path = split_dir / f"{stem}.jpg"
        image = read_bgr(image_path)
        mask = read_mask(split_dir / f"{stem}.mask.png")
        label = json.loads(label_path.read_text(encoding="utf-8"))
        heads = np.asarray(label["heads"], np.float32).reshape(-1, 2)
        altitude_m = float(label["altitude_m"])
        fx_px = float(label.get("camera", {}).get("fx_px", 0.0))
        gsd = altitude_m / fx_px if fx_px > 0 else 0.0
        frames.append(LabelledFrame(stem, image, mask, heads, altitude_m, gsd))
    return frames


class CrowdCrops(Dataset[tuple[torch.Tensor, torch.Tensor]]):
    """Augmented random crops.

    Parameters
    ----------
    frames : list of LabelledFrame
        The source frames.
    crop_px : int
        Side of the square crops (a multiple of the output stride).
    samples_per_epoch : int
        Length of one epoch.
    seed : int
        Base seed: sample ``i`` of epoch ``e`` is drawn from ``(seed, e, i)``, whatever the worker.
    augment : bool
        False gives centre crops without augmentation (validation).
    distractors : bool
        Paste procedural hard negatives (``models/data/distractors.py``); False for the ablation without them.
    scale_range : (float, float)
        Crops are rescaled by a factor drawn log-uniformly in this range (another altitude, another lens).
    real_ground : sequence of RealGround
        Real frames with nobody in them (never the held-out ones); empty: synthetic samples only.
    real_negative_fraction, composite_fraction : float
        Shares of the samples that are real negatives and composites (module docstring); the rest are synthetic.
    real_gsd_m_per_px : (float, float)
        GSD range (m/px, drawn log-uniformly) of the real negatives and composites.
    real_detail_fraction : float
        Share of the composites whose people carry the real crop's fine texture
        (:func:`models.data.real_ground.composite`, ``real_detail``).
    """

    def __init__(
        self,
        frames: list[LabelledFrame],
        crop_px: int,
        samples_per_epoch: int,
        seed: int,
        augment: bool = True,
        distractors: bool = True,
        scale_range: tuple[float, float] = (0.7, 1.4),
        real_ground: Sequence[RealGround] = (),
        real_negative_fraction: float = 0.0,
        composite_fraction: float = 0.0,
        real_gsd_m_per_px: tuple[float, float] = WORKING_GSD_M_PER_PX,
        real_detail_fraction: float = 0.0,
    ) -> None:
        if not 0.0 <= real_detail_fraction <= 1.0:
            raise ValueError(f"real_detail_fraction must be in [0, 1], got {real_detail_fraction}")
        if not 0.005 <= real_gsd_m_per_px[0] <= real_gsd_m_per_px[1] <= 1.0:
            raise ValueError(f"real_gsd_m_per_px must satisfy 0.005 <= low <= high <= 1 m/px, got {real_gsd_m_per_px}")
        if not 0.1 <= scale_range[0] <= scale_range[1] <= 10.0:
            raise ValueError(f"scale_range must satisfy 0.1 <= low <= high <= 10, got {scale_range}")
        if not (
            real_negative_fraction >= 0.0
            and composite_fraction >= 0.0
            and real_negative_fraction + composite_fraction <= 1.0
        ):
            raise ValueError("real_negative_fraction and composite_fraction must be >= 0 and add up to at most 1")
        if (real_negative_fraction or composite_fraction) and not real_ground:
            raise ValueError("real negatives and composites need real_ground frames")
        if composite_fraction and any(f.gsd_m_per_px <= 0 for f in frames):
            raise ValueError("composites need every frame's gsd_m_per_px (the label's camera.fx_px)")
        self.real_ground = list(real_ground)
        self.real_negative_fraction = real_negative_fraction
        self.composite_fraction = composite_fraction
        self.real_gsd_m_per_px = real_gsd_m_per_px
        self.real_detail_fraction = real_detail_fraction
        # The coarsest stored GSD of the real frames: no real crop is enlarged at or above it.
        self.stored_gsd_m_per_px = max((g.gsd_m_per_px for g in self.real_ground), default=0.0)
        self.scale_range = scale_range
        if crop_px % OUTPUT_STRIDE:
            raise ValueError(f"crop_px must be a multiple of {OUTPUT_STRIDE}, got {crop_px}")
        self.frames, self.crop_px, self.samples, self.seed, self.augment = (
            frames,
            crop_px,
            samples_per_epoch,
            seed,
            augment,
        )
        self.distractors = distractors
        self.epoch = 0

    def __len__(self) -> int:
        return self.samples

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        rng = np.random.default_rng([self.seed, self.epoch, index])
        frame = (
            self.frames[index % len(self.frames)] if not self.augment else self.frames[rng.integers(len(self.frames))]
        )
        image, mask, heads = frame.image_bgr, frame.person_mask, frame.heads_px
        c = self.crop_px
        kind = "synthetic"
        if self.augment and self.real_ground:
            draw = rng.random()
            if draw < self.real_negative_fraction:
                kind = "negative"
            elif draw < self.real_negative_fraction + self.composite_fraction:
                kind = "composite"
        if kind == "negative":
            ground = self.real_ground[int(rng.integers(len(self.real_ground)))]
            real = ground_crop(ground, rng, c, _log_uniform(rng, self.real_gsd_m_per_px))
            none = np.zeros((0, 2), np.float32)
            real, none = _augment(real, np.zeros((c, c), np.bool_), none, rng, False)
            return torch.from_numpy(to_input(real)), torch.from_numpy(none)
        if self.augment:
            if kind == "composite":  # the people at a GSD of the range (upsampled by at most 1.4)
                target = _log_uniform(rng, self.real_gsd_m_per_px)
                scale = min(1.4, frame.gsd_m_per_px / max(target, self.stored_gsd_m_per_px))
                # Finer than the stored ground: made at the stored GSD on a smaller crop, then enlarged as a whole.
                c = min(c, max(OUTPUT_STRIDE, round(c * target / self.stored_gsd_m_per_px)))
            else:
                scale = _log_uniform(rng, self.scale_range)
            h, w = image.shape[:2]
            new_w, new_h = max(c, round(w * scale)), max(c, round(h * scale))
            sx, sy = new_w / w, new_h / h
            interpolation = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
            image = np.asarray(cv2.resize(image, (new_w, new_h), interpolation=interpolation), np.uint8)
            mask = cv2.resize(mask.astype(np.uint8), (new_w, new_h), interpolation=cv2.INTER_NEAREST) > 0
            heads = heads * np.array([sx, sy], np.float32)
            if len(heads) and rng.random() < 0.6:  # most crops hold people
                u, v = heads[rng.integers(len(heads))]
                x0 = int(np.clip(u - rng.uniform(0, c), 0, new_w - c))
                y0 = int(np.clip(v - rng.uniform(0, c), 0, new_h - c))
            else:
                x0, y0 = int(rng.integers(0, new_w - c + 1)), int(rng.integers(0, new_h - c + 1))
        else:
            h, w = image.shape[:2]
            x0, y0 = (w - c) // 2, (h - c) // 2
        image = np.ascontiguousarray(image[y0 : y0 + c, x0 : x0 + c])
        mask = mask[y0 : y0 + c, x0 : x0 + c]
        heads = heads - np.array([x0, y0], np.float32)
        heads = heads[(heads[:, 0] >= 0) & (heads[:, 0] < c) & (heads[:, 1] >= 0) & (heads[:, 1] < c)]
        if kind == "composite":
            gsd = frame.gsd_m_per_px / scale
            ground = self.real_ground[int(rng.integers(len(self.real_ground)))]
            background = ground_crop(ground, rng, c, gsd)
            detail = self.real_detail_fraction > 0 and rng.random() < self.real_detail_fraction
            image = composite(image, mask, background, rng, gsd, real_detail=detail)
            if c < self.crop_px:  # enlarged as a whole to the crop size
                grow = self.crop_px / c
                image = np.asarray(
                    cv2.resize(image, (self.crop_px, self.crop_px), interpolation=cv2.INTER_LINEAR), np.uint8
                )
                mask = (
                    cv2.resize(mask.astype(np.uint8), (self.crop_px, self.crop_px), interpolation=cv2.INTER_NEAREST) > 0
                )
                heads = heads * np.float32(grow)
        if self.augment:
            image, heads = _augment(image, mask, heads, rng, self.distractors and kind == "synthetic")
        return torch.from_numpy(to_input(image)), torch.from_numpy(np.ascontiguousarray(heads, np.float32))


def _log_uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return math.exp(rng.uniform(math.log(bounds[0]), math.log(bounds[1])))


def _augment(
    image: npt.NDArray[np.uint8],
    mask: npt.NDArray[np.bool_],
    heads: npt.NDArray[np.float32],
    rng: np.random.Generator,
    distractors: bool,
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.float32]]:
    c = image.shape[0]
    if rng.random() < 0.6 and distractors:
        image = paste(image, mask, rng, int(rng.integers(1, 7)), c // 2)
    image, heads = turn_and_flip(image, heads, int(rng.integers(4)), bool(rng.random() < 0.5))
    # Colour: hue, saturation, brightness, contrast, gamma, sometimes grey.
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV).astype(np.float32)
    hsv[:, :, 0] = (hsv[:, :, 0] + rng.uniform(-12, 12)) % 180
    hsv[:, :, 1] *= rng.uniform(0.5, 1.4)
    hsv[:, :, 2] *= rng.uniform(0.6, 1.4)
    image = np.asarray(cv2.cvtColor(np.clip(hsv, 0, 255).astype(np.uint8), cv2.COLOR_HSV2BGR), np.uint8)
    if rng.random() < 0.1:
        image = np.asarray(cv2.cvtColor(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR), np.uint8)
    x = image.astype(np.float32) / 255.0
    x = (x - x.mean()) * rng.uniform(0.7, 1.3) + x.mean()
    x = np.clip(x, 0, 1) ** rng.uniform(0.7, 1.4)
    if rng.random() < 0.4:  # a veil: low contrast towards one colour (haze, glare, washed-out sensors), uneven
        veil = rng.uniform(0.35, 1.0, size=3).astype(np.float32)
        strength: float | npt.NDArray[np.float32] = float(rng.uniform(0.2, 0.75))
        if rng.random() < 0.5:  # stronger towards one edge
            strength = strength * np.linspace(rng.uniform(0.3, 1.0), 1.0, c, dtype=np.float32)[:, None, None]
        x = x * (1 - strength) + veil[None, None, :] * strength
    if rng.random() < 0.3:
        x = np.asarray(cv2.GaussianBlur(x, (0, 0), rng.uniform(0.3, 1.2)), np.float32)
    if rng.random() < 0.5:
        x = x + rng.normal(0, rng.uniform(0.005, 0.03), size=x.shape).astype(np.float32)
    image = np.clip(x * 255 + 0.5, 0, 255).astype(np.uint8)
    if rng.random() < 0.4:
        ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(35, 95))])
        if ok:
            image = np.asarray(cv2.imdecode(buf, cv2.IMREAD_COLOR), np.uint8)
    return image, heads.astype(np.float32)


def turn_and_flip(
    image: npt.NDArray[np.uint8], heads: npt.NDArray[np.float32], quarter_turns: int, mirror: bool
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.float32]]:
    """Rotate a square crop by ``quarter_turns`` x 90 degrees counter-clockwise, then mirror it left-right.

    Head points (K, 2) of (u, v) continuous pixel coordinates (pixel centres at +0.5) follow the image.
    """
    c = image.shape[0]
    if image.shape[1] != c:
        raise ValueError(f"crop must be square, got {image.shape[:2]}")
    heads = heads.reshape(-1, 2).astype(np.float32)
    for _ in range(quarter_turns % 4):
        image = np.rot90(image)
        heads = np.stack([heads[:, 1], c - heads[:, 0]], axis=1)
    if mirror:
        image = image[:, ::-1]
        heads = np.stack([c - heads[:, 0], heads[:, 1]], axis=1)
    return np.ascontiguousarray(image), heads.astype(np.float32)


def collate(batch: list[tuple[torch.Tensor, torch.Tensor]]) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """Stack images (N, 3, c, c); keep each crop's head points (K_i, 2) apart."""
    return torch.stack([b[0] for b in batch]), [b[1] for b in batch]
