"""Projection of the image occupancy map onto a world grid on the head plane (paper, Eq. 1).

The head plane is the horizontal plane ``down_m = -head_height_m`` of the world NED frame. A point on it,
``(north_m, east_m)``, maps to the image through the plane-induced homography
``lambda * [u, v, 1]^T = K @ [r1, r2, -h * r3 + t] @ [north_m, east_m, 1]^T`` where ``[r1 r2 r3 | t]`` is
``T_camera_world``. Its third row is the point's depth along the optical axis, which tells points in front of
the camera from points behind it: only the former can be seen.

Grid convention: cell ``(row, col)`` has its centre at
``north_m = north_min_m + (row + 0.5) * resolution_m`` and ``east_m = east_min_m + (col + 0.5) * resolution_m``
(row grows northwards, col eastwards). Draw it with ``np.flipud`` to put north up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from companion.geometry import F64Array, PinholeCamera, Pose, invert_transform
from companion.perception.config import ProjectionConfig
from companion.perception.errors import PerceptionError

BoolArray = npt.NDArray[np.bool_]
U8Array = npt.NDArray[np.uint8]

FREE = 255
"""Occupancy value of a free cell (paper: 255 free, 0 crowded)."""
OCCUPIED = 0


def plane_homography(K: F64Array, T_world_camera: F64Array, plane_height_m: float) -> F64Array:
    """Homography (3, 3) from ``[north_m, east_m, 1]`` on the plane ``down_m = -plane_height_m`` to pixels.

    Parameters
    ----------
    K : ndarray, shape (3, 3)
        Camera intrinsics.
    T_world_camera : ndarray, shape (4, 4)
        Camera pose in world NED.
    plane_height_m : float
        Height of the horizontal plane above the ground.

    Returns
    -------
    ndarray, shape (3, 3)
        ``H`` such that ``H @ [north_m, east_m, 1]`` is ``depth * [u, v, 1]``, depth along the optical axis.
    """
    T_camera_world = invert_transform(T_world_camera)
    R, t = T_camera_world[:3, :3], T_camera_world[:3, 3]
    return K @ np.column_stack([R[:, 0], R[:, 1], -plane_height_m * R[:, 2] + t])


@dataclass(frozen=True)
class GridSpec:
    """A square-celled grid on the head plane, axis-aligned with north and east."""

    north_min_m: float
    east_min_m: float
    resolution_m: float
    rows: int
    cols: int

    @property
    def north_centres_m(self) -> F64Array:
        """North coordinate (rows,) of each row's cell centres."""
        return np.asarray(self.north_min_m + (np.arange(self.rows) + 0.5) * self.resolution_m, dtype=np.float64)

    @property
    def east_centres_m(self) -> F64Array:
        """East coordinate (cols,) of each column's cell centres."""
        return np.asarray(self.east_min_m + (np.arange(self.cols) + 0.5) * self.resolution_m, dtype=np.float64)

    def cell_to_world(self, row: float, col: float) -> tuple[float, float]:
        """(north_m, east_m) of a (fractional) cell position."""
        return (
            self.north_min_m + (row + 0.5) * self.resolution_m,
            self.east_min_m + (col + 0.5) * self.resolution_m,
        )

    def world_to_cell(self, north_m: float, east_m: float) -> tuple[float, float]:
        """Fractional (row, col) of a head-plane point."""
        return (
            (north_m - self.north_min_m) / self.resolution_m - 0.5,
            (east_m - self.east_min_m) / self.resolution_m - 0.5,
        )


@dataclass(frozen=True)
class HeadPlaneOccupancy:
    """The occupancy map resampled onto the head-plane grid.

    Attributes
    ----------
    grid : GridSpec
        Where the cells are.
    free : ndarray, shape (rows, cols), bool
        True where the camera saw the cell and it is free of people (with the safety dilation).
    known : ndarray, shape (rows, cols), bool
        True where the cell is in front of the camera and inside the image. Unknown cells are never free.
    """

    grid: GridSpec
    free: BoolArray
    known: BoolArray


