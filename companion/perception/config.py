"""Configuration of the SLZ perception pipeline: one validated model for every parameter.

Symbols in brackets are the paper's (safe-landing-paper.tex, section "SLZ algorithm").
"""

from __future__ import annotations

import enum
import math
import os
from pathlib import Path

import numpy as np
from pydantic import Field, model_validator

from companion.config import StrictModel, load_yaml_config
from companion.geometry import polygon_signed_area_m2


class SelectionPolicyName(str, enum.Enum):
    """How the landing target is chosen among the tracked zones."""

    BIGGEST = "biggest"
    """The tracked zone with the largest radius (paper)."""
    OLDEST = "oldest"
    """The tracked zone that has existed longest (paper)."""
    NEAREST = "nearest"
    """The tracked zone whose centre is closest to the vehicle, horizontally."""
    RANDOM = "random"
    """Blind baseline: a seeded random point of the search area, ignoring perception (paper's "random")."""


DEFAULT_MODEL_FILE = "slz_yolox.onnx"
"""The default density model's file in models/density/ (issue 63: YOLOX-nano's early layers fine-tuned on rendered
people and the real ground of three sites; models/density/MODEL_CARD.md)."""


def _shipped_model() -> Path:
    """models/density/slz_yolox.onnx of this installation (the repository, or a copy of it such as the Jetson's
    /opt/slz/src), absolute; relative to the working directory where the package is installed without it."""
    beside = Path(os.path.normpath(Path(__file__).absolute().parents[2] / "models" / "density" / DEFAULT_MODEL_FILE))
    return beside if beside.is_file() else Path("models/density") / DEFAULT_MODEL_FILE


SHIPPED_MODEL = _shipped_model()
"""The default density model."""


class ModelConfig(StrictModel):
    """The density model and how onnxruntime runs it."""

    path: Path = Field(
        default_factory=lambda: SHIPPED_MODEL,
        description="ONNX file; in a config file, a relative path is taken from the file's folder. Default: the "
        "shipped slz_yolox.onnx (models/density/ of this installation); slz_lite.onnx is the synthetic-only model of "
        "the first tables.",
    )
    providers: list[str] = Field(
        default_factory=lambda: ["CPUExecutionProvider"],
        min_length=1,
        description="onnxruntime execution providers in order of preference; unavailable ones are skipped "
        "(e.g. TensorrtExecutionProvider, CUDAExecutionProvider on a Jetson).",
    )
    intra_op_threads: int = Field(default=1, ge=0, le=64, description="0 lets onnxruntime choose.")
    min_gsd_m_per_px: float = Field(
        default=0.045,
        ge=0.0,
        le=1.0,
        description="Frames finer than this ground sampling distance (metres per pixel on the head plane: a low "
        "altitude) are shrunk to it before the model sees them, so that ground texture keeps the scale the model "
        "was trained on; 0 disables. 0.045 is the finest GSD of a nadir 90-degree 640 px camera at about 16 m "
        "(chosen on training-style frames, models/density/MODEL_CARD.md).",
    )
    engine_cache_dir: Path | None = Field(
        default=None,
        description="TensorRT: keep built engines (and the timing cache) here, on a persistent path, so only the "
        "first start after a model change pays the build (minutes on a Jetson). None: build at every start.",
    )
    fp16: bool = Field(
        default=True, description="TensorRT: allow FP16 kernels (Jetson GPUs run them at about twice the FP32 rate)."
    )
    require_real_imagery_validation: bool = Field(
        default=False,
        description="slz doctor fails (instead of warning) when the model is not validated for flight over real "
        "people (no shipped model is: companion/perception/model_validation.py). Set it on a vehicle that flies over "
        "people.",
    )
    crop_shrunk_frames: bool = Field(
        default=True,
        description="A frame shrunk for min_gsd_m_per_px runs through the model as itself plus the edge pixels its "
        "cells read, not padded to the model's full size: the same density map for a fraction of the work. Only on "
        "the CPU provider alone (a TensorRT engine is built per input shape) and for graphs whose receptive field "
        "can be read (fully convolutional); otherwise, or when false, frames are padded as before.",
    )


