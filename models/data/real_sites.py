"""Three more real sites beside Caliterra: a park (Garfield, CC0), a village seen from a kite (Boruszyn, CC BY 3.0)
and NEON's forest and savanna orthophotos (CC0).

Issue 52: a model's real-ground figure counts only on a site it never trained on, so the project needs several
sites. Each is derived here into ``sitl/world/ground/<site>/`` in Caliterra's layout (``index.json`` with source,
licence, GSD and each frame's split; frames at :data:`~sitl.world.ground.STORED_GSD_M_PER_PX`, JPEG quality 85):

- **garfield** (``../shared/datasets/garfield_msp/rgb``, OpenDroneMap/odm_data_garfield_msp, CC0 1.0): 28 nadir
  frames of a park in Ohio in November (lawns, paths, roads, parking lots with cars, leafless forest), Parrot Sequoia
  RGB, 4608x3456. Ground sampling distance **0.033 m/px**, estimated as for Caliterra: the image displacement of
  consecutive frames against their GPS displacement (:func:`gps_gsd_estimates`: SIFT features, a RANSAC similarity on
  quarter-size frames) gives a median of 0.0330 m/px over the 5 pairs that match well (interquartile 0.029-0.035;
  0.032 over all 20 pairs, lawns and leafless trees match poorly); the camera's 4.88 mm lens and 1.36 um pixels put
  that at about 115 m above the ground, a usual mapping height.
- **boruszyn** (``../shared/datasets/boruszyn_kap/images``, merkato/odm_boruszyn_kap, CC BY 3.0, "Photos: Andrew
  Zaborowski, with attribution to OpenStreetMap-PL"): 28 frames of a Polish village from a kite (roofs, farm yards,
  fields, ponds), halved to 2304x1728 in ``../shared``. No EXIF: the GSD, **0.055 m/px** for the near-nadir frames,
  is read from objects of known size in them (wrapped silage bales of 1.2 m span 21-25 px; the yard's 3 x 1.5 m
  road slabs about 55 x 27 px). A kite sways: the scale varies by perhaps 20 % between frames. Frames that look
  across the land (a horizon, or a scale that changes across the frame) are left out (:data:`BORUSZYN_EXCLUDED`).

- **neon** (``../shared/datasets/neon_trees/images``, NEON AOP camera imagery via weecology/DeepForest 1.5.2, CC0):
  six person-free nadir orthophotos at 0.10 m/px of pine and conifer forest, oak savanna and a Yellowstone meadow
  and road: tree crowns, their shadows, pale dead crowns, fallen logs and boulders, where the density networks put
  most of their false occupancy on unseen ground (issue 63). Upsampled by 2.22 to 0.045 m/px (much softer than a
  camera there); the four 400 px frames are kept whole (889 px), the two Yellowstone mosaics as at most
  :attr:`SiteSource.max_tiles` tiles of :data:`CROP_PX` each (:func:`derive_tiles`), numbered so that every small
  source is trained on and the site's held-out and validation frames are Yellowstone tiles (:func:`tile_numbers`).

Each frame is resampled to 0.045 m/px (Boruszyn's by 1.22: upsampled, softer than a camera at that GSD) and its centre
:data:`CROP_PX` kept (60 x 45 m, the size of a stored Caliterra frame), which keeps the repository small; Garfield's
consecutive frames overlap by half, so the centres overlap little.

**Screened for people** by eye on the ten strongest density peaks of ``slz_lite`` in each frame (``--screen DIR``
draws the sheets, :func:`screen_sheet`): a frame where someone may be is left out with the reason (``--people``).
This finds people the network sees; a person it does not see at all could pass, which the sheets cannot rule out.
The split is Caliterra's (numbers ending in 4 or 9 held out), for use inside a site; a model that never trained on a
site is scored on all its frames (``models/eval/real.py``).

Run once (``python -m models.data.real_sites --site garfield --source ../shared/datasets/garfield_msp/rgb``).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from models.data.images import read_bgr
from sitl.world.ground import GROUND_ROOT, STORED_GSD_M_PER_PX, TRAIN, split_of

U8Image = npt.NDArray[np.uint8]

CROP_PX = (1333, 1000)  # width, height of the stored centre of each frame at 0.045 m/px (as Caliterra's frames)
JPEG_QUALITY = 85
GPS_IFD = 0x8825  # EXIF's GPS block

BORUSZYN_EXCLUDED = {
    "img_4890": "oblique: the horizon is in the frame",
    "img_4909": "oblique: the scale changes across the frame",
    "img_4946": "oblique: the scale changes across the frame",
}


@dataclass(frozen=True)
class SiteSource:
    """Where a real site's frames come from and how they are derived."""

    name: str
    source: str
    licence: str
    credit: str
    source_gsd_m_per_px: float
    gsd_method: str
    pattern: str  # glob of the source frames
    excluded: dict[str, str] = field(default_factory=dict)
    tiled: bool = False  # a source larger than CROP_PX gives whole tiles of a grid, not only its centre
    max_tiles: int = 8  # of a tiled source: at most this many tiles, evenly spaced in the grid (repository size)

    def frame_name(self, path: Path) -> str:
        """The stored name of a source frame: ``garfield_0091`` for ``IMG_161122_164150_0091_RGB.JPG``."""
        if self.name == "neon":
            return NEON_PLACES[path.stem]
        if self.name == "garfield":
            match = re.search(r"_(\d{4})_RGB$", path.stem)
            if match is None:
                raise ValueError(f"unexpected Garfield frame name: {path.name}")
            return f"garfield_{match.group(1)}"
        return path.stem.lower()


