"""Reading dataset images with a clear error and precise types."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

U8Image = npt.NDArray[np.uint8]
BoolMask = npt.NDArray[np.bool_]


def read_bgr(path: Path) -> U8Image:
    """A colour image as (H, W, 3) uint8 BGR. Raises FileNotFoundError when missing or unreadable."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise FileNotFoundError(f"image missing or unreadable: {path}")
    return np.asarray(image, np.uint8)


def read_mask(path: Path) -> BoolMask:
    """An 8-bit mask as (H, W) bool (True where > 127). Raises FileNotFoundError when missing or unreadable."""
    mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if mask is None:
        raise FileNotFoundError(f"mask missing or unreadable: {path}")
    return np.asarray(mask > 127, np.bool_)


def frame_paths(split_dir: Path) -> list[Path]:
    """The frames of a split folder (``NNNNNN.png`` or ``.jpg``; masks and labels left out), sorted by stem.

    Raises FileNotFoundError when there are none.
    """
    frames = sorted(p for p in split_dir.iterdir() if p.stem.isdigit() and p.suffix in (".png", ".jpg"))
    if not frames:
        raise FileNotFoundError(f"no frames (NNNNNN.png/.jpg) in {split_dir}")
    return frames
