"""Procedural hard negatives: textures and objects that look like people to a density network but are not.

A synthetic-only crowd model counts roofs, gravel, tree crowns, bikes and shadows on real aerial frames as people.
These generators draw such things (numpy and OpenCV only, deterministic for a given generator) so that training can
paste them onto frames, away from the people, as unlabelled background.
"""

from __future__ import annotations

import enum
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

U8Image = npt.NDArray[np.uint8]
F32Array = npt.NDArray[np.float32]


class DistractorKind(str, enum.Enum):
    """Kinds of hard negatives."""

    GRAVEL = "gravel"
    """Dense small stones and specks."""
    ROOF = "roof"
    """A roof: flat colour with shingle or panel stripes, a ridge and vents."""
    CANOPY = "canopy"
    """A tree crown: clustered shaded leaf blobs, with gaps."""
    SPOTS = "spots"
    """Head-sized round spots without a body: stones, manholes, drain covers, balls."""
    VEHICLE = "vehicle"
    """Bikes, scooters and parked cars seen from above: dark rounded rectangles and wheel pairs."""
    SHADOW = "shadow"
    """Soft dark polygons: shadows of poles, walls and trees."""
    LINES = "lines"
    """Painted lines, kerbs and cracks."""
    FOLIAGE = "foliage"
    """Bushes, hedges and flower beds: leaf-sized blobs over fractal shading with dark gaps, some flowers."""
    PHOTO = "photo"
    """A tinted crop of a real CC0 photo texture (grass, gravel, brick; ``models/data/textures/SOURCES.md``)."""


TEXTURE_DIR = Path(__file__).parent / "textures"
_textures: list[F32Array] = []


def photo_textures() -> list[F32Array]:
    """The CC0 photo textures (grayscale, float32 0-255), read once."""
    if not _textures:
        for path in sorted(TEXTURE_DIR.glob("*.jpg")):
            image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            if image is None:
                raise FileNotFoundError(f"texture missing or unreadable: {path}")
            _textures.append(image.astype(np.float32))
        if not _textures:
            raise FileNotFoundError(f"no photo textures (*.jpg) in {TEXTURE_DIR}")
    return _textures


def fractal_noise(size_px: int, rng: np.random.Generator, octaves: int = 4) -> F32Array:
    """Noise with most of its energy at coarse scales (octaves of upsampled white noise), shape (s, s), 0-1."""
    out = np.zeros((size_px, size_px), np.float32)
    weight_total = 0.0
    for octave in range(octaves):
        cells = max(2, size_px >> (octaves - octave))
        layer = rng.random((cells, cells)).astype(np.float32)
        weight = 0.5**octave
        out += weight * np.asarray(cv2.resize(layer, (size_px, size_px), interpolation=cv2.INTER_CUBIC), np.float32)
        weight_total += weight
    out /= weight_total
    lo, hi = float(out.min()), float(out.max())
    return (out - lo) / (hi - lo) if hi > lo else np.full_like(out, 0.5)


def _colour(rng: np.random.Generator, low: int = 20, high: int = 235) -> npt.NDArray[np.float32]:
    return rng.integers(low, high, size=3).astype(np.float32)