GARFIELD = SiteSource(
    name="garfield",
    source="https://github.com/OpenDroneMap/odm_data_garfield_msp @ b526478, rgb/",
    licence="CC0 1.0 Universal",
    credit="OpenDroneMap odm_data_garfield_msp (CC0)",
    source_gsd_m_per_px=0.033,
    gsd_method="image displacement of consecutive frames against GPS: median 0.0330 m/px over 5 well-matched pairs",
    pattern="*_RGB.JPG",
)
BORUSZYN = SiteSource(
    name="boruszyn",
    source="https://github.com/merkato/odm_boruszyn_kap @ f8e9eab, images/ (halved to 2304x1728)",
    licence="CC BY 3.0",
    credit="Photos: Andrew Zaborowski, with attribution to OpenStreetMap-PL",
    source_gsd_m_per_px=0.055,
    gsd_method="objects of known size: silage bales (1.2 m) and yard road slabs (3 x 1.5 m)",
    pattern="img_*.jpg",
    excluded=dict(BORUSZYN_EXCLUDED),
)
NEON = SiteSource(
    name="neon",
    source="NEON AOP camera imagery (DP1.30010.001) via weecology/DeepForest 1.5.2, deepforest/data/",
    licence="CC0 1.0 Universal",
    credit="NEON (National Ecological Observatory Network), AOP camera imagery, via weecology/DeepForest",
    source_gsd_m_per_px=0.10,
    gsd_method="NEON AOP orthophotos at 0.10 m/px (../shared/datasets/neon_trees/README.md)",
    pattern="neon_*",
    tiled=True,
    max_tiles=8,
)
# The places of the NEON frames, letters only: a stored name's number (split_of) is the one NEON_NUMBERS gives it.
NEON_PLACES = {
    "neon_osbs_029": "osbs",
    "neon_sjer_477": "sjer",
    "neon_soap_031": "soapa",
    "neon_soap_061": "soapb",
    "neon_yell_528000_crop2": "yellb",
    "neon_yell_541000_crop": "yella",
}
SITES = {site.name: site for site in (GARFIELD, BORUSZYN, NEON)}


def tile_numbers(tiles_per_source: list[int]) -> list[list[int]]:
    """Frame numbers for a tiled site's sources, in order: a source of one tile takes the next number of the
    training split that is not a validation number (:func:`~models.data.real_ground.is_validation`: ending in 2);
    a source of several tiles takes the numbers left, in order, so that the site's held-out frames (numbers ending
    in 4 or 9) and its validation frames are tiles of its larger sources and every small source is trained on."""
    total = sum(tiles_per_source)
    numbers = list(range(1, total + 1))
    plain = [n for n in numbers if split_of(str(n)) == TRAIN and n % 10 != 2]
    singles = sum(1 for count in tiles_per_source if count == 1)
    if singles > len(plain):
        raise ValueError(f"{singles} single-tile sources but only {len(plain)} plain training numbers")
    single_numbers = iter(plain[:singles])
    rest = iter(n for n in numbers if n not in set(plain[:singles]))
    return [[next(single_numbers)] if count == 1 else [next(rest) for _ in range(count)] for count in tiles_per_source]


