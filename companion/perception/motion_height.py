"""Height above the ground from the camera's own motion (issue 64): motion parallax between two frames.

A standing person, a car, a bin or a tree stands above the ground, and the vehicle moves: seen from two positions, a
point at height ``h`` shifts against the ground under it by about ``f * b * h / (D * (D - h))`` pixels (focal length
``f`` px, baseline ``b`` m across the line of sight, camera ``D`` m above the ground). At 20 m with the 640 px camera
(``f`` = 320 px) two frames 2 m apart shift a 1.7 m head by 3 px; dense optical flow resolves a fraction of that. No
training data is involved: the cue holds on ground of any kind, in any light.

Per frame (:func:`height_map`), between the newest frame and an earlier one (:class:`MotionHeight` keeps the recent
frames and chooses the earlier one for its baseline):

1. **Flow**: dense optical flow (OpenCV's DIS) from the newest frame to the earlier one and back, at
   ``flow_scale``; where the two disagree by more than ``max_fb_error_px`` (occlusions, no texture) a cell is unknown,
   and their disagreement is part of its uncertainty.
2. **The ground's homography**: the poses at capture time (world NED, the vehicle's clock) give the ground plane's
   homography between the two frames; a homography fitted to the flow (RANSAC, robust to what stands on the ground)
   corrects it for the poses' attitude and position errors. A fit that moves the image more than
   ``max_plane_correction_px`` from the poses' is not the ground (a canopy filling the view, say): the map is unknown.
3. **Height**: each cell's flow, so corrected, is triangulated against the ray of the newest frame with the poses'
   baseline: its height above the ground (the plane ``down_m = 0``), and its uncertainty from the baseline, the
   altitude and the flow's own consistency. A rigid point must move along one line (its epipolar line); a cell that
   leaves it by more than ``mover_px``, or lies confidently below the ground, moves against the ground (a walker).

Each cell of the map (the density map's grid: stride 4 of the frame) is :class:`HeightState` ``UNKNOWN`` (no usable
baseline, as when hovering or at the walker gate: unknown, never flat), ``GROUND``, ``RAISED`` or ``MOVING``. Times
are vehicle-clock seconds, positions world NED metres.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from companion.geometry import F64Array, PinholeCamera, Pose, invert_transform
from companion.perception.config import MotionHeightConfig
from companion.perception.errors import PerceptionError
from companion.perception.projection import plane_homography

F32Array = npt.NDArray[np.float32]
U8Array = npt.NDArray[np.uint8]
BoolArray = npt.NDArray[np.bool_]

CELL_PX = 4
"""Side of one cell of the height map in frame pixels (the density map's stride)."""
PLANE_SAMPLE_STEP = 2
"""Every this many cells, in each direction, one correspondence for the ground's homography fit."""


class HeightState(enum.IntEnum):
    """What a cell of the height map says about the ground there."""

    UNKNOWN = 0
    """No usable measurement: no baseline, no texture, occluded, or too uncertain."""
    GROUND = 1
    """Measured, confidently below ``raised_m``: the ground, or something flat on it."""
    RAISED = 2
    """Measured, confidently at least ``raised_m`` above the ground: a person, a car, a bin, a post, a tree."""
    MOVING = 3
    """Moves against the ground (off its epipolar line, or below the ground): not ground, a walker."""


@dataclass(frozen=True)
class HeightMap:
    """Height above the ground of every cell of a frame, measured from the camera's motion.

    Attributes
    ----------
    height_m : ndarray, shape (rows, cols), float32
        Height above the ground plane of what the cell sees, metres (NaN where unknown).
    sigma_m : ndarray, shape (rows, cols), float32
        Its one-sigma uncertainty, metres (NaN where unknown).
    state : ndarray, shape (rows, cols), uint8
        :class:`HeightState` of each cell.
    cell_px : int
        Side of a cell in frame pixels.
    baseline_m : float
        Distance between the two camera positions, metres (0 with no earlier frame).
    parallax_px_per_m : float
        How many pixels a point 1 m above the ground at the image centre shifts against the ground between the two
        frames: the usable baseline.
    dt_s : float
        Time between the two frames, seconds.
    reason : str
        Why the map is wholly unknown, or "" when it measured.
    """

    height_m: F32Array
    sigma_m: F32Array
    state: U8Array
    cell_px: int
    baseline_m: float
    parallax_px_per_m: float
    dt_s: float
    reason: str = ""
    heights: F64Array | None = None  # the heights swept, metres (None: nothing was swept)

    @property
    def not_ground(self) -> BoolArray:
        """Cells measured to stand above the ground or to move against it (what fusion makes occupied)."""
        return np.isin(self.state, (HeightState.RAISED, HeightState.MOVING))

    def share(self, state: HeightState) -> float:
        """The share of the map's cells in ``state``."""
        return float((self.state == state).mean())

    def resampled(self, shape: tuple[int, int]) -> BoolArray:
        """:attr:`not_ground` on another grid over the same frame (``shape`` rows, cols): a cell there is not ground
        when any part of it is (area resampling, so a coarser grid keeps every raised cell)."""
        if shape == self.state.shape:
            return self.not_ground
        mask = self.not_ground.astype(np.float32)
        return np.asarray(cv2.resize(mask, (shape[1], shape[0]), interpolation=cv2.INTER_AREA) > 1e-6)


def unknown_map(shape: tuple[int, int], reason: str, baseline_m: float = 0.0, parallax: float = 0.0) -> HeightMap:
    """A map that knows nothing (``shape`` rows, cols), and why."""
    nan = np.full(shape, np.nan, np.float32)
    state = np.full(shape, HeightState.UNKNOWN, np.uint8)
    return HeightMap(nan, nan.copy(), state, CELL_PX, baseline_m, parallax, 0.0, reason)


def grid_shape(camera: PinholeCamera) -> tuple[int, int]:
    """(rows, cols) of the height map of a frame of ``camera``."""
    return camera.height_px // CELL_PX, camera.width_px // CELL_PX


def parallax_px_per_m(
    camera: PinholeCamera, T_world_camera_new: F64Array, T_world_camera_old: F64Array, height_m: float = 1.0
) -> float:
    """How many pixels of the earlier frame a point ``height_m`` above the ground is away from the ground point on
    the same ray of the newest frame, per metre of height, where the view shifts most (its centre or the midpoint
    of an edge: a horizontal baseline shifts the whole view, a vertical one only away from the centre): the
    baseline's use for this cue (0 without one)."""
    origin = T_world_camera_new[:3, 3]
    if origin[2] >= -height_m:  # below that height
        return 0.0
    w, h = camera.width_px - 1.0, camera.height_px - 1.0
    pixels = np.array([[camera.cx_px, camera.cy_px], [0.0, h / 2], [w, h / 2], [w / 2, 0.0], [w / 2, h]])
    rays = (np.column_stack([pixels, np.ones(len(pixels))]) @ np.linalg.inv(camera.K).T) @ T_world_camera_new[:3, :3].T
    T_camera_world = invert_transform(T_world_camera_old)
    best = 0.0
    for ray in rays:
        if ray[2] <= 1e-9:  # looking up
            continue
        seen = []
        for down_m in (0.0, -height_m):
            point = origin + ray * (down_m - origin[2]) / ray[2]
            p_cam = T_camera_world[:3, :3] @ point + T_camera_world[:3, 3]
            if p_cam[2] <= 1e-6:
                break
            seen.append((camera.K @ p_cam)[:2] / p_cam[2])
        if len(seen) == 2:
            best = max(best, float(np.hypot(*(seen[1] - seen[0]))) / height_m)
    return best


class FlowField:
    """Dense optical flow and its forward-backward disagreement (OpenCV's DIS, fast preset), for the ground's fit."""

    def __init__(self) -> None:
        self._dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_FAST)  # type: ignore[attr-defined]

    def forward(self, new_grey: U8Array, old_grey: U8Array) -> F32Array:
        """The flow (h, w, 2) that takes each pixel of ``new_grey`` to where it is in ``old_grey``."""
        return np.asarray(self._dis.calc(new_grey, old_grey, None), np.float32)

    def between(self, new_grey: U8Array, old_grey: U8Array) -> tuple[F32Array, F32Array]:
        """``(flow, fb_error)``: ``flow`` (h, w, 2) takes each pixel of ``new_grey`` to where it is in ``old_grey``;
        ``fb_error`` (h, w) the length of forward plus backward flow there (NaN where it leaves the frame)."""
        forward = self._dis.calc(new_grey, old_grey, None)
        backward = self._dis.calc(old_grey, new_grey, None)
        h, w = new_grey.shape
        xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        map_x, map_y = xs + forward[..., 0], ys + forward[..., 1]
        back = cv2.remap(backward, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
        error = np.hypot(forward[..., 0] + back[..., 0], forward[..., 1] + back[..., 1]).astype(np.float32)
        return np.asarray(forward, np.float32), error


def _ground_homography(
    new_grey: U8Array,
    old_grey: U8Array,
    camera: PinholeCamera,
    H_pose: F64Array,
    config: MotionHeightConfig,
    flow: FlowField,
) -> tuple[F64Array | None, str]:
    """The ground's homography (newest frame's pixels -> the earlier frame's, full frame): the poses', corrected by
    the shift that aligns the two frames on the ground (the attitude's errors move a nadir image as a whole): the
    median of the optical flow between the newest frame and the earlier one brought onto it through the poses' ground
    (at ``plane_scale``), robust to what stands or walks on the ground. None and why where too little of the frame
    moves with that shift (no texture, or no ground in common), or the shift exceeds ``max_plane_correction_px``."""
    s = config.plane_scale
    size = (round(camera.width_px * s), round(camera.height_px * s))
    to_small = np.array([[s, 0.0, 0.5 * s - 0.5], [0.0, s, 0.5 * s - 0.5], [0.0, 0.0, 1.0]])
    small_new = cv2.resize(new_grey, size, interpolation=cv2.INTER_AREA)
    small_old = cv2.resize(old_grey, size, interpolation=cv2.INTER_AREA)
    aligned = cv2.warpPerspective(
        small_old,
        to_small @ H_pose @ np.linalg.inv(to_small),
        size,
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_REFLECT,
    )
    field = flow.forward(np.asarray(small_new, np.uint8), np.asarray(aligned, np.uint8))
    margin = max(1, size[1] // 12)
    inner = field[margin:-margin:2, margin:-margin:2].reshape(-1, 2)
    shift_small = np.median(inner, axis=0)
    agreeing = float((np.hypot(*(inner - shift_small).T) <= 1.0).mean())
    if agreeing < config.min_ground_share:
        return None, f"the frames do not align on the ground ({agreeing:.0%} of the flow agrees)"
    shift = shift_small / s  # where the newest frame's ground lies on the aligned earlier one, full pixels
    if float(np.hypot(*shift)) > config.max_plane_correction_px:
        return None, "the plane the frames align on is not the poses' ground"
    return np.asarray(H_pose @ np.array([[1.0, 0.0, shift[0]], [0.0, 1.0, shift[1]], [0.0, 0.0, 1.0]])), ""


def sweep_heights_m(parallax_px_per_m: float, altitude_m: float, config: MotionHeightConfig) -> F64Array:
    """The heights of the swept planes: the ground, then planes whose points shift against the ground by
    ``config.sweep_shifts_px`` (full-frame pixels) where the view shifts most, up to ``altitude_m - 2`` m (``D`` above
    the ground: a point at height ``h`` shifts by about ``P * h * D / (D - h)`` for ``P`` pixels per metre at the
    ground)."""
    top = altitude_m - 2.0
    heights = [0.0]
    for shift in config.sweep_shifts_px:
        ratio = shift / (parallax_px_per_m * altitude_m)  # h / (D - h)
        h = altitude_m * ratio / (1.0 + ratio)
        if h > top:
            break
        if h > heights[-1] + 0.05:
            heights.append(h)
    return np.asarray(heights, np.float64)


def height_map(
    new_grey: U8Array,
    old_grey: U8Array,
    camera: PinholeCamera,
    T_world_camera_new: F64Array,
    T_world_camera_old: F64Array,
    config: MotionHeightConfig,
    flow: FlowField | None = None,
    dt_s: float = 0.0,
    ground: F64Array | None = None,
    heights_m: F64Array | None = None,
) -> HeightMap:
    """The height map of the newest frame against an earlier one (see the module docstring).

    Parameters
    ----------
    new_grey, old_grey : ndarray, shape (h, w), uint8
        The two frames, grey, full size (``camera``'s).
    camera : PinholeCamera
        The full frame's intrinsics (undistorted).
    T_world_camera_new, T_world_camera_old : ndarray, shape (4, 4)
        The camera's pose (world NED) at each frame's capture time.
    config : MotionHeightConfig
        Thresholds.
    flow : FlowField, optional
        A flow computer to reuse.
    dt_s : float
        Time between the frames, for the record.
    ground : ndarray, shape (3, 3), optional
        The ground's homography (newest frame's pixels -> the earlier frame's) where it is known otherwise (matched
        features of two photographs without poses): used instead of the poses' corrected by the flow.
    heights_m : ndarray, optional
        The heights to sweep instead of those of ``config.sweep_shifts_px`` (the ground first, increasing).
    """
    shape = grid_shape(camera)
    baseline_m = float(np.linalg.norm(T_world_camera_new[:3, 3] - T_world_camera_old[:3, 3]))
    parallax = parallax_px_per_m(camera, T_world_camera_new, T_world_camera_old)
    if parallax < config.min_parallax_px_per_m:
        why = f"no usable baseline: {parallax:.2f} px per metre of height (need {config.min_parallax_px_per_m:g})"
        return unknown_map(shape, why, baseline_m, parallax)
    H_new0 = plane_homography(camera.K, T_world_camera_new, 0.0)
    H_pose = plane_homography(camera.K, T_world_camera_old, 0.0) @ np.linalg.inv(H_new0)
    H_ground = ground
    if H_ground is None:
        H_ground, why = _ground_homography(new_grey, old_grey, camera, H_pose, config, flow or FlowField())
        if H_ground is None:
            return unknown_map(shape, why, baseline_m, parallax)
    correction = H_ground @ np.linalg.inv(H_pose)  # the poses' errors, as the ground shows them in the earlier frame

    # Sweep: the earlier frame brought onto the newest through planes at heights above the ground; each pixel's
    # matching cost (sum of absolute differences over a window) at each plane.
    altitude_m = -float(T_world_camera_new[2, 3])
    heights = sweep_heights_m(parallax, altitude_m, config) if heights_m is None else np.asarray(heights_m, np.float64)
    s = config.sweep_scale
    size = (round(camera.width_px * s), round(camera.height_px * s))
    to_small = np.array([[s, 0.0, 0.5 * s - 0.5], [0.0, s, 0.5 * s - 0.5], [0.0, 0.0, 1.0]])
    from_small = np.linalg.inv(to_small)
    new_small = new_grey if s == 1.0 else np.asarray(cv2.resize(new_grey, size, interpolation=cv2.INTER_AREA))
    old_small = old_grey if s == 1.0 else np.asarray(cv2.resize(old_grey, size, interpolation=cv2.INTER_AREA))
    window = (config.window_px, config.window_px)
    first_raised = int(np.searchsorted(heights, config.raised_m))
    shape_small = (size[1], size[0])
    c_ground = c_best = c_raised = np.full(shape_small, np.inf, np.float32)
    best = np.zeros(shape_small, np.int32)
    everywhere = np.full(shape_small, 255, np.uint8)
    covered: npt.NDArray[np.uint8] = everywhere
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    for k, h in enumerate(heights):
        H_new = plane_homography(camera.K, T_world_camera_new, h)
        H_h = to_small @ correction @ plane_homography(camera.K, T_world_camera_old, h) @ np.linalg.inv(H_new)
        H_h = H_h @ from_small
        warped = cv2.warpPerspective(old_small, H_h, size, flags=flags, borderMode=cv2.BORDER_REPLICATE)
        if k in (0, len(heights) - 1):  # what the earlier frame covers: the ground's and the highest plane's views
            inside = cv2.warpPerspective(everywhere, H_h, size, flags=flags, borderMode=cv2.BORDER_CONSTANT)
            covered = np.asarray(cv2.min(covered, inside), np.uint8)
        cost = cv2.blur(cv2.absdiff(new_small, warped), window, borderType=cv2.BORDER_REFLECT).astype(np.float32)
        if k == 0:
            c_ground, c_best = cost, cost.copy()
            continue
        better = cost < c_best
        c_best = np.where(better, cost, c_best)
        best[better] = k
        if k >= first_raised:
            c_raised = np.minimum(c_raised, cost)
    seen = covered == 255
    # What a plane must beat another by: the frame's noise, and what the residual misregistration of the ground
    # (``registration_px``) makes of this pixel's gradient.
    dx = cv2.Sobel(new_small, cv2.CV_16S, 1, 0, ksize=1)
    dy = cv2.Sobel(new_small, cv2.CV_16S, 0, 1, ksize=1)
    gradient = cv2.blur(cv2.add(cv2.convertScaleAbs(dx, alpha=0.5), cv2.convertScaleAbs(dy, alpha=0.5)), window)
    sample = c_best[::4, ::4][seen[::4, ::4]]
    noise = float(np.median(sample)) if sample.size else 0.0
    tau = max(config.min_gain, config.k_noise * noise) + config.registration_px * s * gradient.astype(np.float32)
    h_best = heights[best]
    if first_raised < len(heights):
        raised_px = seen & (h_best >= config.raised_m) & (c_ground - c_best >= tau)
        ground_px = seen & (h_best < config.raised_m) & (c_raised - c_ground >= tau)
    else:  # no plane reaches raised_m here: nothing can be shown to stand that high
        raised_px = np.zeros(best.shape, bool)
        ground_px = np.zeros(best.shape, bool)
    moving_px = seen & (c_best >= config.k_moving * tau)
    # Cells of the height map (CELL_PX of the frame): raised or moving where enough of their pixels are, ground
    # where most are and none stands.
    rows, cols = shape
    cell = (cols, rows)
    raised_share = cv2.resize(raised_px.astype(np.float32), cell, interpolation=cv2.INTER_AREA)
    moving_share = cv2.resize((moving_px & ~raised_px).astype(np.float32), cell, interpolation=cv2.INTER_AREA)
    ground_share = cv2.resize(ground_px.astype(np.float32), cell, interpolation=cv2.INTER_AREA)
    h_px = np.where(raised_px | ground_px, h_best, np.nan).astype(np.float32)
    h_cells = cv2.resize(np.nan_to_num(h_px, nan=0.0), cell, interpolation=cv2.INTER_AREA)
    known_share = cv2.resize((raised_px | ground_px).astype(np.float32), cell, interpolation=cv2.INTER_AREA)
    with np.errstate(invalid="ignore", divide="ignore"):
        h_cells = h_cells / known_share
    min_share = config.min_cell_share
    state = np.full(shape, HeightState.UNKNOWN, np.uint8)
    state[ground_share >= 0.5] = HeightState.GROUND
    state[moving_share >= min_share] = HeightState.MOVING
    state[raised_share >= min_share] = HeightState.RAISED
    # One plane's spacing is the height's resolution: half of it as one sigma, at the cell's height.
    spacing = np.diff(heights).min() if len(heights) > 1 else math.inf
    sigma = np.full(shape, 0.5 * spacing, np.float32)
    known = state != HeightState.UNKNOWN
    return HeightMap(
        np.where(known, h_cells, np.nan).astype(np.float32),
        np.where(known, sigma, np.nan).astype(np.float32),
        state,
        CELL_PX,
        baseline_m,
        parallax,
        dt_s,
        heights=heights,
    )


@dataclass(frozen=True)
class _Kept:
    t_s: float
    T_world_camera: F64Array
    grey: U8Array


class MotionHeight:
    """The height map of each frame against the best earlier frame of the last ``max_age_s`` (kept here, grey, at
    ``flow_scale``). Frames must come in capture-time order (vehicle clock), as the pipeline gives them.

    Parameters
    ----------
    camera : PinholeCamera
        The full frame's intrinsics.
    T_body_camera : ndarray, shape (4, 4)
        The camera's mounting.
    config : MotionHeightConfig
        Thresholds and the baseline's choice.
    """

    def __init__(self, camera: PinholeCamera, T_body_camera: F64Array, config: MotionHeightConfig) -> None:
        self.camera = camera
        self.T_body_camera = T_body_camera
        self.config = config
        self._kept: deque[_Kept] = deque()
        self._flow = FlowField()

    def reset(self) -> None:
        """Forget the earlier frames (a new mission)."""
        self._kept.clear()

    @staticmethod
    def grey(frame_bgr: U8Array) -> U8Array:
        """A frame as this keeps it: grey, full size."""
        return np.asarray(cv2.cvtColor(frame_bgr, cv2.COLOR_BGR2GRAY), np.uint8)

    def update(self, frame_bgr: U8Array, pose: Pose, t_s: float) -> HeightMap:
        """The height map of this frame (full size, BGR, undistorted) taken from ``pose`` at ``t_s``; keeps it."""
        if self._kept and t_s < self._kept[-1].t_s:
            raise PerceptionError("motion_height", f"frames out of order: {t_s:.3f} s after {self._kept[-1].t_s:.3f} s")
        T_wc = pose.T_world_body @ self.T_body_camera
        grey = self.grey(frame_bgr)
        while self._kept and t_s - self._kept[0].t_s > self.config.max_age_s:
            self._kept.popleft()
        earlier = self._choose(T_wc)
        self._kept.append(_Kept(t_s, T_wc, grey))
        if earlier is None:
            return unknown_map(grid_shape(self.camera), "no earlier frame")
        return height_map(
            grey, earlier.grey, self.camera, T_wc, earlier.T_world_camera, self.config, self._flow, t_s - earlier.t_s
        )

    def _choose(self, T_world_camera: F64Array) -> _Kept | None:
        """The newest kept frame whose baseline reaches ``target_parallax_px_per_m``, else the one with the most."""
        best, best_parallax = None, -math.inf
        for kept in reversed(self._kept):
            parallax = parallax_px_per_m(self.camera, T_world_camera, kept.T_world_camera)
            if parallax >= self.config.target_parallax_px_per_m:
                return kept
            if parallax > best_parallax:
                best, best_parallax = kept, parallax
        return best
