"""``slz height-map A B --out DIR``: the height above the ground of what two overlapping photographs of a site show.

A field engineer checks the geometry on frames of their own site before flying over it (issue 64): two nadir
photographs taken from two positions (a mapping flight's consecutive frames, two stills from a hover 10-20 m apart),
and the same motion parallax the companion measures in flight (:mod:`companion.perception.motion_height`) says what
stands above the ground: trees, cars, buildings, people, and that lawn and asphalt are flat.

Without the vehicle's poses the geometry comes from the photographs: the ground's homography from matched features
(SIFT, RANSAC: the dominant plane), the focal length from EXIF (the focal length and the focal plane's resolution, or
the 35 mm equivalent) or ``--hfov-deg``, the baseline from their EXIF GPS positions or ``--baseline-m``, and the height
above the ground ``--altitude-m`` (EXIF's GPS altitude is above the sea). With only one of the baseline and the
altitude, the other follows from how far the ground moved between the two (a nadir camera over flat ground). Both
cameras are taken as nadir; the homography takes out what they turned and tilted between the shots.

Writes into ``DIR``: ``height_m.npy`` (float32, metres, NaN unknown; one cell per 4 pixels of the working frame),
``above_ground.png`` (255 where a cell stands above the ground or moves), ``overlay.png`` (A with the map drawn over
it: red above the ground, magenta moving or inconsistent, green measured flat, untouched unknown) and
``summary.json``.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from companion.errors import SlzError
from companion.json_value import JsonObject
from companion.perception.config import MotionHeightConfig
from companion.perception.motion_height import CELL_PX, HeightMap, HeightState

U8Image = npt.NDArray[np.uint8]

EXIF_IFD = 0x8769
GPS_IFD = 0x8825
DIAGONAL_35MM = math.hypot(36.0, 24.0)
HEIGHT_BANDS_M = ((0.5, 1.0), (1.0, 2.0), (2.0, 5.0), (5.0, 10.0), (10.0, math.inf))


class HeightPairError(SlzError):
    """Two photographs whose geometry cannot be worked out (which one, and what is missing)."""


@dataclass(frozen=True)
class PhotoMeta:
    """What a photograph's EXIF says of its geometry (None where it does not)."""

    focal_px: float | None
    focal_source: str
    latitude_deg: float | None
    longitude_deg: float | None


def photo_meta(path: Path, width_px: int) -> PhotoMeta:
    """The focal length (pixels of a frame ``width_px`` wide) and the GPS position from EXIF, where present.

    The focal length from ``FocalLength`` and ``FocalPlaneXResolution`` (pixels per mm, cm or inch of the sensor),
    else from ``FocalLengthIn35mmFilm`` (over the 35 mm frame's diagonal). Needs Pillow (the ``report`` extra);
    without it nothing is read."""
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - Pillow comes with matplotlib, which the report extra brings
        return PhotoMeta(None, "no EXIF reader (Pillow)", None, None)
    with Image.open(path) as image:
        exif = image.getexif()
        size = image.size
        sub = exif.get_ifd(EXIF_IFD)
        gps = exif.get_ifd(GPS_IFD)
    scale = width_px / size[0]
    focal_px, source = None, "none in EXIF"
    focal_mm, plane_res, unit = sub.get(0x920A), sub.get(0xA20E), sub.get(0xA210)
    units_mm = {2: 25.4, 3: 10.0, 4: 1.0}
    if focal_mm and plane_res and unit in units_mm:
        focal_px = float(focal_mm) * float(plane_res) / units_mm[int(unit)] * scale
        source = "EXIF focal length and focal plane resolution"
    elif sub.get(0xA405):
        focal_px = float(sub[0xA405]) / DIAGONAL_35MM * math.hypot(*size) * scale
        source = "EXIF 35 mm equivalent focal length"

    def degrees(value: Any, ref: Any, negative: str) -> float | None:
        if not value:
            return None
        d = float(sum(float(x) / 60**i for i, x in enumerate(value)))
        return -d if str(ref).upper().startswith(negative) else d

    lat = degrees(gps.get(2), gps.get(1), "S")
    lon = degrees(gps.get(4), gps.get(3), "W")
    return PhotoMeta(focal_px, source, lat, lon)


def gps_baseline_m(a: PhotoMeta, b: PhotoMeta) -> float | None:
    """The horizontal distance between two GPS positions (equirectangular, metres), None without both."""
    if None in (a.latitude_deg, a.longitude_deg, b.latitude_deg, b.longitude_deg):
        return None
    assert a.latitude_deg is not None
    assert b.latitude_deg is not None
    assert a.longitude_deg is not None
    assert b.longitude_deg is not None
    north = (b.latitude_deg - a.latitude_deg) * 111_320.0
    east = (b.longitude_deg - a.longitude_deg) * 111_320.0 * math.cos(math.radians(a.latitude_deg))
    return math.hypot(north, east)


