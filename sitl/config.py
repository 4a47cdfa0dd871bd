"""The SITL vehicle's configuration: ports, origin, dynamics, clock, seed, parameters."""

from __future__ import annotations

import enum
from pathlib import Path

from pydantic import Field, field_validator, model_validator

from companion.config import StrictModel, load_yaml_config
from sitl.dynamics.base import DynamicsBackend
from sitl.px4_params import PARAMS
from sitl.render.sensor import SensorConfig
from sitl.world.scenario import ScenarioConfig

API_PORT_REMOTE = 14540
API_PORT_LOCAL = 14580
GCS_PORT_REMOTE = 14550
GCS_PORT_LOCAL = 18570
CONTROL_PORT = 4560
FRAME_PORT = 5600
# PX4's layout puts instance N's API link on local port 14580 + N and MAVSDK on 14540 + N, so instance N + 40 would
# listen where instance N's vehicle sends from: instances 0..39 are the ones whose ports never meet.
MAX_INSTANCE = 39


class SitlCameraConfig(StrictModel):
    """The simulated down-looking camera (its frames stream on TCP 5600 + instance)."""

    enabled: bool = False
    rate_hz: float = Field(default=10.0, gt=0.0, le=60.0, description="Frames per simulated second.")
    width_px: int = Field(default=640, ge=16, le=4096)
    height_px: int = Field(default=480, ge=16, le=4096)
    hfov_deg: float = Field(default=90.0, gt=1.0, lt=179.0)
    tilt_deg: float = Field(default=0.0, ge=-90.0, le=90.0, description="0 = nadir, positive towards the nose.")
    distortion: list[float] = Field(
        default_factory=list,
        description="A lens: OpenCV's distortion coefficients (k1, k2, p1, p2[, k3, ...]) applied to each rendered "
        "frame (companion.perception.lens). The companion's perception.camera.distortion must match. Empty: none.",
    )
    sensor: SensorConfig = Field(
        default_factory=SensorConfig,
        description="What a real camera does to the picture: motion blur, defocus, vignetting, exposure and white "
        "balance drift, noise, JPEG (sitl/render/sensor.py). Off by default: the paper tables were flown without.",
    )

    @field_validator("distortion")
    @classmethod
    def _opencv_counts(cls, coefficients: list[float]) -> list[float]:
        if len(coefficients) not in (0, 4, 5, 8, 12, 14):
            raise ValueError(f"{len(coefficients)} coefficients; OpenCV's model takes 4, 5, 8, 12 or 14 (or none)")
        return coefficients


class FaultKind(str, enum.Enum):
    """Faults the SITL can inject at a simulated time (failsafe tests and campaigns)."""

    CAMERA_FAIL = "camera_fail"
    """The camera delivers nothing from then on."""
    CAMERA_DISCONNECT = "camera_disconnect"
    """The camera's connection is closed and it delivers nothing from then on (a cable pulled)."""
    LINK_LOSS = "link_loss"
    """The companion's MAVLink link (the API port) goes silent both ways."""


class FaultConfig(StrictModel):
    """One fault at one instant."""

    kind: FaultKind
    at_s: float = Field(ge=0.0, description="Simulated time of the fault.")


MAX_WIND_MPS = 40.0  # each wind component; beyond it the simple drag model (and any real quadrotor) is meaningless


class LinkName(str, enum.Enum):
    """The SITL's two MAVLink links."""

    API = "api"
    """The companion's (MAVSDK's) offboard link."""
    GCS = "gcs"
    """The ground station's link."""


class SigningConfig(StrictModel):
    """MAVLink 2 message signing on some links: outgoing frames signed, unsigned or badly signed frames dropped."""

    key_hex: str = Field(
        pattern=r"^[0-9a-fA-F]{64}$",
        description="The shared 32-byte secret as 64 hex digits (as MAVProxy's and QGroundControl's signing setup "
        "derive it from a passphrase: sha256 of the passphrase).",
    )
    links: list[LinkName] = Field(
        default_factory=lambda: [LinkName.GCS],
        min_length=1,
        description="Links that require signatures. The companion's MAVSDK 4.x Python API cannot sign, so the API "
        "link stays unsigned unless its peer signs (a pymavlink client, MAVProxy).",
    )

    @property
    def key(self) -> bytes:
        """The 32-byte secret."""
        return bytes.fromhex(self.key_hex)


