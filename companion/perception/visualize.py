"""Drawing what the pipeline saw and decided onto the camera view (for demos, dry runs, reports, replays)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np
import numpy.typing as npt

from companion.geometry import F64Array, Pose
from companion.perception.pipeline import FrameResult
from companion.perception.projection import HeadPlaneProjector

U8Image = npt.NDArray[np.uint8]

ZONE_BGR = (255, 200, 0)
TARGET_BGR = (0, 255, 255)
OCCUPIED_BGR = (0, 0, 255)


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