def ground_homography(a: U8Image, b: U8Image, planes: int = 3) -> tuple[npt.NDArray[np.float64], float]:
    """The ground's homography from ``a``'s pixels to ``b``'s and the share of matched features that fit it.

    SIFT features, the ratio test, then up to ``planes`` planes by RANSAC, each from the matches the ones before left
    over (a forest's canopy, roofs and the ground each fit their own): the ground is the plane that moved least at
    the image's centre, the farthest from a camera that moved across it. A plane needs 15 % of the matches."""
    cv2.setRNGSeed(0)
    sift = cv2.SIFT_create(4000)  # type: ignore[attr-defined]  # in OpenCV's main module since 4.4
    ka, da = sift.detectAndCompute(a, None)
    kb, db = sift.detectAndCompute(b, None)
    if da is None or db is None or len(ka) < 20 or len(kb) < 20:
        raise HeightPairError("too few features in the photographs to match them")
    pairs = cv2.BFMatcher().knnMatch(da, db, k=2)
    good = [m for m, n in (p for p in pairs if len(p) == 2) if m.distance < 0.75 * n.distance]
    if len(good) < 20:
        raise HeightPairError(f"the photographs do not overlap enough: {len(good)} matched features")
    pa = np.array([ka[m.queryIdx].pt for m in good], np.float32)
    pb = np.array([kb[m.trainIdx].pt for m in good], np.float32)
    h, w = a.shape[:2]
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0, 1.0])
    left = np.ones(len(good), bool)
    found: list[tuple[float, npt.NDArray[np.float64], float]] = []
    for _ in range(planes):
        if left.sum() < max(20, 0.15 * len(good)):
            break
        H, inliers = cv2.findHomography(
            pa[left], pb[left], cv2.RANSAC, ransacReprojThreshold=2.0, maxIters=5000, confidence=0.999
        )
        if H is None or inliers is None or inliers.sum() < 0.15 * len(good):
            break
        moved = H @ centre
        found.append((float(np.hypot(*(moved[:2] / moved[2] - centre[:2]))), np.asarray(H, np.float64), 0.0))
        share = float(inliers.sum()) / len(good)
        found[-1] = (found[-1][0], found[-1][1], share)
        idx = np.flatnonzero(left)
        left[idx[inliers.ravel().astype(bool)]] = False
    if not found:
        raise HeightPairError("no plane fits the matched features")
    _, H, share = min(found, key=lambda f: f[0])
    return H, share


@dataclass(frozen=True)
class PairGeometry:
    """How the two photographs were taken, as worked out (metres, pixels of the working frame)."""

    width_px: int
    height_px: int
    focal_px: float
    focal_source: str
    altitude_m: float
    altitude_source: str
    baseline_m: float
    baseline_source: str
    ground_shift_px: float
    plane_inliers: float


def pair_geometry(
    a: U8Image,
    b: U8Image,
    meta_a: PhotoMeta,
    meta_b: PhotoMeta,
    H: npt.NDArray[np.float64],
    inliers: float,
    altitude_m: float | None,
    baseline_m: float | None,
    hfov_deg: float | None,
) -> PairGeometry:
    """The focal length, altitude and baseline of a pair (see the module docstring for where each comes from)."""
    h, w = a.shape[:2]
    if hfov_deg is not None:
        focal_px, focal_source = 0.5 * w / math.tan(math.radians(hfov_deg) / 2.0), "--hfov-deg"
    elif meta_a.focal_px is not None:
        focal_px, focal_source = meta_a.focal_px, meta_a.focal_source
    else:
        raise HeightPairError("no focal length: the first photograph's EXIF has none, give --hfov-deg")
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0, 1.0])
    moved = H @ centre
    shift_px = float(np.hypot(*(moved[:2] / moved[2] - centre[:2])))
    b_source = "--baseline-m"
    if baseline_m is None:
        baseline_m, b_source = gps_baseline_m(meta_a, meta_b), "EXIF GPS"
    a_source = "--altitude-m"
    if altitude_m is None:
        if baseline_m is None:
            raise HeightPairError("neither the altitude nor the baseline is known: give --altitude-m or --baseline-m")
        if shift_px < 5.0:
            raise HeightPairError(f"the ground moved {shift_px:.1f} px between the photographs: no baseline to measure")
        altitude_m, a_source = focal_px * baseline_m / shift_px, "from the baseline and the ground's shift"
    if baseline_m is None:
        baseline_m, b_source = shift_px * altitude_m / focal_px, "from the altitude and the ground's shift"
    if not (altitude_m > 0 and baseline_m > 0):
        raise HeightPairError(f"altitude {altitude_m} m and baseline {baseline_m} m must be positive")
    return PairGeometry(
        w, h, focal_px, focal_source, altitude_m, a_source, baseline_m, b_source, shift_px, round(inliers, 3)
    )


