"""The mission config of ``slz fly``: one validated object from ``mission_configs/<name>.yaml``.

Switching between the SITL and a real drone is a change of ``vehicle.url`` and ``camera.url`` here, never of code.
"""

from __future__ import annotations

import enum
import math
from pathlib import Path
from typing import TYPE_CHECKING

from pydantic import Field, ValidationError, field_validator, model_validator

from companion.app.live_view_config import LiveViewConfig
from companion.config import ConfigError, StrictModel, format_validation_error, host_port, load_yaml_config
from companion.ground.config import GroundStationConfig
from companion.guidance.config import GuidanceConfig
from companion.guidance.geofence import Geofence, GeofenceConfig
from companion.json_value import JsonObject
from companion.perception.config import MODEL_PATH_FIELDS, PerceptionConfig
from companion.vehicle.link import FlightMode

if TYPE_CHECKING:
    from companion.perception.pipeline import SlzPipeline


class OperatingMode(str, enum.Enum):
    """What the companion may do."""

    FLY = "fly"
    """Perceive, decide and command the vehicle."""
    DRY_RUN = "dry_run"
    """Perceive and decide, log and show, but never arm, change mode or send a setpoint."""


class StartConfig(StrictModel):
    """How a mission starts."""

    arm_and_takeoff: bool = Field(
        default=False,
        description="Arm and take off to takeoff_altitude_m first (SITL and test benches). In the field the pilot "
        "flies to the area and the companion starts from the air.",
    )
    takeoff_altitude_m: float = Field(default=20.0, gt=1.0, le=120.0)
    handover_modes: list[FlightMode] = Field(
        default_factory=lambda: [FlightMode.HOLD],
        min_length=1,
        description="Without arm_and_takeoff: the companion starts only once the vehicle is armed, in the air and "
        "in one of these modes (the pilot hands over by switching to it). It never starts from the ground, so a "
        "restarted companion cannot take off.",
    )
    start_north_m: float | None = Field(default=None, description="Fly here before the search (SITL campaigns).")
    start_east_m: float | None = None

    @field_validator("handover_modes")
    @classmethod
    def _no_offboard(cls, modes: list[FlightMode]) -> list[FlightMode]:
        if FlightMode.OFFBOARD in modes or FlightMode.UNKNOWN in modes:
            raise ValueError("must not list OFFBOARD or UNKNOWN: the pilot hands over from a mode of their own")
        return modes


class VehicleConfig(StrictModel):
    """The link to the autopilot (MAVSDK)."""

    url: str = Field(
        default="udpin://0.0.0.0:14540",
        description="MAVSDK connection URL: udpin://0.0.0.0:14540 (SITL, PX4 offboard port), "
        "serial:///dev/ttyTHS1:921600 (Jetson TELEM2), tcpout://host:port.",
    )
    system_id: int | None = Field(
        default=None,
        ge=1,
        le=255,
        description="The companion's MAVLink system id, which is the autopilot's (MAV_SYS_ID): a ground station then "
        "shows the companion's status texts as the vehicle's, and commands to the vehicle's system reach it. None "
        "(the default): taken from the autopilot's heartbeat at connect; a number that differs from the autopilot's "
        "is refused at connect, naming both.",
    )
    connect_timeout_s: float = Field(default=20.0, gt=0.0, le=600.0, description="Wall time to find the autopilot.")
    telemetry_rate_hz: float = Field(default=50.0, gt=0.0, le=250.0, description="Position and attitude rate asked.")
    link_lost_after_s: float = Field(default=1.5, gt=0.0, le=30.0, description="No telemetry this long: link lost.")
    decision_watchdog_s: float = Field(
        default=0.5,
        gt=0.0,
        le=10.0,
        description="The decision loop silent this long (wall time): stop offboard (MAVSDK keeps re-sending "
        "the last setpoint on its own thread otherwise).",
    )

    @field_validator("url")
    @classmethod
    def _scheme(cls, url: str) -> str:
        schemes = ("udpin://", "udpout://", "udp://", "tcpin://", "tcpout://", "tcp://", "serial://")
        if not url.startswith(schemes):
            raise ValueError(f"must start with one of {', '.join(schemes)}")
        return url