def draw(kind: DistractorKind, size_px: int, rng: np.random.Generator) -> tuple[F32Array, F32Array]:
    """One distractor patch.

    Parameters
    ----------
    kind : DistractorKind
        What to draw.
    size_px : int
        Side of the square patch, pixels (>= 8).
    rng : numpy Generator
        Source of randomness.

    Returns
    -------
    colour : ndarray, shape (size_px, size_px, 3), float32
        BGR values 0-255.
    alpha : ndarray, shape (size_px, size_px), float32
        Opacity 0-1 (soft edges).
    """
    s = max(8, int(size_px))
    colour = np.zeros((s, s, 3), np.float32)
    alpha = np.zeros((s, s), np.float32)
    if kind is DistractorKind.GRAVEL:
        base = _colour(rng, 90, 200)
        colour[:] = base * rng.uniform(0.85, 1.1)
        n = int(rng.integers(s * s // 40, s * s // 8))
        for _ in range(n):
            c = (int(rng.integers(0, s)), int(rng.integers(0, s)))
            r = int(rng.integers(1, 4))
            shade = base * rng.uniform(0.4, 1.4)
            cv2.circle(colour, c, r, tuple(float(x) for x in shade), -1)
        cv2.circle(alpha, (s // 2, s // 2), s // 2, 1.0, -1)
    elif kind is DistractorKind.ROOF:
        base = _colour(rng, 40, 200)
        colour[:] = base
        period = int(rng.integers(3, 9))
        stripe = base * rng.uniform(0.6, 0.9)
        for y in range(0, s, period):
            cv2.line(colour, (0, y), (s, y), tuple(float(x) for x in stripe), 1)
        cv2.line(colour, (0, s // 2), (s, s // 2), tuple(float(x) for x in base * 1.3), 2)
        for _ in range(int(rng.integers(0, 6))):
            c = (int(rng.integers(2, s - 2)), int(rng.integers(2, s - 2)))
            cv2.circle(colour, c, int(rng.integers(2, 6)), tuple(float(x) for x in _colour(rng)), -1)
        half = int(s * rng.uniform(0.3, 0.5))
        cv2.rectangle(alpha, (s // 2 - half, s // 2 - half), (s // 2 + half, s // 2 + half), 1.0, -1)
    elif kind is DistractorKind.CANOPY:
        green = np.array([rng.uniform(20, 80), rng.uniform(60, 140), rng.uniform(20, 90)], np.float32)
        for _ in range(int(rng.integers(10, 40))):
            c = (int(rng.normal(s / 2, s / 6)), int(rng.normal(s / 2, s / 6)))
            r = int(rng.integers(max(2, s // 16), max(3, s // 5)))
            shade = green * rng.uniform(0.5, 1.4)
            cv2.circle(colour, c, r, tuple(float(x) for x in shade), -1)
            cv2.circle(alpha, c, r, 1.0, -1)
    elif kind is DistractorKind.SPOTS:
        for _ in range(int(rng.integers(1, 12))):
            c = (int(rng.integers(0, s)), int(rng.integers(0, s)))
            r = int(rng.integers(1, 7))
            cv2.circle(colour, c, r, tuple(float(x) for x in _colour(rng)), -1)
            cv2.circle(alpha, c, r, 1.0, -1)
    elif kind is DistractorKind.VEHICLE:
        body = _colour(rng)
        for _ in range(int(rng.integers(1, 4))):
            centre = (float(rng.uniform(0.2, 0.8) * s), float(rng.uniform(0.2, 0.8) * s))
            length = float(rng.uniform(0.15, 0.6) * s)
            width = float(length * rng.uniform(0.15, 0.5))
            box = cv2.boxPoints((centre, (length, width), float(rng.uniform(0, 180)))).astype(np.int32)
            cv2.fillPoly(colour, [box], tuple(float(x) for x in body * rng.uniform(0.6, 1.2)))
            cv2.fillPoly(alpha, [box], 1.0)
            for end in (box[0], box[2]):
                cv2.circle(colour, (int(end[0]), int(end[1])), max(1, int(width / 3)), (25.0, 25.0, 25.0), -1)
                cv2.circle(alpha, (int(end[0]), int(end[1])), max(1, int(width / 3)), 1.0, -1)
    elif kind is DistractorKind.SHADOW:
        pts = rng.uniform(0, s, size=(int(rng.integers(3, 7)), 2)).astype(np.int32)
        cv2.fillPoly(alpha, [cv2.convexHull(pts)], float(rng.uniform(0.3, 0.6)))
    elif kind is DistractorKind.FOLIAGE:
        leaf = np.array([rng.uniform(20, 90), rng.uniform(50, 150), rng.uniform(20, 110)], np.float32)
        if rng.random() < 0.3:  # dry or autumn leaves, soil of a bed
            leaf = np.array([rng.uniform(30, 90), rng.uniform(60, 140), rng.uniform(90, 170)], np.float32)
        shading = fractal_noise(s, rng)
        colour[:] = leaf * (0.3 + 0.9 * shading)[:, :, None]
        for _ in range(int(rng.integers(s * s // 60, s * s // 12))):
            c = (int(rng.integers(0, s)), int(rng.integers(0, s)))
            axes = (int(rng.integers(1, 4)), int(rng.integers(1, 3)))
            shade = leaf * rng.uniform(0.2, 1.6)
            cv2.ellipse(colour, c, axes, float(rng.uniform(0, 180)), 0, 360, tuple(float(x) for x in shade), -1)
        if rng.random() < 0.4:  # flowers: small bright dots
            petal = _colour(rng, 120, 255)
            for _ in range(int(rng.integers(s // 4, s * 2))):
                c = (int(rng.integers(0, s)), int(rng.integers(0, s)))
                cv2.circle(colour, c, int(rng.integers(1, 3)), tuple(float(x) for x in petal), -1)
        alpha[:] = (fractal_noise(s, rng, octaves=3) > rng.uniform(0.2, 0.5)).astype(np.float32)
        cv2.circle(alpha, (s // 2, s // 2), s // 3, 1.0, -1)
    elif kind is DistractorKind.PHOTO:
        texture = photo_textures()[int(rng.integers(len(photo_textures())))]
        scale = float(rng.uniform(0.25, 1.5))
        side = min(texture.shape[0], max(8, round(s / scale)))
        y0, x0 = (int(rng.integers(0, texture.shape[i] - side + 1)) for i in (0, 1))
        crop = np.asarray(cv2.resize(texture[y0 : y0 + side, x0 : x0 + side], (s, s)), np.float32) / 255.0
        crop = np.clip((crop - crop.mean()) * rng.uniform(0.6, 1.6) + 0.5, 0.0, 1.0)
        natural = ((60, 140, 70), (70, 110, 140), (150, 150, 150), (90, 160, 190), (60, 90, 60))  # BGR
        tint = np.array(natural[int(rng.integers(len(natural)))], np.float32) if rng.random() < 0.7 else _colour(rng)
        colour[:] = crop[:, :, None] * tint[None, None, :] * rng.uniform(0.8, 1.6)
        alpha[:] = 1.0
    else:  # LINES
        paint = _colour(rng, 150, 255) if rng.random() < 0.6 else _colour(rng, 10, 60)
        for _ in range(int(rng.integers(1, 4))):
            p0 = (int(rng.integers(0, s)), int(rng.integers(0, s)))
            p1 = (int(rng.integers(0, s)), int(rng.integers(0, s)))
            thick = int(rng.integers(1, 4))
            cv2.line(colour, p0, p1, tuple(float(x) for x in paint), thick)
            cv2.line(alpha, p0, p1, 1.0, thick)
    blur = float(rng.uniform(0.3, 1.0))
    alpha = np.asarray(cv2.GaussianBlur(alpha, (0, 0), blur), np.float32)
    return colour, np.clip(alpha, 0.0, 1.0)


def paste(
    image_bgr: U8Image, person_mask: npt.NDArray[np.bool_], rng: np.random.Generator, count: int, max_size_px: int
) -> U8Image:
    """Paste ``count`` random distractors onto a frame, never over a person (mask grown by 3 px).

    Parameters
    ----------
    image_bgr : ndarray, shape (H, W, 3), uint8
        The frame; not modified.
    person_mask : ndarray, shape (H, W), bool
        True where a person is visible.
    rng : numpy Generator
        Source of randomness.
    count : int
        Number of patches.
    max_size_px : int
        Largest patch side.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
        The frame with the distractors.
    """
    h, w = person_mask.shape
    out = image_bgr.astype(np.float32)
    keep_out = cv2.dilate(person_mask.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    kinds = list(DistractorKind)
    for _ in range(count):
        kind = kinds[int(rng.integers(len(kinds)))]
        size = int(rng.integers(12, max(13, max_size_px)))
        colour, alpha = draw(kind, size, rng)
        if kind is DistractorKind.SHADOW:
            colour = np.zeros_like(colour)
        y0, x0 = int(rng.integers(-size // 2, h - size // 2)), int(rng.integers(-size // 2, w - size // 2))
        ys, xs = slice(max(0, y0), min(h, y0 + size)), slice(max(0, x0), min(w, x0 + size))
        py, px = slice(ys.start - y0, ys.stop - y0), slice(xs.start - x0, xs.stop - x0)
        a = alpha[py, px] * ~keep_out[ys, xs]
        out[ys, xs] = out[ys, xs] * (1.0 - a[:, :, None]) + colour[py, px] * a[:, :, None]
    return np.clip(out, 0, 255).astype(np.uint8)