class BatteryConfig(StrictModel):
    """The simulated pack (drained by the motors' thrust; PX4's BAT_* thresholds and COM_LOW_BAT_ACT act on it)."""

    capacity_mah: float = Field(
        default=5000.0, ge=100.0, le=100_000.0, description="Full capacity (a 4S 5000 mAh pack hovers about 20 min)."
    )
    initial_fraction: float = Field(
        default=1.0,
        gt=0.0,
        le=1.0,
        description="Charge at the start, a fraction of the capacity (a campaign makes "
        "energy scarce with a smaller pack or a partly used one).",
    )


class SitlConfig(StrictModel):
    """One simulated vehicle. Ports follow PX4 SITL and shift with ``instance``."""

    instance: int = Field(
        default=0,
        ge=0,
        le=MAX_INSTANCE,
        description="Shifts every port by this much, as PX4 does; from 40 up, ports meet another instance's.",
    )
    bind_address: str = Field(default="127.0.0.1", description="Local address of every socket (loopback).")
    gcs_port_remote: int = Field(default=GCS_PORT_REMOTE, ge=1, le=65535, description="Ground station port.")
    origin_lat_deg: float = Field(default=47.397742, ge=-90.0, le=90.0)
    origin_lon_deg: float = Field(default=8.545594, ge=-180.0, le=180.0)
    origin_alt_m: float = Field(default=488.0, ge=-500.0, le=9000.0)
    dynamics: DynamicsBackend = DynamicsBackend.RIGID_BODY
    physics_rate_hz: float = Field(default=400.0, ge=100.0, le=2000.0)
    speed_factor: float = Field(default=1.0, ge=0.0, le=1000.0, description="Sim seconds per wall second; 0 = max.")
    lockstep: bool = Field(default=False, description="Wait for the client's acknowledgement at every tick.")
    lockstep_period_s: float = Field(default=0.1, gt=0.0, le=10.0, description="Tick period (the camera's).")
    lockstep_timeout_s: float = Field(default=10.0, gt=0.0, le=600.0, description="Wall-clock wait for an ack.")
    seed: int = Field(default=0, ge=0)
    position_noise_m: float = Field(default=0.0, ge=0.0, le=5.0, description="Noise on reported positions.")
    home_ne_m: tuple[float, float] = Field(
        default=(0.0, 0.0),
        description="Where the vehicle rests at the start and returns to (local NED north, east, m; PX4's home). The "
        "world's region of interest is centred on the origin: a home outside it is a launch point clear of the crowd.",
    )
    wind_ned_mps: tuple[float, float, float] = Field(
        default=(0.0, 0.0, 0.0), description=f"Wind, NED m/s, each component within +-{MAX_WIND_MPS:g}."
    )
    signing: SigningConfig | None = Field(default=None, description="MAVLink 2 signing; None: off, as PX4's default.")
    params: dict[str, float] = Field(default_factory=dict, description="Parameter overrides, PX4 names.")
    log_path: Path | None = Field(default=None, description="Trajectory log (CSV), ground truth.")
    log_rate_hz: float = Field(default=50.0, gt=0.0, le=1000.0)
    live_view_port: int | None = Field(
        default=None,
        ge=1,
        le=65535,
        description="Serve the truth (every person, the vehicle) to Foxglove on this TCP port (slz sitl --live-view).",
    )
    ulog_path: Path | None = Field(
        default=None,
        description="The flight as a PX4 ULog (.ulg), as PX4's SITL writes one: Flight Review, pyulog and PlotJuggler "
        "read it; its samples at log_rate_hz of simulated time.",
    )
    truth_path: Path | None = Field(
        default=None,
        description="Ground-truth log (JSON lines) at every camera frame instant: the vehicle, its landed state and "
        "every person's position; for metrics, never seen by the companion.",
    )
    duration_s: float | None = Field(default=None, gt=0.0, description="Stop after this much simulated time.")
    end_after_touchdown_s: float | None = Field(
        default=None,
        gt=0.0,
        le=600.0,
        description="Once a lockstep client has let go: end the run this much simulated time after the vehicle is "
        "first seen on the ground, or at once when it is disarmed (a campaign's mission is over, and its ground truth "
        "holds the touchdown). None: run on.",
    )
    camera: SitlCameraConfig = Field(default_factory=SitlCameraConfig)
    faults: list[FaultConfig] = Field(default_factory=list, description="Injected at their simulated times.")
    battery: BatteryConfig = Field(default_factory=BatteryConfig)
    scenario: ScenarioConfig = Field(default_factory=ScenarioConfig)

    @field_validator("params")
    @classmethod
    def _known_params(cls, value: dict[str, float]) -> dict[str, float]:
        known = {p.name for p in PARAMS}
        unknown = sorted(set(value) - known)
        if unknown:
            raise ValueError(f"unknown parameters {unknown}; known: {sorted(known)}")
        return value

    @field_validator("wind_ned_mps")
    @classmethod
    def _wind(cls, value: tuple[float, float, float]) -> tuple[float, float, float]:
        if any(abs(v) > MAX_WIND_MPS for v in value):
            raise ValueError(f"each wind component must lie within +-{MAX_WIND_MPS:g} m/s")
        return value

    @model_validator(mode="after")
    def _ports(self) -> SitlConfig:
        if self.api_port_remote == self.gcs_port_remote:
            raise ValueError(
                f"instance {self.instance} puts the API link on the ground-station port {self.gcs_port_remote}; "
                "choose another instance (or gcs_port_remote)"
            )
        return self

    @model_validator(mode="after")
    def _camera_ticks(self) -> SitlConfig:
        if self.camera.enabled and self.lockstep and abs(self.lockstep_period_s * self.camera.rate_hz - 1.0) > 1e-9:
            raise ValueError(
                f"with the camera in lockstep every tick is a frame: lockstep_period_s must be 1 / camera.rate_hz "
                f"({1.0 / self.camera.rate_hz:g} s), got {self.lockstep_period_s}"
            )
        if self.camera.enabled:
            steps = self.physics_rate_hz / self.camera.rate_hz
            if abs(steps - round(steps)) > 1e-6:
                raise ValueError(
                    f"camera.rate_hz must divide physics_rate_hz ({self.physics_rate_hz}), got {self.camera.rate_hz}"
                )
        return self

    @model_validator(mode="after")
    def _rates(self) -> SitlConfig:
        if (
            abs(self.lockstep_period_s * self.physics_rate_hz - round(self.lockstep_period_s * self.physics_rate_hz))
            > 1e-6
        ):
            raise ValueError(
                f"lockstep_period_s ({self.lockstep_period_s}) must be a whole number of physics steps "
                f"(1/{self.physics_rate_hz} s)"
            )
        return self

    @property
    def api_port_local(self) -> int:
        """Local port of the offboard/API link."""
        return API_PORT_LOCAL + self.instance

    @property
    def api_port_remote(self) -> int:
        """Where the API link sends (MAVSDK listens here: ``udpin://0.0.0.0:14540``)."""
        return API_PORT_REMOTE + self.instance

    @property
    def gcs_port_local(self) -> int:
        """Local port of the ground-station link."""
        return GCS_PORT_LOCAL + self.instance

    @property
    def control_port(self) -> int:
        """The harness control channel (JSON over UDP): simulated pilot, lockstep, ground truth."""
        return CONTROL_PORT + self.instance

    @property
    def frame_port(self) -> int:
        """The camera's frame stream (TCP): ``sitl://127.0.0.1:<port>``."""
        return FRAME_PORT + self.instance

    @property
    def system_id(self) -> int:
        """MAVLink system id (PX4: instance + 1)."""
        return self.instance + 1


def load_sitl_config(path: str | Path) -> SitlConfig:
    """Load the ``sitl`` section of a YAML file."""
    return load_yaml_config(SitlConfig, path, section="sitl")