class CameraSourceConfig(StrictModel):
    """Where frames come from, chosen by URL."""

    url: str = Field(
        default="sitl://127.0.0.1:5600",
        description="sitl://HOST:PORT (the bundled SITL), v4l2:///dev/video0, rtsp://..., udp://..., or a video "
        "file path (file:///path.mp4).",
    )
    max_frame_age_s: float = Field(
        default=0.5, gt=0.0, le=10.0, description="Frames older than this (vehicle clock) are dropped and counted."
    )
    latency_s: float = Field(
        default=0.0,
        ge=0.0,
        le=2.0,
        description="For sources without capture times (V4L2, RTSP, files): time from exposure to arrival "
        "(scripts/measure_latency.py measures it from a recorded flight).",
    )
    wait_for_s: float = Field(
        default=30.0,
        ge=0.0,
        le=600.0,
        description="At start, wait this long (wall time) for a camera that is not up yet, retrying and saying so: "
        "on a drone the camera service and the companion start in any order. 0: fail at once.",
    )


class SimulatorConfig(StrictModel):
    """Stepping with a simulator (the bundled SITL); absent on a real vehicle."""

    lockstep_url: str | None = Field(
        default=None,
        description="udp://HOST:PORT of the SITL's control channel (4560 + instance). The companion subscribes to "
        "its ticks; a SITL that runs free says so and the companion runs free too. None: never step.",
    )
    tick_timeout_s: float = Field(default=30.0, gt=0.0, le=600.0, description="Wall time to wait for a tick.")

    @field_validator("lockstep_url")
    @classmethod
    def _udp(cls, url: str | None) -> str | None:
        if url is not None:
            host_port(url, "udp")
        return url


class FrameFormat(str, enum.Enum):
    """How the recorder saves frames."""

    JPEG = "jpeg"
    """Small, lossy: for looking at."""
    PNG = "png"
    """Lossless: ``slz replay`` re-runs the pipeline on them bit for bit."""


class RecorderConfig(StrictModel):
    """The flight recorder, and the rotation of old flights in its directory."""

    directory: Path = Field(default=Path("runs/flights"), description="Each flight gets a sub-folder here.")
    frame_every: int = Field(
        default=10, ge=0, le=10000, description="Save every n-th frame (0: none; 1 with png makes a replayable log)."
    )
    frame_format: FrameFormat = FrameFormat.JPEG
    keep_flights: int = Field(
        default=0,
        ge=0,
        le=100000,
        description="Before a flight, delete the oldest flights beyond this many (0: keep all).",
    )
    max_total_mb: float = Field(
        default=0.0,
        ge=0.0,
        description="Before a flight, delete the oldest flights until the directory holds at most this (0: no limit).",
    )


class SupervisionConfig(StrictModel):
    """What the companion does once it has handed the vehicle to the autopilot (a failsafe's hold, return or land)."""

    stay_after_failsafe: bool = Field(
        default=True,
        description="Keep watching and recording after a failsafe command until the vehicle is on the ground or the "
        "pilot has switched it to a mode of their own (the console and the ground station say which), so that no "
        "flight ends with the vehicle in the air and nobody watching. False: end once the command is sent (SITL "
        "campaigns, whose harness ends the simulator).",
    )


class MissionConfig(StrictModel):
    """Everything ``slz fly`` needs."""

    mode: OperatingMode = OperatingMode.FLY
    vehicle: VehicleConfig = Field(default_factory=VehicleConfig)
    camera: CameraSourceConfig = Field(default_factory=CameraSourceConfig)
    start: StartConfig = Field(default_factory=StartConfig)
    geofence: GeofenceConfig = Field(default_factory=GeofenceConfig)
    guidance: GuidanceConfig = Field(default_factory=GuidanceConfig)
    perception: PerceptionConfig = Field(default_factory=PerceptionConfig)
    recorder: RecorderConfig = Field(default_factory=RecorderConfig)
    simulator: SimulatorConfig = Field(default_factory=SimulatorConfig)
    supervision: SupervisionConfig = Field(default_factory=SupervisionConfig)
    ground_station: GroundStationConfig = Field(default_factory=GroundStationConfig)
    live_view: LiveViewConfig = Field(default_factory=LiveViewConfig)

    @model_validator(mode="after")
    def _inside_the_fence(self) -> MissionConfig:
        problems = fence_contradictions(self)
        if problems:
            raise ValueError("\n".join(problems))  # one line each in the config error
        return self


