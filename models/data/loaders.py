"""Loaders for the public drone datasets users bring to train field models (nothing is downloaded here).

- **DroneCrowd** (full release, head annotations): images ``<root>/<split>_data/images/img{seq:3}{frame:3}.jpg`` and,
  per sequence, ``<root>/annotations/00{seq}.mat`` whose variable ``anno`` has one row per head,
  ``[frame_id, track_id, xmin, ymin, xmax, ymax]`` (the layout read by public DroneCrowd converters; the ECCV 2020
  challenge's per-frame ``GT_img*.mat`` files are another layout, not read here). A head point is its box centre.
- **VisDrone DET**: ``<root>/images/<name>.jpg`` and ``<root>/annotations/<name>.txt`` with lines
  ``left,top,width,height,score,category,truncation,occlusion``. Categories 1 (pedestrian) and 2 (people) are
  persons; score 0 marks an ignored region. VisDrone has boxes, not heads: the head point is taken at the top of the
  box, half a box width down (an approximation, exact only for upright people seen obliquely).

Both return :class:`LabelledImage` lists: an image path and head points (N, 2) in pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt


class DatasetError(Exception):
    """A dataset is missing or malformed (what, and which file)."""

    def __init__(self, path: Path, what: str) -> None:
        super().__init__(f"{path}: {what}")
        self.path = path


@dataclass(frozen=True)
class LabelledImage:
    """An image and the pixel positions (N, 2) of the people's heads in it."""

    image_path: Path
    heads_uv: npt.NDArray[np.float64]


def load_dronecrowd(root: Path, split: str) -> list[LabelledImage]:
    """Every image of a DroneCrowd split with its head points (see the module docstring for the layout)."""
    from scipy import io

    image_dir = root / f"{split}_data" / "images"
    if not image_dir.is_dir():
        raise DatasetError(image_dir, "no such directory (expected <root>/<split>_data/images)")
    annotations: dict[str, npt.NDArray[np.float64]] = {}
    out = []
    for image_path in sorted(image_dir.glob("img*.jpg")):
        name = image_path.stem
        seq, frame = name[3:6], name[6:]
        if not (seq.isdigit() and frame.isdigit()):
            raise DatasetError(image_path, "expected a name img<seq:3><frame:3>.jpg")
        if seq not in annotations:
            mat_path = root / "annotations" / f"00{seq}.mat"
            if not mat_path.is_file():
                raise DatasetError(mat_path, "annotation file missing")
            try:
                anno = np.asarray(io.loadmat(str(mat_path))["anno"], dtype=np.float64)
            except (KeyError, ValueError, OSError) as exc:
                raise DatasetError(mat_path, f"cannot read variable 'anno': {exc}") from None
            if anno.ndim != 2 or anno.shape[1] < 6:
                raise DatasetError(mat_path, f"'anno' must have 6 columns per row, has shape {anno.shape}")
            annotations[seq] = anno
        rows = annotations[seq][annotations[seq][:, 0] == int(frame)]
        heads = np.column_stack([(rows[:, 2] + rows[:, 4]) / 2.0, (rows[:, 3] + rows[:, 5]) / 2.0])
        out.append(LabelledImage(image_path, heads.reshape(-1, 2)))
    if not out:
        raise DatasetError(image_dir, "no img*.jpg images")
    return out


PERSON_CATEGORIES = (1, 2)


def load_visdrone_det(root: Path) -> list[LabelledImage]:
    """Every VisDrone DET image with approximate head points of its pedestrians and people."""
    image_dir, annotation_dir = root / "images", root / "annotations"
    for directory in (image_dir, annotation_dir):
        if not directory.is_dir():
            raise DatasetError(directory, "no such directory (expected <root>/images and <root>/annotations)")
    out = []
    for image_path in sorted(image_dir.glob("*.jpg")):
        txt = annotation_dir / f"{image_path.stem}.txt"
        if not txt.is_file():
            raise DatasetError(txt, "annotation file missing")
        heads = []
        for number, line in enumerate(txt.read_text(encoding="utf-8").splitlines(), start=1):
            if not line.strip():
                continue
            fields = line.strip().rstrip(",").split(",")
            try:
                left, top, width, height, score, category = (float(v) for v in fields[:6])
            except ValueError:
                raise DatasetError(txt, f"line {number}: expected numbers, got {line!r}") from None
            if len(fields) < 6:
                raise DatasetError(txt, f"line {number}: expected at least 6 fields, got {len(fields)}")
            if score == 0 or int(category) not in PERSON_CATEGORIES or width <= 0 or height <= 0:
                continue
            heads.append((left + width / 2.0, top + min(width / 2.0, height / 2.0)))
        out.append(LabelledImage(image_path, np.asarray(heads, dtype=np.float64).reshape(-1, 2)))
    if not out:
        raise DatasetError(image_dir, "no .jpg images")
    return out