def centre_crop(image: U8Image, size_px: tuple[int, int]) -> U8Image:
    """The centre ``size_px`` (width, height) of ``image``, or all of it where it is smaller."""
    h, w = image.shape[:2]
    cw, ch = min(size_px[0], w), min(size_px[1], h)
    y0, x0 = (h - ch) // 2, (w - cw) // 2
    return np.ascontiguousarray(image[y0 : y0 + ch, x0 : x0 + cw])


def derive_frame(site: SiteSource, image: U8Image) -> U8Image:
    """A source frame at the stored GSD, its centre :data:`CROP_PX` (landscape; a portrait frame is turned)."""
    if image.shape[0] > image.shape[1]:
        image = np.ascontiguousarray(np.rot90(image))
    factor = site.source_gsd_m_per_px / STORED_GSD_M_PER_PX
    h, w = image.shape[:2]
    size = (round(w * factor), round(h * factor))
    interpolation = cv2.INTER_AREA if factor < 1 else cv2.INTER_CUBIC
    resized = np.asarray(cv2.resize(image, size, interpolation=interpolation), np.uint8)
    return centre_crop(resized, CROP_PX)


def derive_tiles(site: SiteSource, image: U8Image) -> list[U8Image]:
    """A source frame at the stored GSD as whole :data:`CROP_PX` tiles of a centred grid (row by row; at most
    ``site.max_tiles`` of them, evenly spaced), or the whole frame where it is smaller than one tile (a portrait frame
    is turned)."""
    if image.shape[0] > image.shape[1]:
        image = np.ascontiguousarray(np.rot90(image))
    factor = site.source_gsd_m_per_px / STORED_GSD_M_PER_PX
    h, w = image.shape[:2]
    interpolation = cv2.INTER_AREA if factor < 1 else cv2.INTER_CUBIC
    resized = np.asarray(
        cv2.resize(image, (round(w * factor), round(h * factor)), interpolation=interpolation), np.uint8
    )
    h, w = resized.shape[:2]
    cols, rows = w // CROP_PX[0], h // CROP_PX[1]
    if cols == 0 or rows == 0:
        return [centre_crop(resized, CROP_PX)]
    y0, x0 = (h - rows * CROP_PX[1]) // 2, (w - cols * CROP_PX[0]) // 2
    cells = [divmod(k, cols) for k in range(rows * cols)]
    if len(cells) > site.max_tiles:
        cells = [cells[round(k)] for k in np.linspace(0, len(cells) - 1, site.max_tiles)]
    return [
        np.ascontiguousarray(
            resized[y0 + r * CROP_PX[1] : y0 + (r + 1) * CROP_PX[1], x0 + c * CROP_PX[0] : x0 + (c + 1) * CROP_PX[0]]
        )
        for r, c in cells
    ]