def fence_contradictions(config: MissionConfig) -> list[str]:
    """One line per place where the mission would fly outside its own geofence, each naming both fields: the
    landing area, the start pose, the takeoff, search and landing altitudes against the fence's altitude band (every
    setpoint is clamped into the fence, so a contradiction would silently fly another mission than the one written)."""
    fence = Geofence(config.geofence)
    band = config.geofence
    problems = []
    localized = band.polygon_latlon_deg is None  # a fence in latitude and longitude: checked at the flight's start
    for north_m, east_m in config.perception.zones.landing_area_ne_m or []:
        if localized and not fence.contains_ne(north_m, east_m):
            problems.append(
                f"perception.zones.landing_area_ne_m vertex ({north_m}, {east_m}) lies outside "
                "geofence.polygon_ne_m: the companion could not fly to a zone there"
            )
    footprint_m = config.perception.zones.min_radius_m
    for site in config.guidance.fallback.sites:
        if localized and fence.distance_inside_m(site.north_m, site.east_m) < footprint_m:
            problems.append(
                f"guidance.fallback.sites {site.name!r} ({site.north_m}, {site.east_m}): its footprint "
                f"({footprint_m:g} m) reaches outside geofence.polygon_ne_m"
            )
        if site.radius_m < footprint_m:
            problems.append(
                f"guidance.fallback.sites {site.name!r}: radius_m {site.radius_m:g} m is smaller than the footprint "
                f"(perception.zones, {footprint_m:g} m)"
            )
    start = config.start
    n0, e0 = start.start_north_m, start.start_east_m
    if n0 is not None and e0 is not None and localized and not fence.contains_ne(n0, e0):
        problems.append(f"start.start_north_m, start.start_east_m ({n0}, {e0}) lie outside geofence.polygon_ne_m")
    guidance = config.guidance
    altitudes = [("guidance.search_altitude_m", guidance.search_altitude_m)]
    if start.arm_and_takeoff or start.start_north_m is not None:  # the takeoff and the transit fly at it
        altitudes.insert(0, ("start.takeoff_altitude_m", start.takeoff_altitude_m))
    for name, altitude_m in altitudes:
        if not band.min_altitude_m <= altitude_m <= band.max_altitude_m:
            problems.append(
                f"{name} ({altitude_m:g} m) must lie within geofence.min_altitude_m ({band.min_altitude_m:g} m) and "
                f"geofence.max_altitude_m ({band.max_altitude_m:g} m)"
            )
    if band.min_altitude_m > guidance.land_altitude_m + guidance.land_tolerance_m:
        problems.append(
            f"geofence.min_altitude_m ({band.min_altitude_m:g} m) lies above guidance.land_altitude_m "
            f"({guidance.land_altitude_m:g} m, + land_tolerance_m): the descent could never reach the landing"
        )
    return problems


REQUIRED_FOR_FLIGHT = (("polygon_ne_m", "polygon_latlon_deg"), ("max_altitude_m",))
"""The geofence fields a config must give for ``slz fly`` (one of each group): no flight on a default fence."""


def with_fallback_sites(config: MissionConfig, sites: list[JsonObject]) -> MissionConfig:
    """``config`` with ``sites`` as its fallback sites (``guidance.fallback.sites``, the rally points downloaded at the
    start among them), validated again with every cross-check; raises ConfigError naming what they contradict."""
    data = config.model_dump(mode="json")
    data["guidance"]["fallback"]["sites"] = sites
    try:
        return MissionConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(
            "the fallback sites with the autopilot's rally points", format_validation_error(exc)
        ) from None