class OccupancyConfig(StrictModel):
    """Density map -> binary occupancy map in the image (paper: threshold, then dilate for safety)."""

    density_threshold: float = Field(
        default=0.01,
        gt=0.0,
        description="A density cell is occupied when its value (people per cell) reaches this.",
    )
    relative_threshold: float = Field(
        default=0.0,
        ge=0.0,
        le=1.0,
        description="Also require at least this fraction of the frame's maximum density (0 disables).",
    )
    dilation_m: float = Field(
        default=0.5,
        ge=0.0,
        le=10.0,
        description="Safety margin grown around occupied cells, metres on the head plane, converted to pixels "
        "with the frame's finest ground sampling distance.",
    )


class MotionHeightConfig(StrictModel):
    """Height above the ground from the camera's own motion (issue 64; ``companion.perception.motion_height``): the
    parallax of what stands on the ground between the newest frame and an earlier one taken from elsewhere."""

    enabled: bool = Field(
        default=False,
        description="Measure the height map at every frame (its cost: bench/motion_height.py) and record it.",
    )
    fuse: bool = Field(
        default=False,
        description="Cells measured to stand above the ground (or to move against it) are occupied, whatever the "
        "density says. Needs enabled.",
    )
    max_age_s: float = Field(
        default=2.0, gt=0.0, le=30.0, description="The earlier frame is at most this old (vehicle clock)."
    )
    target_parallax_px_per_m: float = Field(
        default=2.0,
        gt=0.0,
        le=100.0,
        description="The earlier frame is the newest one whose baseline shifts a point 1 m above the ground by at "
        "least this many pixels against the ground where the view shifts most (else the one that shifts it most).",
    )
    min_parallax_px_per_m: float = Field(
        default=0.5,
        gt=0.0,
        le=100.0,
        description="Below this (hovering, the walker gate) there is no usable baseline: the map is unknown, not "
        "flat. Where a baseline shifts only part of the view (a descent: not its centre), the rest is unknown too.",
    )
    plane_scale: float = Field(
        default=0.5,
        gt=0.05,
        le=1.0,
        description="Frames are shrunk by this before they are aligned on the ground (the poses' errors).",
    )
    min_ground_share: float = Field(
        default=0.3,
        ge=0.0,
        le=1.0,
        description="At least this share of the frame must move with the shift that aligns the two frames on the "
        "ground (within a pixel); less, they show no textured ground in common: the map is unknown.",
    )
    max_plane_correction_px: float = Field(
        default=48.0,
        gt=0.0,
        le=1000.0,
        description="The ground's homography fitted to the flow may move the image corners this far from the "
        "poses' (attitude and position errors); farther, the fitted plane is not the ground: the map is unknown.",
    )
    sweep_scale: float = Field(
        default=0.5, gt=0.05, le=1.0, description="Frames are shrunk by this before the plane sweep."
    )
    sweep_shifts_px: list[float] = Field(
        default_factory=lambda: [1.0, 2.0, 3.0, 4.0, 6.0, 9.0, 14.0, 20.0, 28.0],
        min_length=1,
        description="The planes swept above the ground: those whose points shift against the ground by these many "
        "full-frame pixels where the view shifts most (their heights follow from the baseline and the altitude).",
    )
    window_px: int = Field(default=3, ge=1, le=31, description="Side of the matching window, sweep pixels.")
    raised_m: float = Field(
        default=0.5,
        gt=0.0,
        le=20.0,
        description="A pixel stands above the ground when a plane at least this high explains it better than the "
        "ground (a cell, when enough of its pixels do); it is ground when the ground explains it better than every "
        "plane this high.",
    )
    min_gain: float = Field(
        default=2.0,
        gt=0.0,
        le=255.0,
        description="A plane explains a pixel better than another when its matching cost (mean absolute grey "
        "difference over the window) is lower by at least this, or k_noise times the frame's median best cost if "
        "more.",
    )
    k_noise: float = Field(default=1.0, gt=0.0, le=20.0, description="See min_gain.")
    registration_px: float = Field(
        default=0.5,
        ge=0.0,
        le=10.0,
        description="How far the ground may still be misaligned after the correction (full-frame pixels): a plane "
        "must also beat another by what that misalignment makes of the pixel's gradient (edges, shadows).",
    )
    k_moving: float = Field(
        default=4.0,
        gt=0.0,
        le=50.0,
        description="A pixel no plane explains (its best cost and the ground's at least this many times the gain "
        "threshold) moves against the ground: a walker.",
    )
    min_cell_share: float = Field(
        default=0.125,
        gt=0.0,
        le=1.0,
        description="A cell stands above the ground (or moves) when this share of its pixels do.",
    )

    @model_validator(mode="after")
    def _parallax_order(self) -> MotionHeightConfig:
        if self.min_parallax_px_per_m > self.target_parallax_px_per_m:
            raise ValueError(
                f"min_parallax_px_per_m ({self.min_parallax_px_per_m}) must be <= target_parallax_px_per_m "
                f"({self.target_parallax_px_per_m})"
            )
        if self.fuse and not self.enabled:
            raise ValueError("motion_height.fuse needs motion_height.enabled")
        if sorted(self.sweep_shifts_px) != self.sweep_shifts_px or self.sweep_shifts_px[0] <= 0:
            raise ValueError(f"sweep_shifts_px must be positive and increasing, got {self.sweep_shifts_px}")
        return self


