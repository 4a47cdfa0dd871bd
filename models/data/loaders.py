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

Real frames with person *boxes*, read for evaluation (``models/eval/real.py``) as :class:`BoxedImage` lists (an image
path, boxes (N, 4) of ``x_min, y_min, x_max, y_max`` pixels, and the altitude when the set records it):

- **SDD reference** (``../shared/datasets/sdd-reference``, evaluation only: non-commercial): ``boxes.json`` with
  ``{"images": {name: {"people_boxes_xyxy": [[x0, y0, x1, y1], ...], ...}}}`` beside the images.
- **COCO boxes** (HIT-UAV's ``normal_json``, CC BY 4.0, and any COCO-style set): ``images`` (``id``, ``file_name``),
  ``annotations`` (``image_id``, ``category_id``, ``bbox`` = ``[left, top, width, height]``), ``categories``
  (``id``, ``name``); categories named person, pedestrian or people are persons. HIT-UAV file names
  (``T_HHH_AA_P_NNNNN``: daylight flag, altitude in metres, camera angle in degrees, ...) give the altitude.
- **YOLO** (``images/NAME.jpg`` and ``labels/NAME.txt`` with lines ``class x_centre y_centre width height``, all
  relative to the image size): the classes given as persons.

:func:`load_real_set` recognises the layout of a folder.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from companion.errors import SlzError


class DatasetError(SlzError):
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


PERSON_CATEGORY_NAMES = ("person", "pedestrian", "people")
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")


@dataclass(frozen=True)
class BoxedImage:
    """A real frame and its annotated people.

    Attributes
    ----------
    image_path : Path
        The frame.
    boxes_xyxy : ndarray, shape (N, 4), float64
        ``x_min, y_min, x_max, y_max`` of each annotated person, image pixels.
    altitude_m : float or None
        Camera altitude above ground, metres, when the set records it.
    """

    image_path: Path
    boxes_xyxy: npt.NDArray[np.float64]
    altitude_m: float | None = None


def _boxes(rows: list[list[float]], where: Path) -> npt.NDArray[np.float64]:
    boxes = np.asarray(rows, dtype=np.float64).reshape(-1, 4) if rows else np.zeros((0, 4), np.float64)
    if not np.isfinite(boxes).all():
        raise DatasetError(where, "box coordinates must be finite numbers")
    if (boxes[:, 2] < boxes[:, 0]).any() or (boxes[:, 3] < boxes[:, 1]).any():
        raise DatasetError(where, "boxes must be x_min, y_min, x_max, y_max with max >= min")
    return boxes


def _read_json(path: Path) -> object:
    if not path.is_file():
        raise DatasetError(path, "no such file")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise DatasetError(path, f"not valid JSON: {str(exc)[:120]}") from None


def load_sdd_reference(root: Path) -> list[BoxedImage]:
    """The SDD reference frames with the person boxes of ``boxes.json`` (module docstring); altitude unknown."""
    path = root / "boxes.json"
    data = _read_json(path)
    images = data.get("images") if isinstance(data, dict) else None
    if not isinstance(images, dict) or not images:
        raise DatasetError(path, "expected an object with a non-empty 'images' object")
    out = []
    for name, entry in sorted(images.items()):
        rows = entry.get("people_boxes_xyxy") if isinstance(entry, dict) else None
        if not isinstance(rows, list):
            raise DatasetError(path, f"images.{str(name)[:80]}: 'people_boxes_xyxy' must be a list of boxes")
        image_path = root / str(name)
        if not image_path.is_file():
            raise DatasetError(image_path, "image listed in boxes.json is missing")
        try:
            boxes = _boxes(rows, path)
        except ValueError:
            raise DatasetError(path, f"images.{str(name)[:80]}: boxes must be [x0, y0, x1, y1] numbers") from None
        out.append(BoxedImage(image_path, boxes, None))
    return out


_HIT_UAV_NAME = re.compile(r"^[01]_(\d{2,3})_(\d{2})_\d+_\d+$")


def hit_uav_altitude_m(stem: str) -> float | None:
    """The altitude in a HIT-UAV file name (``T_HHH_AA_P_NNNNN``, ``HHH`` metres), or None for other names."""
    match = _HIT_UAV_NAME.match(stem)
    return float(match.group(1)) if match else None


def load_coco_people(annotation_path: Path, image_dir: Path) -> list[BoxedImage]:
    """Every image of a COCO-style annotation file with its person boxes (module docstring)."""
    data = _read_json(annotation_path)
    if not isinstance(data, dict) or not all(isinstance(data.get(k), list) for k in ("images", "categories")):
        raise DatasetError(annotation_path, "expected COCO keys 'images' and 'categories' (lists)")
    try:
        persons = {int(c["id"]) for c in data["categories"] if str(c["name"]).strip().lower() in PERSON_CATEGORY_NAMES}
        boxes: dict[int, list[list[float]]] = {}
        for a in data.get("annotations", []):
            if int(a["category_id"]) in persons:
                left, top, width, height = (float(v) for v in a["bbox"][:4])
                boxes.setdefault(int(a["image_id"]), []).append([left, top, left + width, top + height])
        images = [(int(i["id"]), str(i["file_name"])) for i in data["images"]]
    except (KeyError, TypeError, ValueError) as exc:
        raise DatasetError(annotation_path, f"malformed COCO entry: {str(exc)[:120]}") from None
    out = []
    for image_id, file_name in sorted(images, key=lambda item: item[1]):
        image_path = image_dir / file_name
        if not image_path.is_file():
            raise DatasetError(image_path, "image listed in the annotations is missing")
        out.append(
            BoxedImage(
                image_path, _boxes(boxes.get(image_id, []), annotation_path), hit_uav_altitude_m(image_path.stem)
            )
        )
    if not out:
        raise DatasetError(annotation_path, "no images")
    return out


def load_yolo_people(image_dir: Path, label_dir: Path, person_classes: tuple[int, ...] = (0,)) -> list[BoxedImage]:
    """Every image of a YOLO-layout folder with the boxes of ``person_classes`` (a missing label file: nobody)."""
    if not image_dir.is_dir():
        raise DatasetError(image_dir, "no such directory")
    out = []
    for image_path in sorted(p for p in image_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES):
        shape = cv2.imread(str(image_path), cv2.IMREAD_UNCHANGED)
        if shape is None:
            raise DatasetError(image_path, "unreadable image")
        h, w = shape.shape[:2]
        rows: list[list[float]] = []
        txt = label_dir / f"{image_path.stem}.txt"
        lines = txt.read_text(encoding="utf-8").splitlines() if txt.is_file() else []
        for number, line in enumerate(lines, start=1):
            fields = line.split()
            if not fields:
                continue
            try:
                cls, xc, yc, bw, bh = int(fields[0]), *(float(v) for v in fields[1:5])
            except ValueError:
                raise DatasetError(txt, f"line {number}: expected 'class xc yc w h', got {line[:80]!r}") from None
            if len(fields) < 5 or not all(math.isfinite(v) for v in (xc, yc, bw, bh)):
                raise DatasetError(txt, f"line {number}: expected 5 finite fields, got {line[:80]!r}")
            if cls in person_classes:
                rows.append([(xc - bw / 2) * w, (yc - bh / 2) * h, (xc + bw / 2) * w, (yc + bh / 2) * h])
        out.append(BoxedImage(image_path, _boxes(rows, txt), hit_uav_altitude_m(image_path.stem)))
    if not out:
        raise DatasetError(image_dir, "no images (.jpg, .jpeg, .png)")
    return out


def load_real_ground(root: Path, split: str | None = "heldout") -> list[BoxedImage]:
    """The frames of ``split`` (None: every frame) of a derived real-ground folder (``sitl/world/ground/<site>``:
    ``index.json`` with ``gsd_m_per_px`` and ``frames``): nobody in them, so no boxes."""
    path = root / "index.json"
    data = _read_json(path)
    frames = data.get("frames") if isinstance(data, dict) else None
    if not isinstance(frames, list):
        raise DatasetError(path, "expected an object with a 'frames' list")
    out = []
    for entry in frames:
        if not isinstance(entry, dict) or "name" not in entry or "split" not in entry:
            raise DatasetError(path, "each frame needs 'name' and 'split'")
        if split is not None and entry["split"] != split:
            continue
        image_path = root / f"{entry['name']}.jpg"
        if not image_path.is_file():
            raise DatasetError(image_path, "frame listed in index.json is missing")
        out.append(BoxedImage(image_path, np.zeros((0, 4), np.float64), None))
    if not out:
        raise DatasetError(path, f"no frame of split {split!r}" if split else "no frame")
    return out


def load_real_set(root: Path) -> list[BoxedImage]:
    """A folder of real frames in any layout above: ``boxes.json`` (SDD reference), ``annotations/*.json`` with
    images beside them or in ``images/`` or a folder named like the file (COCO, HIT-UAV), ``images/`` with
    ``labels/`` (YOLO, class 0 = person), or a derived real-ground folder (``index.json``: its held-out frames)."""
    if (root / "boxes.json").is_file():
        return load_sdd_reference(root)
    if (root / "index.json").is_file():
        return load_real_ground(root)
    annotation_files = sorted((root / "annotations").glob("*.json")) if (root / "annotations").is_dir() else []
    if annotation_files:
        out: list[BoxedImage] = []
        for annotation in annotation_files:
            candidates = [root / annotation.stem, root / "images", root]
            image_dir = next((d for d in candidates if d.is_dir() and any(d.glob("*.jp*g"))), root / "images")
            out += load_coco_people(annotation, image_dir)
        return out
    if (root / "images").is_dir() and (root / "labels").is_dir():
        return load_yolo_people(root / "images", root / "labels")
    raise DatasetError(root, "no known layout (boxes.json, annotations/*.json, or images/ with labels/)")