def with_fence_ne_m(config: MissionConfig, polygon_ne_m: list[tuple[float, float]]) -> MissionConfig:
    """``config`` with its fence in local NED (a fence given in latitude and longitude, projected at the flight's
    start), validated again with every cross-check; raises ConfigError naming what the projected fence contradicts."""
    data = config.model_dump(mode="json")
    data["geofence"]["polygon_ne_m"] = [list(v) for v in polygon_ne_m]
    data["geofence"]["polygon_latlon_deg"] = None
    try:
        localized = MissionConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError("the fence projected from latitude and longitude", format_validation_error(exc)) from None
    return localized


MISSION_PATH_FIELDS = (*(("perception", *keys) for keys in MODEL_PATH_FIELDS), ("recorder", "directory"))
"""The paths of a mission config, taken from the config file's folder when relative (:func:`load_mission_config`)."""


def load_mission_config(path: str | Path) -> MissionConfig:
    """Load and validate a mission config (raises ``ConfigError`` naming every bad field). The relative paths it gives
    (the model, TensorRT's engine cache, the recorder's directory) are taken from the file's folder, so the same file
    means the same files from any working directory."""
    return load_yaml_config(MissionConfig, path, path_fields=MISSION_PATH_FIELDS)


def validate_for_flight(path: str | Path, never_arm: bool = False) -> tuple[MissionConfig, SlzPipeline]:
    """Everything ``slz fly`` checks before it opens a link, and ``slz check-config`` checks the same way.

    The file (every section and cross-check of :class:`MissionConfig`), ``--never-arm`` (the systemd unit) against
    ``start.arm_and_takeoff``, and the density model: it loads with the configured providers and its contract agrees
    with ``perception`` (input size, stride).

    Raises
    ------
    ConfigError
        A field, named with its allowed range.
    PerceptionError
        The model does not load or does not fit the config.
    """
    from companion.perception.pipeline import SlzPipeline

    config = load_mission_config(path)
    given = config.geofence.model_fields_set
    unset = [" or ".join(f"geofence.{n}" for n in group) for group in REQUIRED_FOR_FLIGHT if not given & set(group)]
    if unset:
        raise ConfigError(
            str(path),
            [
                f"{name}: required for slz fly (the field's own fence, in local NED metres around the EKF origin or "
                "in latitude and longitude; there is no default fence)"
                for name in unset
            ],
        )
    if never_arm and config.start.arm_and_takeoff:
        raise ConfigError(
            str(path),
            ["start.arm_and_takeoff: must be false with --never-arm (the systemd unit): the pilot takes off"],
        )
    return config, SlzPipeline.from_config(config.perception, fence_ne_m=config.geofence.polygon_ne_m)


# What a simulated camera must share with perception.camera, or every projection is silently wrong.
CAMERA_FIELDS = ("width_px", "height_px", "hfov_deg", "tilt_deg")


def camera_mismatches(perception: PerceptionConfig, sim_camera: object, where: str = "sitl.camera") -> list[str]:
    """One line per field of a simulated camera (any object with ``width_px``, ``height_px``, ``hfov_deg`` and
    ``tilt_deg``) that differs from ``perception.camera``; empty when they agree. Focal lengths given in pixels
    (``fx_px``) override the field of view and are compared through it."""
    cam = perception.camera
    ours: dict[str, float] = {k: float(getattr(cam, k)) for k in CAMERA_FIELDS}
    if cam.fx_px is not None:
        ours["hfov_deg"] = math.degrees(2.0 * math.atan(cam.width_px / (2.0 * cam.fx_px)))
    problems = []
    for key in CAMERA_FIELDS:
        theirs = float(getattr(sim_camera, key))
        if abs(theirs - ours[key]) > 1e-6 * max(1.0, abs(ours[key])):
            problems.append(
                f"perception.camera.{key}: {ours[key]:g} does not match {where}.{key} = {theirs:g} "
                "(the projection would put people in the wrong place)"
            )

    def lens(coefficients: list[float]) -> list[float]:  # all zero is no lens, as an empty list
        return [float(c) for c in coefficients] if any(coefficients) else []

    theirs_lens = lens(list(getattr(sim_camera, "distortion", [])))
    if theirs_lens != lens(cam.distortion):
        problems.append(
            f"perception.camera.distortion: {cam.distortion} does not match {where}.distortion = {theirs_lens} "
            "(frames would be undistorted with another lens than the one they were taken with)"
        )
    return problems