class ProjectionConfig(StrictModel):
    """The world grid on the head plane that the occupancy map is projected onto."""

    head_height_m: float = Field(default=1.7, ge=0.0, le=3.0, description="Head plane height above ground [h_t].")
    grid_resolution_m: float = Field(default=0.1, gt=0.0, le=2.0, description="Side of one grid cell.")
    grid_extent_m: float = Field(default=40.0, gt=0.0, le=500.0, description="Side of the square grid.")
    min_depth_m: float = Field(
        default=0.5, gt=0.0, description="Head-plane points closer to the camera than this are unknown."
    )

    @model_validator(mode="after")
    def _grid_size(self) -> ProjectionConfig:
        cells = self.grid_extent_m / self.grid_resolution_m
        if not 8 <= cells <= 4096:
            raise ValueError(
                f"grid_extent_m / grid_resolution_m must give between 8 and 4096 cells per side (got {cells:.0f})"
            )
        return self


class ZoneConfig(StrictModel):
    """Largest-free-circle zone proposals (paper: distance transform, repeated N_p times)."""

    n_proposals: int = Field(default=10, ge=1, le=100, description="Maximum zones per frame [N_p].")
    vehicle_radius_m: float = Field(
        default=0.5, gt=0.0, le=10.0, description="Vehicle footprint radius including propellers."
    )
    margin_m: float = Field(default=0.5, ge=0.0, le=20.0, description="Extra clearance around the footprint.")
    landing_area_ne_m: list[tuple[float, float]] | None = Field(
        default=None,
        description="Vertices (north_m, east_m, world NED) of the only area zones may lie in, wholly; its edge "
        "bounds a zone as a person would. None: anywhere the camera sees (the geofence still applies).",
    )

    @model_validator(mode="after")
    def _area(self) -> ZoneConfig:
        if self.landing_area_ne_m is not None:
            polygon = np.asarray(self.landing_area_ne_m, np.float64)
            if len(polygon) < 3 or not np.isfinite(polygon).all():
                raise ValueError("landing_area_ne_m needs at least 3 finite vertices (north_m, east_m)")
            area_m2 = abs(polygon_signed_area_m2(polygon))
            if area_m2 < math.pi * self.min_radius_m**2:
                raise ValueError(
                    f"landing_area_ne_m encloses {area_m2:.2f} m^2, less than one zone of the minimum radius "
                    f"({self.min_radius_m} m: vehicle_radius_m + margin_m)"
                )
        return self

    @property
    def min_radius_m(self) -> float:
        """Zones smaller than the footprint plus margin are dropped."""
        return self.vehicle_radius_m + self.margin_m


class TrackingConfig(StrictModel):
    """Kalman tracking of zones with IoU/Hungarian association."""

    max_tracks: int = Field(default=5, ge=1, le=100, description="Maximum simultaneous trackers [M_p].")
    iou_threshold: float = Field(default=0.3, gt=0.0, le=1.0, description="Minimum circle IoU to associate [mu].")
    max_misses: int = Field(
        default=5, ge=1, le=1000, description="A track is deleted after this many consecutive misses [mu_1]."
    )
    sigma_a: float = Field(
        default=0.5,
        gt=0.0,
        le=100.0,
        description="Scale of the process noise Q, an acceleration variance in m^2/s^4 [sigma_a].",
    )
    measurement_std_position_m: float = Field(default=0.3, gt=0.0, le=10.0, description="R: centre noise.")
    measurement_std_radius_m: float = Field(default=0.3, gt=0.0, le=10.0, description="R: radius noise.")
    initial_std_velocity_mps: float = Field(
        default=1.0, gt=0.0, le=100.0, description="Initial standard deviation of a new track's rates."
    )


