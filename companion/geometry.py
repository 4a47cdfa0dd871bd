"""Rigid transforms, attitudes, the pinhole camera, and polygons on the ground (north/east).

The shared geometry at the bottom of ``companion``: the vehicle link (poses), perception (projection), guidance
(polygons) and the lab's renderer use it; it imports nothing else of the project.

Frames (all right-handed)
-------------------------
world
    Local NED: x = north, y = east, z = down, metres, origin on the ground at the home position. This is
    MAVLink's ``MAV_FRAME_LOCAL_NED``. The ground is the plane ``down_m = 0``; the head plane is
    ``down_m = -head_height_m``.
body
    FRD: x = forward, y = right, z = down, at the vehicle's centre of mass.
camera
    OpenCV optical frame: x = image right, y = image down, z = optical axis (out of the lens).

A transform ``T_a_b`` is a 4x4 homogeneous matrix that maps coordinates of a point expressed in frame ``b`` to
frame ``a``: ``p_a = T_a_b @ p_b``. So ``T_world_camera = T_world_body @ T_body_camera``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from companion.errors import SlzError

F64Array = npt.NDArray[np.float64]


class GeometryError(SlzError, ValueError):
    """A geometric input is not what it claims (a zero quaternion, a degenerate camera): where, and what."""

    def __init__(self, where: str, what: str) -> None:
        super().__init__(f"{where}: {what}")
        self.where = where
        self.what = what


def rot_x(angle_rad: float) -> F64Array:
    """Rotation matrix (3, 3) about the x axis by ``angle_rad`` (right-hand rule)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle_rad: float) -> F64Array:
    """Rotation matrix (3, 3) about the y axis by ``angle_rad`` (right-hand rule)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle_rad: float) -> F64Array:
    """Rotation matrix (3, 3) about the z axis by ``angle_rad`` (right-hand rule)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def R_world_body_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> F64Array:
    """Attitude as a rotation matrix (3, 3) from aerospace Euler angles (MAVLink ``ATTITUDE``).

    ZYX convention: ``R_world_body = Rz(yaw) @ Ry(pitch) @ Rx(roll)``, world NED, body FRD. Yaw is measured
    from north towards east, pitch is nose up, roll is right wing down.
    """
    return rot_z(yaw_rad) @ rot_y(pitch_rad) @ rot_x(roll_rad)


def R_world_body_from_quaternion(q_wxyz: npt.ArrayLike) -> F64Array:
    """Attitude as a rotation matrix (3, 3) from a unit quaternion ``[w, x, y, z]`` (MAVLink order).

    The quaternion rotates body FRD to world NED, as in ``ATTITUDE_QUATERNION``. It is normalized here;
    a zero or non-finite quaternion raises :class:`GeometryError`.
    """
    q = np.asarray(q_wxyz, dtype=np.float64).reshape(4)
    norm = float(np.linalg.norm(q))
    if not math.isfinite(norm) or norm < 1e-9:
        raise GeometryError("geometry.quaternion", f"not a rotation quaternion: {q.tolist()}")
    w, x, y, z = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> F64Array:
    """Unit quaternion ``[w, x, y, z]`` (MAVLink order, body FRD to world NED) from ZYX Euler angles, by PX4's
    closed form (independent of :func:`R_world_body_from_euler`'s matrix product; a test checks they agree)."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def make_transform(R: npt.ArrayLike, t: npt.ArrayLike) -> F64Array:
    """Homogeneous transform (4, 4) from a rotation (3, 3) and a translation (3,)."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=np.float64)
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def invert_transform(T: F64Array) -> F64Array:
    """Inverse of a rigid homogeneous transform (4, 4), using ``R.T`` rather than a general inverse."""
    R = T[:3, :3]
    t = T[:3, 3]
    return make_transform(R.T, -R.T @ t)


@dataclass(frozen=True)
class Pose:
    """The vehicle's pose at one instant: ``T_world_body`` (4, 4), world NED, body FRD, metres.

    Build it with :meth:`from_ned_euler` or :meth:`from_ned_quaternion` from MAVLink telemetry.
    """

    T_world_body: F64Array

    @classmethod
    def from_ned_euler(
        cls,
        north_m: float,
        east_m: float,
        down_m: float,
        roll_rad: float = 0.0,
        pitch_rad: float = 0.0,
        yaw_rad: float = 0.0,
    ) -> Pose:
        """Pose from a local NED position (m) and ZYX Euler angles (rad)."""
        R = R_world_body_from_euler(roll_rad, pitch_rad, yaw_rad)
        return cls(make_transform(R, (north_m, east_m, down_m)))

    @classmethod
    def from_ned_quaternion(cls, north_m: float, east_m: float, down_m: float, q_wxyz: npt.ArrayLike) -> Pose:
        """Pose from a local NED position (m) and a ``[w, x, y, z]`` quaternion (body FRD to world NED)."""
        return cls(make_transform(R_world_body_from_quaternion(q_wxyz), (north_m, east_m, down_m)))

    @property
    def position_ned_m(self) -> F64Array:
        """Position (3,) of the body origin in world NED, metres."""
        return np.array(self.T_world_body[:3, 3], dtype=np.float64)

    @property
    def altitude_m(self) -> float:
        """Height above the ground plane (``-down_m``), metres."""
        return float(-self.T_world_body[2, 3])