LOCAL_GROUND_PX = 160
"""Side (working pixels) of the window over which the ground's own residual motion is taken as smooth: what a single
homography leaves on real ground (the lens's distortion, a slope) varies over hundreds of pixels, what stands on the
ground over a few."""
MIN_PARALLAX_PX = 1.0
"""A cell's parallax must exceed the flow's disagreement by this many pixels to count."""


def pair_height_map(
    a: U8Image, b: U8Image, geometry: PairGeometry, H: npt.NDArray[np.float64], config: MotionHeightConfig
) -> HeightMap:
    """The height map of photograph ``a`` (grey, the working frame) against ``b``, both taken as nadir.

    ``b`` is brought onto ``a`` through the ground's homography ``H``; the dense optical flow between them (DIS,
    forward and backward) is what the homography left: the ground's own smooth residual (the lens's distortion, a
    slope; a median over :data:`LOCAL_GROUND_PX`), and the parallax of what stands on the ground. A point ``h`` above
    the ground moves ``|s| * h / (D - h)`` further along the ground's shift ``s`` (``D`` the altitude): its height is
    ``D * p / (|s| + p)`` for a parallax ``p`` along ``s``. Motion across ``s`` or against it (past ``mover`` pixels)
    is moving or inconsistent."""
    h_px, w_px = a.shape
    warped = cv2.warpPerspective(b, H, (w_px, h_px), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    covered = cv2.warpPerspective(
        np.full_like(b, 255), H, (w_px, h_px), flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP, borderValue=0
    )
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)  # type: ignore[attr-defined]
    forward = dis.calc(a, warped, None)
    backward = dis.calc(warped, a, None)
    xs, ys = np.meshgrid(np.arange(w_px, dtype=np.float32), np.arange(h_px, dtype=np.float32))
    back = cv2.remap(backward, xs + forward[..., 0], ys + forward[..., 1], cv2.INTER_LINEAR, borderValue=np.nan)
    fb = np.hypot(forward[..., 0] + back[..., 0], forward[..., 1] + back[..., 1])
    valid = (covered == 255) & np.isfinite(fb) & (fb <= 2.0)
    centre = np.array([(w_px - 1) / 2.0, (h_px - 1) / 2.0, 1.0])
    moved = H @ centre
    s = moved[:2] / moved[2] - centre[:2]  # the ground's shift from a to b, working pixels
    s_len = max(float(np.hypot(*s)), 1e-6)
    along = (forward[..., 0] * s[0] + forward[..., 1] * s[1]) / s_len
    across = (forward[..., 0] * s[1] - forward[..., 1] * s[0]) / s_len
    # The ground's own residual, smooth: what stands on the ground moves further along s than the ground under it,
    # so the ground is the low part of the motion along s (its 20th percentile over a window), the middle across.
    step = 8
    k = max(3, (LOCAL_GROUND_PX // step) | 1)
    pad = k // 2
    levels = []
    for values, q in ((along, 50.0), (across, 50.0)):
        grid = np.where(valid, values, np.nan)[::step, ::step]
        windows = np.lib.stride_tricks.sliding_window_view(np.pad(grid, pad, mode="edge"), (k, k))
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a window with no valid flow: no ground level there
            level = np.nanpercentile(windows.reshape(*windows.shape[:2], -1), q, axis=-1)
        levels.append(cv2.resize(np.nan_to_num(level, nan=0.0).astype(np.float32), (w_px, h_px)))
    along = along - levels[0]
    across = np.abs(across - levels[1])
    with np.errstate(invalid="ignore", divide="ignore"):
        height = geometry.altitude_m * along / (s_len + along)
    sigma_px = 0.5 * fb + MIN_PARALLAX_PX
    raised = valid & (along >= sigma_px) & (height >= config.raised_m)
    moving = valid & ~raised & ((across >= config.k_moving * sigma_px) | (along <= -config.k_moving * sigma_px))
    flat = valid & ~raised & ~moving & (np.abs(along) < sigma_px)
    shape = (h_px // CELL_PX, w_px // CELL_PX)
    cell = (shape[1], shape[0])

    def share(mask: npt.NDArray[np.bool_]) -> npt.NDArray[np.float32]:
        return np.asarray(cv2.resize(mask.astype(np.float32), cell, interpolation=cv2.INTER_AREA))

    state = np.full(shape, HeightState.UNKNOWN, np.uint8)
    state[share(flat) >= 0.5] = HeightState.GROUND
    state[share(moving) >= 0.5] = HeightState.MOVING
    state[share(raised) >= 0.5] = HeightState.RAISED
    h_cells = cv2.resize(np.where(valid, height, 0.0).astype(np.float32), cell, interpolation=cv2.INTER_AREA)
    with np.errstate(invalid="ignore", divide="ignore"):
        h_cells = h_cells / share(valid)
    known = state != HeightState.UNKNOWN
    per_m = s_len / geometry.altitude_m  # parallax per metre near the ground
    return HeightMap(
        np.where(known, h_cells, np.nan).astype(np.float32),
        np.where(known, np.float32(1.0 / per_m), np.nan).astype(np.float32),
        state,
        CELL_PX,
        geometry.baseline_m,
        per_m,
        0.0,
        "" if bool(valid.any()) else "the photographs show no ground in common",
    )


def summary(height: HeightMap, geometry: PairGeometry) -> JsonObject:
    """What the map says, in keys that say what they hold."""
    state = height.state
    raised = state == HeightState.RAISED
    heights = np.nan_to_num(height.height_m, nan=-1.0)
    return {
        "share_of_frame_above_ground": round(float(height.not_ground.mean()), 4),
        "share_of_frame_standing": round(float(raised.mean()), 4),
        "share_of_frame_moving_or_inconsistent": round(float((state == HeightState.MOVING).mean()), 4),
        "share_of_frame_measured_flat": round(float((state == HeightState.GROUND).mean()), 4),
        "share_of_frame_unknown": round(float((state == HeightState.UNKNOWN).mean()), 4),
        "share_of_frame_standing_by_height_band_m": {
            f"{lo:g}-{hi:g}" if math.isfinite(hi) else f">{lo:g}": round(
                float((raised & (heights >= lo) & (heights < hi)).mean()), 4
            )
            for lo, hi in HEIGHT_BANDS_M
        },
        "parallax_px_per_m_at_centre": round(height.parallax_px_per_m, 3),
        "unknown_because": height.reason or None,
        "cell_px": CELL_PX,
        "geometry": asdict(geometry),
    }


def overlay(image_bgr: U8Image, height: HeightMap) -> U8Image:
    """``image_bgr`` with the map over it: red standing, magenta moving or inconsistent, green measured flat."""
    h, w = image_bgr.shape[:2]
    state = cv2.resize(height.state, (w, h), interpolation=cv2.INTER_NEAREST)
    out = image_bgr.astype(np.float32)
    for value, colour, alpha in (
        (HeightState.GROUND, (0, 200, 0), 0.25),
        (HeightState.RAISED, (0, 0, 255), 0.55),
        (HeightState.MOVING, (255, 0, 255), 0.55),
    ):
        mask = state == value
        out[mask] = (1 - alpha) * out[mask] + alpha * np.array(colour, np.float32)
    return np.clip(out, 0, 255).astype(np.uint8)


def read_frame(path: Path, width_px: int) -> U8Image:
    """A photograph (BGR), resized to ``width_px`` wide."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise HeightPairError(f"{path}: not a readable image")
    scale = width_px / image.shape[1]
    size = (width_px, round(image.shape[0] * scale))
    return np.asarray(cv2.resize(image, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_CUBIC))


def run(
    path_a: Path,
    path_b: Path,
    out: Path,
    altitude_m: float | None = None,
    baseline_m: float | None = None,
    hfov_deg: float | None = None,
    width_px: int = 1280,
    config: MotionHeightConfig | None = None,
) -> dict[str, Any]:
    """The whole tool: read, work out the geometry, measure, write ``out``; returns the summary."""
    a_bgr, b_bgr = read_frame(path_a, width_px), read_frame(path_b, width_px)
    if a_bgr.shape != b_bgr.shape:
        raise HeightPairError(f"the photographs differ in shape: {a_bgr.shape[:2]} and {b_bgr.shape[:2]}")
    a = np.asarray(cv2.cvtColor(a_bgr, cv2.COLOR_BGR2GRAY), np.uint8)
    b = np.asarray(cv2.cvtColor(b_bgr, cv2.COLOR_BGR2GRAY), np.uint8)
    H, inliers = ground_homography(a, b)
    meta_a, meta_b = photo_meta(path_a, width_px), photo_meta(path_b, width_px)
    geometry = pair_geometry(a, b, meta_a, meta_b, H, inliers, altitude_m, baseline_m, hfov_deg)
    config = config or MotionHeightConfig(enabled=True)
    height = pair_height_map(a, b, geometry, H, config)
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "height_m.npy", height.height_m)
    cv2.imwrite(str(out / "above_ground.png"), np.where(height.not_ground, 255, 0).astype(np.uint8))
    cv2.imwrite(str(out / "overlay.png"), overlay(a_bgr, height))
    result = {"photograph": str(path_a), "against": str(path_b)} | summary(height, geometry)
    (out / "summary.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    return result