class SelectionConfig(StrictModel):
    """Which tracked zone becomes the landing target."""

    policy: SelectionPolicyName = SelectionPolicyName.OLDEST
    seed: int = Field(default=0, ge=0, description="Seed of the random policy.")
    random_half_extent_m: float = Field(
        default=15.0,
        gt=0.0,
        le=500.0,
        description="The random policy draws its point in a square of this half side around the search area's "
        "centre (the flight app gives the geofence's centroid; the vehicle's position when none is given): 15 m "
        "gives the paper's 30 m x 30 m ROI around the SITL park's centre.",
    )


class CameraConfig(StrictModel):
    """Pinhole intrinsics and the camera's mounting on the body."""

    width_px: int = Field(default=640, ge=16, le=8192)
    height_px: int = Field(default=480, ge=16, le=8192)
    hfov_deg: float = Field(default=90.0, gt=1.0, lt=179.0, description="Used when fx/fy are not given.")
    fx_px: float | None = Field(default=None, gt=0.0)
    fy_px: float | None = Field(default=None, gt=0.0)
    cx_px: float | None = None
    cy_px: float | None = None
    tilt_deg: float = Field(default=0.0, ge=-90.0, le=90.0, description="0 = nadir, positive towards the nose.")
    roll_deg: float = Field(default=0.0, ge=-90.0, le=90.0, description="Positive towards the right side.")
    yaw_deg: float = Field(default=0.0, ge=-180.0, le=180.0, description="Image rotation about the optical axis.")
    offset_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    distortion: list[float] = Field(
        default_factory=list,
        description="OpenCV's lens distortion coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]]), "
        "as cv2.calibrateCamera gives them (scripts/calibrate_camera.py): each frame is undistorted onto the pinhole "
        "image of these intrinsics first. Empty or all zero: no lens (frames untouched).",
    )

    @model_validator(mode="after")
    def _focal_pair(self) -> CameraConfig:
        if (self.fx_px is None) != (self.fy_px is None):
            raise ValueError("fx_px and fy_px must be given together (or neither, to use hfov_deg)")
        if len(self.distortion) not in (0, 4, 5, 8, 12, 14):
            raise ValueError(
                f"distortion: {len(self.distortion)} coefficients; OpenCV's model takes 4, 5, 8, 12 or 14 (or none)"
            )
        return self


class PerceptionConfig(StrictModel):
    """Every parameter of the SLZ perception pipeline, with documented defaults."""

    camera: CameraConfig = Field(default_factory=CameraConfig)
    model: ModelConfig = Field(default_factory=ModelConfig)
    occupancy: OccupancyConfig = Field(default_factory=OccupancyConfig)
    projection: ProjectionConfig = Field(default_factory=ProjectionConfig)
    zones: ZoneConfig = Field(default_factory=ZoneConfig)
    tracking: TrackingConfig = Field(default_factory=TrackingConfig)
    selection: SelectionConfig = Field(default_factory=SelectionConfig)
    motion_height: MotionHeightConfig = Field(default_factory=MotionHeightConfig)

    @model_validator(mode="after")
    def _tracks_vs_proposals(self) -> PerceptionConfig:
        if self.tracking.max_tracks > self.zones.n_proposals:
            raise ValueError(
                f"tracking.max_tracks [M_p] must be <= zones.n_proposals [N_p] "
                f"(got M_p={self.tracking.max_tracks}, N_p={self.zones.n_proposals})"
            )
        return self


MODEL_PATH_FIELDS = (("model", "path"), ("model", "engine_cache_dir"))
"""The paths of a ``perception`` section, taken from the config file's folder when relative."""


def load_perception_config(path: str | Path, section: str | None = "perception") -> PerceptionConfig:
    """Load the ``perception`` section of a mission config YAML file (or the whole file if ``section=None``); its
    relative paths are taken from the file's folder."""
    return load_yaml_config(PerceptionConfig, path, section=section, path_fields=MODEL_PATH_FIELDS)
