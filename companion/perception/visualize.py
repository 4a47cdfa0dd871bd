"""Drawing what the pipeline saw and decided: camera overlay and top view (for demos, dry runs, reports)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import cv2
import numpy as np
import numpy.typing as npt

from companion.geometry import F64Array, Pose
from companion.perception.pipeline import FrameResult
from companion.perception.projection import HeadPlaneProjector
from companion.perception.selection import Target
from companion.perception.tracking import TrackedZone

U8Image = npt.NDArray[np.uint8]
ToPixel = Callable[[float, float], tuple[int, int]]

ZONE_BGR = (255, 200, 0)
TARGET_BGR = (0, 255, 255)
OCCUPIED_BGR = (0, 0, 255)
PERSON_BGR = (255, 0, 255)


def _circle_points(north_m: float, east_m: float, radius_m: float, n: int = 48) -> F64Array:
    angles = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return np.column_stack([north_m + radius_m * np.cos(angles), east_m + radius_m * np.sin(angles)])


def draw_camera_overlay(frame_bgr: U8Image, result: FrameResult, projector: HeadPlaneProjector) -> U8Image:
    """The camera frame with occupied pixels tinted red, tracked zones (cyan, with ids) and the target (yellow).

    Parameters
    ----------
    frame_bgr : ndarray, shape (H, W, 3), uint8
        The frame the result was computed from.
    result : FrameResult
        The pipeline's output for that frame.
    projector : HeadPlaneProjector
        The pipeline's projector (zones are drawn by projecting their head-plane circles).
    """
    h, w = frame_bgr.shape[:2]
    occupied = cv2.resize(result.occupancy.values, (w, h), interpolation=cv2.INTER_NEAREST) == 0
    out: U8Image = frame_bgr.copy()
    tint = np.array(OCCUPIED_BGR, dtype=np.float32)
    out[occupied] = (0.55 * out[occupied] + 0.45 * tint).astype(np.uint8)

    zones = [(t.north_m, t.east_m, t.radius_m, t.track_id) for t in result.tracks]
    target = None if result.target is None else (result.target.north_m, result.target.east_m, result.target.radius_m)
    return draw_circles_overlay(out, result.pose, projector, zones, target)


def draw_circles_overlay(
    frame_bgr: U8Image,
    pose: Pose,
    projector: HeadPlaneProjector,
    zones: Sequence[tuple[float, float, float, int | None]],
    target: tuple[float, float, float] | None,
) -> U8Image:
    """Head-plane circles drawn into the camera view: zones (cyan, with their ids) and the target (yellow).

    Parameters
    ----------
    frame_bgr : ndarray, shape (H, W, 3), uint8
        The camera frame (not modified).
    pose : Pose
        The vehicle pose at the frame's capture time.
    projector : HeadPlaneProjector
        Projects head-plane points (north, east in m, world NED) into the image.
    zones : sequence of (north_m, east_m, radius_m, track_id)
        Tracked zones (``track_id`` None: no label).
    target : (north_m, east_m, radius_m) or None
        The selected target.
    """
    out: U8Image = frame_bgr.copy()

    def polyline(points_ne: F64Array, colour: tuple[int, int, int], thickness: int) -> None:
        pixels, ok = projector.plane_to_pixel(points_ne, pose)
        if ok.all():
            cv2.polylines(out, [np.round(pixels).astype(np.int32)], True, colour, thickness, cv2.LINE_AA)

    for north_m, east_m, radius_m, track_id in zones:
        polyline(_circle_points(north_m, east_m, radius_m), ZONE_BGR, 1)
        pixel, ok = projector.plane_to_pixel([[north_m, east_m]], pose)
        if ok[0] and track_id is not None:
            u, v = (round(c) for c in pixel[0])
            cv2.putText(out, str(track_id), (u - 4, v + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, ZONE_BGR, 1)
    if target is not None:
        north_m, east_m, radius_m = target
        polyline(_circle_points(north_m, east_m, max(radius_m, 0.3)), TARGET_BGR, 2)
    return out


def draw_top_view(
    result: FrameResult,
    people_ne_m: F64Array | None = None,
    people_radius_m: F64Array | None = None,
    size_px: int = 480,
) -> U8Image:
    """Top view of the head-plane grid, north up: free (light), occupied (dark), unknown (grey).

    Tracks are drawn in cyan, the target in yellow, and, when given, ground-truth people in magenta.
    """
    hp = result.head_plane
    img = np.full(hp.free.shape, 110, dtype=np.uint8)
    img[hp.known] = 40
    img[hp.free] = 235
    view: U8Image = np.asarray(cv2.cvtColor(np.flipud(img), cv2.COLOR_GRAY2BGR), dtype=np.uint8)
    scale = size_px / max(hp.grid.rows, hp.grid.cols)
    view = np.asarray(
        cv2.resize(view, (round(hp.grid.cols * scale), round(hp.grid.rows * scale)), interpolation=cv2.INTER_NEAREST),
        dtype=np.uint8,
    )
    px_per_m = scale / hp.grid.resolution_m

    def to_px(north_m: float, east_m: float) -> tuple[int, int]:
        row, col = hp.grid.world_to_cell(north_m, east_m)
        return round((col + 0.5) * scale), round((hp.grid.rows - row - 0.5) * scale)

    if people_ne_m is not None:
        radii = people_radius_m if people_radius_m is not None else np.full(len(people_ne_m), 0.25)
        for (n, e), r in zip(people_ne_m, radii, strict=True):
            cv2.circle(view, to_px(n, e), max(1, round(r * px_per_m)), PERSON_BGR, -1, cv2.LINE_AA)
    for track in result.tracks:
        _draw_zone(view, to_px, track, px_per_m)
    if result.target is not None:
        _draw_target(view, to_px, result.target, px_per_m)
    n, e = result.pose.position_ned_m[:2]
    cv2.drawMarker(view, to_px(float(n), float(e)), (0, 160, 0), cv2.MARKER_CROSS, 14, 2)
    return view


def _draw_zone(view: U8Image, to_px: ToPixel, track: TrackedZone, px_per_m: float) -> None:
    centre = to_px(track.north_m, track.east_m)
    cv2.circle(view, centre, max(1, round(track.radius_m * px_per_m)), ZONE_BGR, 1, cv2.LINE_AA)
    cv2.putText(view, str(track.track_id), centre, cv2.FONT_HERSHEY_SIMPLEX, 0.4, ZONE_BGR, 1)


def _draw_target(view: U8Image, to_px: ToPixel, target: Target, px_per_m: float) -> None:
    centre = to_px(target.north_m, target.east_m)
    cv2.circle(view, centre, max(3, round(target.radius_m * px_per_m)), TARGET_BGR, 2, cv2.LINE_AA)


def side_by_side(left: U8Image, right: U8Image) -> U8Image:
    """Two BGR images next to each other, the shorter padded at the bottom."""
    h = max(left.shape[0], right.shape[0])

    def pad(img: U8Image) -> U8Image:
        return np.asarray(
            cv2.copyMakeBorder(img, 0, h - img.shape[0], 0, 0, cv2.BORDER_CONSTANT, value=(0, 0, 0)), dtype=np.uint8
        )

    return np.hstack([pad(left), pad(right)])