class HeadPlaneProjector:
    """Maps between image pixels and the head plane for one camera on one vehicle.

    Parameters
    ----------
    camera : PinholeCamera
        Intrinsics of the full-resolution camera frame.
    T_body_camera : ndarray, shape (4, 4)
        Camera-to-body transform (body FRD, camera optical frame).
    config : ProjectionConfig
        Head height, grid resolution and extent, minimum depth.
    """

    def __init__(self, camera: PinholeCamera, T_body_camera: F64Array, config: ProjectionConfig) -> None:
        self.camera = camera
        self.T_body_camera = np.asarray(T_body_camera, dtype=np.float64)
        self.config = config
        self._cells = round(config.grid_extent_m / config.grid_resolution_m)

    def T_world_camera(self, pose: Pose) -> F64Array:
        """Camera pose (4, 4) in world NED."""
        return pose.T_world_body @ self.T_body_camera

    def homography(self, pose: Pose, camera: PinholeCamera | None = None) -> F64Array:
        """Homography (3, 3) from head-plane ``[north_m, east_m, 1]`` to homogeneous pixels of ``camera``.

        The third component of the result is the depth (m) of the point along the optical axis.
        """
        cam = camera or self.camera
        return plane_homography(cam.K, self.T_world_camera(pose), self.config.head_height_m)

    def plane_to_pixel(self, points_ne_m: npt.ArrayLike, pose: Pose) -> tuple[F64Array, BoolArray]:
        """Project head-plane points to pixels of the full-resolution frame.

        Parameters
        ----------
        points_ne_m : array_like, shape (N, 2)
            (north_m, east_m) on the head plane.
        pose : Pose
            Vehicle pose at the frame's capture time.

        Returns
        -------
        pixels : ndarray, shape (N, 2)
            (u, v) pixel coordinates; meaningless where ``in_front`` is False.
        in_front : ndarray, shape (N,), bool
            True where the point is at least ``min_depth_m`` in front of the camera.
        """
        pts = np.asarray(points_ne_m, dtype=np.float64).reshape(-1, 2)
        h = np.column_stack([pts, np.ones(len(pts))]) @ self.homography(pose).T
        in_front = h[:, 2] >= self.config.min_depth_m
        with np.errstate(divide="ignore", invalid="ignore"):
            pixels = h[:, :2] / h[:, 2:3]
        return pixels, in_front

    def pixel_to_plane(self, pixels_uv: npt.ArrayLike, pose: Pose) -> tuple[F64Array, BoolArray]:
        """Intersect pixel rays with the head plane.

        Parameters
        ----------
        pixels_uv : array_like, shape (N, 2)
            (u, v) pixel coordinates of the full-resolution frame.
        pose : Pose
            Vehicle pose at the frame's capture time.

        Returns
        -------
        points_ne_m : ndarray, shape (N, 2)
            (north_m, east_m) where each ray meets the head plane; meaningless where ``hits`` is False.
        hits : ndarray, shape (N,), bool
            True where the ray meets the plane at least ``min_depth_m`` in front of the camera.
        """
        uv = np.asarray(pixels_uv, dtype=np.float64).reshape(-1, 2)
        T_wc = self.T_world_camera(pose)
        rays_cam = np.column_stack([uv, np.ones(len(uv))]) @ np.linalg.inv(self.camera.K).T  # z = 1 depth units
        rays_world = rays_cam @ T_wc[:3, :3].T
        origin = T_wc[:3, 3]
        plane_down_m = -self.config.head_height_m
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = (plane_down_m - origin[2]) / rays_world[:, 2]  # ray parameter == depth along optical axis
        hits = np.isfinite(depth) & (depth >= self.config.min_depth_m)
        points = origin[:2] + depth[:, None] * rays_world[:, :2]
        return points, hits

    def grid_for(self, pose: Pose) -> GridSpec:
        """The grid for a frame: centred where the optical axis meets the head plane, snapped to cells.

        When the axis misses the plane (camera above the horizon) or meets it further than half the grid
        extent from the vehicle, the centre is pulled back towards the point below the vehicle.
        """
        res = self.config.grid_resolution_m
        half = self.config.grid_extent_m / 2.0
        vehicle_ne = pose.position_ned_m[:2]
        centre_ne = vehicle_ne
        axis_point, hit = self.pixel_to_plane([[self.camera.cx_px, self.camera.cy_px]], pose)
        if bool(hit[0]):
            offset = axis_point[0] - vehicle_ne
            dist = float(np.hypot(*offset))
            centre_ne = vehicle_ne + offset * min(1.0, half / dist) if dist > 0 else vehicle_ne
        north_min = math.floor((centre_ne[0] - half) / res) * res
        east_min = math.floor((centre_ne[1] - half) / res) * res
        return GridSpec(north_min, east_min, res, self._cells, self._cells)

    def finest_gsd_m_per_px(self, pose: Pose) -> float:
        """The smallest ground sampling distance (m per pixel) on the head plane over the visible image.

        Sampled at the image corners, edge midpoints and centre; the depth along the optical axis divided by
        the focal length gives a pixel's size on a plane facing the camera, a lower bound elsewhere. Using the
        finest value makes a dilation in pixels at least as wide, in metres, as asked everywhere in the frame.
        """
        cam = self.camera
        us = [0.0, (cam.width_px - 1) / 2.0, cam.width_px - 1.0]
        vs = [0.0, (cam.height_px - 1) / 2.0, cam.height_px - 1.0]
        uv = np.array([(u, v) for u in us for v in vs])
        points, hits = self.pixel_to_plane(uv, pose)
        if not hits.any():
            raise PerceptionError("projection.gsd", "the head plane is not visible from this pose")
        T_camera_world = invert_transform(self.T_world_camera(pose))
        p_world = np.column_stack([points[hits], np.full(int(hits.sum()), -self.config.head_height_m)])
        depth = p_world @ T_camera_world[:3, :3].T + T_camera_world[:3, 3]
        return float(depth[:, 2].min() / max(cam.fx_px, cam.fy_px))

    def project(self, occupancy_image: U8Array, image_camera: PinholeCamera, pose: Pose) -> HeadPlaneOccupancy:
        """Resample an image-space occupancy map onto the head-plane grid.

        Parameters
        ----------
        occupancy_image : ndarray, shape (h, w), uint8
            255 free, 0 occupied, in the pixel grid of ``image_camera``.
        image_camera : PinholeCamera
            Intrinsics matching ``occupancy_image`` (the frame's camera scaled to the density map).
        pose : Pose
            Vehicle pose at the frame's capture time.

        Returns
        -------
        HeadPlaneOccupancy
            A cell is free only where bilinear sampling finds nothing but free pixels; cells outside the image
            or behind the camera are unknown and not free.
        """
        if occupancy_image.dtype != np.uint8 or occupancy_image.ndim != 2:
            raise PerceptionError(
                "projection.project",
                f"occupancy image must be 2-D uint8, got {occupancy_image.shape} {occupancy_image.dtype}",
            )
        grid = self.grid_for(pose)
        res = grid.resolution_m
        # Grid (col, row) -> head plane (north, east) -> image pixel: one homography. warpPerspective with
        # WARP_INVERSE_MAP is cv2.remap with that homography's map, computed inside OpenCV.
        grid_to_plane = np.array(
            [[0.0, res, grid.north_min_m + 0.5 * res], [res, 0.0, grid.east_min_m + 0.5 * res], [0.0, 0.0, 1.0]]
        )
        M = self.homography(pose, image_camera) @ grid_to_plane
        size = (grid.cols, grid.rows)
        flags = cv2.WARP_INVERSE_MAP
        sampled = cv2.warpPerspective(
            occupancy_image,
            M,
            size,
            flags=flags | cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=OCCUPIED,
        )
        inside = cv2.warpPerspective(
            np.ones_like(occupancy_image), M, size, flags=flags | cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT
        )
        # The homography's third row is the depth: cells behind the camera would map to mirrored pixels.
        depth = (
            M[2, 0] * np.arange(grid.cols, dtype=np.float32)[None, :]
            + M[2, 1] * np.arange(grid.rows, dtype=np.float32)[:, None]
            + np.float32(M[2, 2])
        )
        known = (depth >= np.float32(self.config.min_depth_m)) & (inside > 0)
        return HeadPlaneOccupancy(grid=grid, free=(sampled == FREE) & known, known=known)
