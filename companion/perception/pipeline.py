"""The SLZ perception pipeline: frame + pose -> occupancy -> head plane -> zones -> tracks -> target.

Each stage is passed in the constructor, so the SITL, tests and the drone plug in their own parts (a fake
density model, another selection policy) without touching the rest.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

from companion.geometry import F64Array, GeometryError, PinholeCamera, Pose, T_body_camera_from_mount
from companion.perception.config import CameraConfig, PerceptionConfig
from companion.perception.density import (
    DensityMap,
    DensityModel,
    OnnxDensityModel,
    U8Image,
    check_frame,
    input_scale,
    predict_downscaled,
)
from companion.perception.errors import PerceptionError
from companion.perception.lens import LensDistortion
from companion.perception.motion_height import HeightMap, MotionHeight
from companion.perception.occupancy import OccupancyImage, OccupancyMapper
from companion.perception.projection import HeadPlaneOccupancy, HeadPlaneProjector
from companion.perception.selection import SelectionContext, SelectionPolicy, Target, make_policy
from companion.perception.tracking import TrackedZone, ZoneTracker
from companion.perception.zones import Zone, ZoneFinder

ResultT = TypeVar("ResultT")

STAGES = ("density", "occupancy", "projection", "zones", "tracking", "selection")
"""The stages every frame runs (with ``perception.motion_height.enabled``, also ``height``, after the density)."""


def camera_from_config(config: CameraConfig) -> tuple[PinholeCamera, F64Array]:
    """Intrinsics and ``T_body_camera`` (4, 4) described by a camera config."""
    if config.fx_px is not None and config.fy_px is not None:
        camera = PinholeCamera(
            config.width_px,
            config.height_px,
            config.fx_px,
            config.fy_px,
            config.cx_px if config.cx_px is not None else (config.width_px - 1) / 2.0,
            config.cy_px if config.cy_px is not None else (config.height_px - 1) / 2.0,
        )
    else:
        camera = PinholeCamera.from_hfov(config.width_px, config.height_px, config.hfov_deg)
    T_body_camera = T_body_camera_from_mount(config.tilt_deg, config.roll_deg, config.yaw_deg, config.offset_frd_m)
    return camera, T_body_camera


@dataclass(frozen=True)
class FrameResult:
    """Everything the pipeline computed for one frame.

    Attributes
    ----------
    t_s : float
        Capture time (vehicle clock, s).
    pose : Pose
        Vehicle pose at the capture time.
    density : DensityMap
        Network output.
    occupancy : OccupancyImage
        Thresholded and dilated occupancy in the density map's pixel grid.
    head_plane : HeadPlaneOccupancy
        Occupancy on the world grid.
    zones : list of Zone
        This frame's proposals, largest first.
    tracks : list of TrackedZone
        Live tracks after this frame.
    target : Target or None
        The selected landing target.
    timings_ms : dict
        Wall time of each stage (``STAGES``, and ``height`` when measured), milliseconds.
    height : HeightMap or None
        Height above the ground from the camera's motion (``perception.motion_height``), None when not measured.
    """

    t_s: float
    pose: Pose
    density: DensityMap
    occupancy: OccupancyImage
    head_plane: HeadPlaneOccupancy
    zones: list[Zone]
    tracks: list[TrackedZone]
    target: Target | None
    timings_ms: dict[str, float] = field(default_factory=dict)
    height: HeightMap | None = None


class SlzPipeline:
    """Runs the stages in order for each frame. See the module docstring."""

    def __init__(
        self,
        density_model: DensityModel,
        occupancy: OccupancyMapper,
        projector: HeadPlaneProjector,
        zone_finder: ZoneFinder,
        tracker: ZoneTracker,
        policy: SelectionPolicy,
        min_gsd_m_per_px: float = 0.0,
        lens: LensDistortion | None = None,
        motion_height: MotionHeight | None = None,
        fuse_height: bool = False,
    ) -> None:
        if not (math.isfinite(min_gsd_m_per_px) and min_gsd_m_per_px >= 0.0):
            raise PerceptionError("pipeline", f"min_gsd_m_per_px must be >= 0, got {min_gsd_m_per_px}")
        self.min_gsd_m_per_px = min_gsd_m_per_px
        self.density_model = density_model
        self.occupancy = occupancy
        self.projector = projector
        self.zone_finder = zone_finder
        self.tracker = tracker
        self.policy = policy
        self.lens = lens
        """The camera's lens: each frame is undistorted onto the pinhole image first (None: no lens)."""
        self.motion_height = motion_height
        """Height above the ground from the camera's motion, measured at every frame (None: not measured)."""
        self.fuse_height = fuse_height and motion_height is not None
        """Cells the height map finds standing above the ground or moving are occupied, whatever the density says."""

    @classmethod
    def from_config(
        cls,
        config: PerceptionConfig,
        density_model: DensityModel | None = None,
        fence_ne_m: Sequence[tuple[float, float]] | None = None,
    ) -> SlzPipeline:
        """Build every stage from one config; the ONNX model is loaded unless ``density_model`` is given.

        ``fence_ne_m``, the mission's geofence polygon (north_m, east_m), bounds the zones as the landing area does.
        """
        camera, T_body_camera = camera_from_config(config.camera)
        model = density_model or OnnxDensityModel.from_config(config.model)
        return cls(
            density_model=model,
            occupancy=OccupancyMapper(config.occupancy),
            projector=HeadPlaneProjector(camera, T_body_camera, config.projection),
            zone_finder=ZoneFinder(config.zones, fence_ne_m),
            tracker=ZoneTracker(config.tracking),
            policy=make_policy(config.selection, config.zones.landing_area_ne_m),
            min_gsd_m_per_px=config.model.min_gsd_m_per_px,
            lens=LensDistortion.from_coefficients(camera, config.camera.distortion),
            motion_height=MotionHeight(camera, T_body_camera, config.motion_height)
            if config.motion_height.enabled
            else None,
            fuse_height=config.motion_height.fuse,
        )

    def reset(self) -> None:
        """Start a new mission: no tracks, fresh policy state, no earlier frames."""
        self.tracker.reset()
        self.policy.reset()
        if self.motion_height is not None:
            self.motion_height.reset()

    def process(
        self, frame_bgr: U8Image, pose: Pose, t_s: float, area_centre_ne_m: tuple[float, float] | None = None
    ) -> FrameResult:
        """Run the whole pipeline on one frame.

        Parameters
        ----------
        frame_bgr : ndarray, shape (H, W, 3), uint8
            Camera frame (BGR), of the size given in the camera config.
        pose : Pose
            Vehicle pose interpolated at the frame's capture time.
        t_s : float
            Capture time on the vehicle's clock, seconds; must not decrease between calls.
        area_centre_ne_m : tuple of float, optional
            Centre of the mission's search area, for policies that use one.
        """
        frame_bgr = check_frame(frame_bgr, "pipeline.process")
        cam = self.projector.camera
        if frame_bgr.shape[:2] != (cam.height_px, cam.width_px):
            raise PerceptionError(
                "pipeline.process",
                f"frame is {frame_bgr.shape[1]}x{frame_bgr.shape[0]}, "
                f"camera config says {cam.width_px}x{cam.height_px}",
            )
        timings: dict[str, float] = {}
        lens = self.lens
        if lens is not None:
            frame_bgr = _timed(timings, "undistort", lambda: lens.undistort(frame_bgr))
        gsd = self.projector.finest_gsd_m_per_px(pose)
        scale = input_scale(gsd, self.min_gsd_m_per_px)
        density = _timed(timings, "density", lambda: predict_downscaled(self.density_model, frame_bgr, scale))
        height = None
        estimator = self.motion_height
        if estimator is not None:
            height = _timed(timings, "height", lambda: estimator.update(frame_bgr, pose, t_s))
        return self._after_density(density, pose, t_s, area_centre_ne_m, timings, gsd, height)

    def sees_head_plane(self, pose: Pose) -> bool:
        """A frame taken from ``pose`` can be read: the camera sees the head plane (the vehicle is high enough
        above it and not tilted past the horizon)."""
        try:
            self.projector.finest_gsd_m_per_px(pose)
        except (PerceptionError, GeometryError):
            return False
        return True

    def input_scale(self, pose: Pose) -> float:
        """How much the frame is shrunk before the model sees it at this pose (1: not at all).

        Below the altitude where the frame's finest ground sampling distance reaches ``min_gsd_m_per_px``, the
        frame is shrunk to that GSD (:func:`~companion.perception.density.predict_downscaled`): the model then sees
        the ground at a scale it was trained on, and the density map has coarser cells.
        """
        if self.min_gsd_m_per_px <= 0.0:
            return 1.0
        return input_scale(self.projector.finest_gsd_m_per_px(pose), self.min_gsd_m_per_px)

    def _after_density(
        self,
        density: DensityMap,
        pose: Pose,
        t_s: float,
        area_centre_ne_m: tuple[float, float] | None,
        timings: dict[str, float],
        gsd_m_per_px: float | None = None,
        height: HeightMap | None = None,
    ) -> FrameResult:
        projector = self.projector

        def occupancy_stage() -> OccupancyImage:
            gsd = projector.finest_gsd_m_per_px(pose) if gsd_m_per_px is None else gsd_m_per_px
            standing = height.resampled(density.values.shape) if height is not None and self.fuse_height else None
            return self.occupancy.compute(density, gsd, also_occupied=standing)

        occupancy = _timed(timings, "occupancy", occupancy_stage)
        density_camera = projector.camera.scaled(1.0 / density.stride_x, 1.0 / density.stride_y)
        head_plane = _timed(timings, "projection", lambda: projector.project(occupancy.values, density_camera, pose))
        zones = _timed(timings, "zones", lambda: self.zone_finder.find(head_plane))
        tracks = _timed(timings, "tracking", lambda: self.tracker.update(t_s, zones))
        position = pose.position_ned_m
        context = SelectionContext(t_s, float(position[0]), float(position[1]), area_centre_ne_m)
        target = _timed(timings, "selection", lambda: self.policy.select(tracks, context))
        return FrameResult(t_s, pose, density, occupancy, head_plane, zones, tracks, target, timings, height)


def _timed(timings: dict[str, float], stage: str, fn: Callable[[], ResultT]) -> ResultT:
    start = time.perf_counter()
    result = fn()
    timings[stage] = (time.perf_counter() - start) * 1e3
    return result