@dataclass(frozen=True)
class PinholeCamera:
    """Intrinsics of an undistorted pinhole camera.

    Attributes
    ----------
    width_px, height_px : int
        Image size in pixels.
    fx_px, fy_px : float
        Focal lengths in pixels.
    cx_px, cy_px : float
        Principal point in pixels (OpenCV convention: the centre of the top-left pixel is (0, 0)).
    """

    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float

    @classmethod
    def from_hfov(cls, width_px: int, height_px: int, hfov_deg: float) -> PinholeCamera:
        """Square-pixel camera with its principal point at the image centre and horizontal FOV ``hfov_deg``."""
        f = 0.5 * width_px / math.tan(math.radians(hfov_deg) / 2.0)
        return cls(width_px, height_px, f, f, (width_px - 1) / 2.0, (height_px - 1) / 2.0)

    @property
    def K(self) -> F64Array:
        """Intrinsic matrix (3, 3)."""
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    def scaled(self, sx: float, sy: float) -> PinholeCamera:
        """The same camera seen through an image resized by ``sx`` horizontally and ``sy`` vertically.

        Pixel centres map as ``u' = (u + 0.5) * sx - 0.5``, so the principal point shifts accordingly.
        """
        return PinholeCamera(
            width_px=round(self.width_px * sx),
            height_px=round(self.height_px * sy),
            fx_px=self.fx_px * sx,
            fy_px=self.fy_px * sy,
            cx_px=(self.cx_px + 0.5) * sx - 0.5,
            cy_px=(self.cy_px + 0.5) * sy - 0.5,
        )


def T_body_camera_from_mount(
    tilt_deg: float = 0.0,
    roll_deg: float = 0.0,
    yaw_deg: float = 0.0,
    offset_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> F64Array:
    """Camera-to-body transform (4, 4) for a camera mounted under the vehicle.

    With all angles zero the camera looks straight down (nadir) with the top of the image towards the
    vehicle's nose: camera x = body right, camera y = body backward, camera z = body down.

    Parameters
    ----------
    tilt_deg : float
        Rotation of the optical axis from nadir towards the nose (0 = nadir, 90 = looking forward).
    roll_deg : float
        Rotation of the optical axis from nadir towards the right side, applied after the tilt.
    yaw_deg : float
        Rotation of the camera about its own optical axis (image rotation), applied first.
    offset_frd_m : tuple of float
        Position of the optical centre in the body FRD frame, metres.
    """
    R_nadir = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    R = rot_x(-math.radians(roll_deg)) @ rot_y(math.radians(tilt_deg)) @ R_nadir @ rot_z(math.radians(yaw_deg))
    return make_transform(R, offset_frd_m)


def polygon_signed_area_m2(polygon_ne_m: npt.ArrayLike) -> float:
    """Shoelace area (m^2) of a polygon given as vertices (K, 2) north/east m; the sign gives the direction."""
    poly = np.asarray(polygon_ne_m, np.float64)
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def polygon_centroid_ne_m(polygon_ne_m: npt.ArrayLike) -> tuple[float, float]:
    """Area centroid (north_m, east_m) of a simple polygon given as vertices (K, 2), in either direction.

    A polygon without area (all vertices on a line) gives the mean of its vertices.
    """
    poly = np.asarray(polygon_ne_m, np.float64)
    x, y = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area2 = float(cross.sum())  # twice the signed area
    if abs(area2) < 1e-12:
        return float(x.mean()), float(y.mean())
    return float(((x + x1) * cross).sum() / (3.0 * area2)), float(((y + y1) * cross).sum() / (3.0 * area2))


def inside_polygon(
    polygon_ne_m: npt.NDArray[np.float64], north_m: npt.ArrayLike, east_m: npt.ArrayLike
) -> npt.NDArray[np.bool_]:
    """Whether points lie inside a polygon, by the number of its edges they cross going east (odd: inside).

    Parameters
    ----------
    polygon_ne_m : ndarray, shape (K, 2)
        Vertices (north_m, east_m), in order (either direction); convex or not.
    north_m, east_m : array_like
        The points' coordinates (m), broadcast against each other.

    Returns
    -------
    ndarray of bool, the broadcast shape of ``north_m`` and ``east_m``
    """
    north = np.asarray(north_m, np.float64)[..., None]
    east = np.asarray(east_m, np.float64)
    n0, e0 = polygon_ne_m[:, 0], polygon_ne_m[:, 1]  # (K,)
    n1, e1 = np.roll(n0, -1), np.roll(e0, -1)
    # Where each edge crosses the east-west line through each point (half-open: a vertex counts once, an east-west
    # edge never): this depends on the north coordinate only, so a grid's rows are computed once, not per cell.
    crosses = (n0 <= north) != (n1 <= north)
    t = np.divide(north - n0, n1 - n0, out=np.zeros(crosses.shape), where=crosses)
    east_cross = np.where(crosses, e0 + t * (e1 - e0), -np.inf)
    # The parity of the crossings east of each point, one edge at a time (a (rows, cols) pass per edge, not a
    # (rows, cols, K) array counted along its last axis: the same answer, ten times faster on a perception grid).
    inside = np.zeros(np.broadcast_shapes(east_cross.shape[:-1], east.shape), dtype=bool)
    for k in range(east_cross.shape[-1]):
        inside ^= east_cross[..., k] > east
    return inside