def prepare(
    site: SiteSource, source_dir: Path, out_dir: Path | None = None, people: dict[str, str] | None = None
) -> dict[str, object]:
    """Write the site's derived frames, ``index.json`` and nothing else; ``people``: frames left out because someone
    may be in them (name: where), beside the site's own exclusions. Returns the index."""
    out_dir = out_dir or GROUND_ROOT / site.name
    sources = sorted(source_dir.glob(site.pattern))
    if not sources:
        raise FileNotFoundError(f"no {site.pattern} in {source_dir} ({site.source})")
    excluded = dict(site.excluded) | {name: f"someone may be there: {where}" for name, where in (people or {}).items()}
    out_dir.mkdir(parents=True, exist_ok=True)
    named: list[tuple[str, U8Image]] = []
    if site.tiled:
        kept = [p for p in sources if site.frame_name(p) not in excluded]
        tiles = [derive_tiles(site, read_bgr(path)) for path in kept]
        for path, source_tiles, numbers in zip(kept, tiles, tile_numbers([len(t) for t in tiles]), strict=True):
            named += [
                (f"{site.name}_{n:02d}_{site.frame_name(path)}", t) for n, t in zip(numbers, source_tiles, strict=True)
            ]
        named.sort(key=lambda item: item[0])
    else:
        for path in sources:
            name = site.frame_name(path)
            if name not in excluded:
                named.append((name, derive_frame(site, read_bgr(path))))
    frames = []
    for name, derived in named:
        cv2.imwrite(str(out_dir / f"{name}.jpg"), derived, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        h, w = derived.shape[:2]
        frames.append({"name": name, "split": split_of(name), "width_px": w, "height_px": h})
    index: dict[str, object] = {
        "site": site.name,
        "source": site.source,
        "licence": site.licence,
        "credit": site.credit,
        "source_gsd_m_per_px": site.source_gsd_m_per_px,
        "gsd_method": site.gsd_method,
        "gsd_m_per_px": STORED_GSD_M_PER_PX,
        "excluded": excluded,
        "frames": frames,
    }
    (out_dir / "index.json").write_text(json.dumps(index, indent=1) + "\n", encoding="utf-8")
    return index


def gps_gsd_estimates(paths: list[Path], downscale: int = 4) -> list[float]:
    """Metres per pixel of each well-matched pair of consecutive frames (numbered n, n+1) of a GPS-tagged nadir
    flight: the GPS displacement over the image displacement of the frame centre (SIFT features with the ratio test,
    a RANSAC similarity on ``1/downscale`` frames; a pair counts with >= 30 inliers and a scale within 5 % of 1).
    Needs Pillow (in the training lock) for EXIF."""
    from PIL import Image  # training-only dependency
    from PIL.ExifTags import GPSTAGS

    def latlon_deg(path: Path) -> tuple[float, float]:
        gps = {GPSTAGS.get(k, k): v for k, v in Image.open(path).getexif().get_ifd(GPS_IFD).items()}
        lat = sum(float(x) / 60**i for i, x in enumerate(gps["GPSLatitude"]))
        lon = sum(float(x) / 60**i for i, x in enumerate(gps["GPSLongitude"]))
        return lat, lon

    cv2.setRNGSeed(0)  # RANSAC's draws: the same estimate every run
    sift = cv2.SIFT_create(6000)  # type: ignore[attr-defined]  # in OpenCV's main module since 4.4; stubs lag

    def features(path: Path) -> tuple[Any, Any, tuple[int, int]]:
        grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if grey is None:
            raise FileNotFoundError(f"unreadable frame: {path}")
        small = cv2.resize(grey, None, fx=1 / downscale, fy=1 / downscale, interpolation=cv2.INTER_AREA)
        keypoints, descriptors = sift.detectAndCompute(small, None)
        return keypoints, descriptors, (small.shape[1], small.shape[0])

    numbers = [int(re.findall(r"\d+", p.stem)[-1]) for p in paths]
    out = []
    for a, b, na, nb in zip(paths, paths[1:], numbers, numbers[1:], strict=False):
        if nb - na != 1:
            continue
        (lat_a, lon_a), (lat_b, lon_b) = latlon_deg(a), latlon_deg(b)
        moved_m = math.hypot((lat_b - lat_a) * 111_320.0, (lon_b - lon_a) * 111_320.0 * math.cos(math.radians(lat_a)))
        ka, da, (w, h) = features(a)
        kb, db, _ = features(b)
        pairs = cv2.BFMatcher().knnMatch(da, db, k=2)
        good = [m for m, n in (p for p in pairs if len(p) == 2) if m.distance < 0.7 * n.distance]
        if len(good) < 30:
            continue
        pa = np.array([ka[m.queryIdx].pt for m in good], np.float32)
        pb = np.array([kb[m.trainIdx].pt for m in good], np.float32)
        similarity, inliers = cv2.estimateAffinePartial2D(
            pa, pb, method=cv2.RANSAC, ransacReprojThreshold=2.0, maxIters=20000, confidence=0.999
        )
        if similarity is None or int(inliers.sum()) < 30 or abs(math.hypot(*similarity[:, 0]) - 1.0) > 0.05:
            continue
        centre = np.array([w / 2, h / 2, 1.0])
        moved_px = float(np.hypot(*(similarity @ centre - centre[:2]))) * downscale
        out.append(moved_m / moved_px)
    return out


def screen_sheet(
    frames: list[tuple[str, U8Image]],
    density: list[npt.NDArray[np.float32]],
    out: Path,
    per_frame: int = 10,
    crop_px: int = 64,
) -> None:
    """A sheet of the ``per_frame`` strongest density peaks of each frame (``crop_px`` squares, 2x), a row per frame
    with its name, to screen the frames for people by eye. ``density``: (h, w) maps of the frames, any stride."""
    rows = []
    for (name, image), dmap in zip(frames, density, strict=True):
        h, w = image.shape[:2]
        sy, sx = h / dmap.shape[0], w / dmap.shape[1]
        work = cv2.GaussianBlur(dmap.astype(np.float32), (0, 0), 1.0)
        tiles = []
        for _ in range(per_frame):
            y, x = np.unravel_index(int(np.argmax(work)), work.shape)
            cy, cx = int((y + 0.5) * sy), int((x + 0.5) * sx)
            y0 = int(np.clip(cy - crop_px // 2, 0, h - crop_px))
            x0 = int(np.clip(cx - crop_px // 2, 0, w - crop_px))
            patch = image[y0 : y0 + crop_px, x0 : x0 + crop_px]
            tile = cv2.resize(patch, None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST)
            tiles.append(cv2.copyMakeBorder(tile, 2, 2, 2, 2, cv2.BORDER_CONSTANT, value=(255, 255, 255)))
            r = max(1, round(crop_px / (2 * sy)))
            work[max(0, y - r) : y + r + 1, max(0, x - r) : x + r + 1] = -np.inf
        row = np.hstack(tiles)
        label = np.full((24, row.shape[1], 3), 255, np.uint8)
        cv2.putText(label, name, (4, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1)
        rows.append(np.vstack([label, row]))
    cv2.imwrite(str(out), np.vstack(rows))


def main() -> int:
    parser = argparse.ArgumentParser(description="Derive a real site's ground frames into sitl/world/ground/<site>/.")
    parser.add_argument("--site", choices=sorted(SITES), required=True)
    parser.add_argument("--source", type=Path, required=True, help="the site's frames (see this module's docstring)")
    parser.add_argument("--out", type=Path, help="default sitl/world/ground/<site>")
    parser.add_argument("--people", action="append", default=[], metavar="NAME=WHERE", help="leave out a frame")
    parser.add_argument("--gsd", action="store_true", help="print the GPS estimate of the GSD and write nothing")
    parser.add_argument("--screen", type=Path, metavar="DIR", help="after deriving: screening sheets into DIR")
    parser.add_argument("--screen-model", type=Path, default=Path("models/density/slz_lite.onnx"))
    args = parser.parse_args()
    site = SITES[args.site]
    if args.gsd:
        estimates = gps_gsd_estimates(sorted(args.source.glob(site.pattern)))
        if not estimates:
            sys.stderr.write("error: no pair of consecutive GPS-tagged frames matched\n")
            return 2
        q1, median, q3 = np.percentile(estimates, [25, 50, 75])
        sys.stdout.write(f"{len(estimates)} pairs: median {median:.4f} m/px (interquartile {q1:.4f}-{q3:.4f})\n")
        return 0
    people = dict(spec.split("=", 1) for spec in args.people)
    index = prepare(site, args.source, args.out, people)
    frames = index["frames"]
    assert isinstance(frames, list)
    out_dir = args.out or GROUND_ROOT / site.name
    sys.stdout.write(f"wrote {len(frames)} frames of {site.name} to {out_dir}\n")
    if args.screen is not None:
        from companion.perception.density import OnnxDensityModel
        from models.eval.real import tiled_density  # the evaluation's own tiling: the maps it scores

        model = OnnxDensityModel(str(args.screen_model))
        args.screen.mkdir(parents=True, exist_ok=True)
        named = [(str(f["name"]), read_bgr(out_dir / f"{f['name']}.jpg")) for f in frames]
        for k in range(0, len(named), 7):
            chunk = named[k : k + 7]
            maps = [tiled_density(model, image).values for _, image in chunk]
            screen_sheet(chunk, maps, args.screen / f"screen_{site.name}_{k // 7}.png")
        sys.stdout.write(f"screening sheets in {args.screen}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
