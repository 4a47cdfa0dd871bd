"""The landing logic's parameters (:class:`GuidanceConfig`, the mission config's ``guidance:``) and what it asks of
the autopilot when a limit or silence ends a mission (:class:`FailsafeAction`). Metres, seconds, vehicle clock."""

from __future__ import annotations

import enum

from pydantic import Field, model_validator

from companion.config import StrictModel
from companion.guidance.commitment import CommitmentConfig
from companion.guidance.walker_watch import WalkerWatchConfig


class FailsafeAction(str, enum.Enum):
    """What the companion asks of the autopilot when perception stays silent for T2."""

    HOLD = "hold"
    """Autopilot hold (loiter) where it is."""
    LAND = "land"
    """Land in place (the autopilot's own landing)."""
    RETURN = "return"
    """Return to launch."""


class EnergyConfig(StrictModel):
    """The mission config's ``guidance.energy``: the search's budget from the battery (off by default)."""

    enabled: bool = Field(default=False, description="Budget the search by the battery (needs capacity_mah).")
    capacity_mah: float | None = Field(
        default=None, gt=0.0, le=1_000_000.0, description="The pack's full capacity (PX4: BAT1_CAPACITY)."
    )
    reserve_fraction: float = Field(
        default=0.25,
        ge=0.0,
        lt=1.0,
        description="Charge never planned against: the vehicle is home and down with at least this much left. Keep "
        "it above the autopilot's critical threshold (PX4: BAT_CRIT_THR), so its failsafe never has to act.",
    )
    return_speed_mps: float = Field(default=5.0, gt=0.0, le=30.0, description="Horizontal speed home (RTL's).")
    descent_speed_mps: float = Field(default=1.0, gt=0.0, le=10.0, description="Descent speed of the landing.")
    margin: float = Field(default=1.3, ge=1.0, le=5.0, description="Factor on the time home and down.")
    current_smoothing_s: float = Field(
        default=10.0, gt=0.0, le=300.0, description="Time constant of the current's average (vehicle seconds)."
    )
    action: FailsafeAction = Field(
        default=FailsafeAction.RETURN, description="What the budget's end asks of the autopilot: return or hold."
    )

    @model_validator(mode="after")
    def _complete(self) -> EnergyConfig:
        if self.enabled and self.capacity_mah is None:
            raise ValueError("capacity_mah: required when the energy budget is enabled (the pack's mAh)")
        if self.action is FailsafeAction.LAND:
            raise ValueError("action: must be return or hold (got land): a landing the map has not chosen")
        return self


class FallbackSiteConfig(StrictModel):
    """One place surveyed by the operator where a landing is acceptable (local NED, as the fence)."""

    name: str = Field(min_length=1, max_length=40, description="For the log and the ground station.")
    north_m: float = Field(ge=-100_000.0, le=100_000.0)
    east_m: float = Field(ge=-100_000.0, le=100_000.0)
    radius_m: float = Field(
        default=3.0, gt=0.0, le=100.0, description="The surveyed area around the point: the landing's zone radius."
    )


class FallbackConfig(StrictModel):
    """The mission config's ``guidance.fallback``: where to land when the search's budget ends without a zone
    (companion/guidance/fallback.py); none by default."""

    sites: list[FallbackSiteConfig] = Field(
        default_factory=list, description="Surveyed sites, tried nearest first; each checked by the map on arrival."
    )
    site_time_s: float = Field(
        default=120.0, gt=0.0, le=3600.0, description="From choosing a site to its landing; past it, the next site."
    )
    rally_points: bool = Field(
        default=False,
        description="Also the autopilot's rally points (a ground station uploads them with the rally protocol), "
        "downloaded at the start; one whose footprint leaves the fence is dropped (logged).",
    )
    rally_radius_m: float = Field(
        default=3.0, gt=0.0, le=100.0, description="The radius of a rally point's site (rally points carry none)."
    )

    @model_validator(mode="after")
    def _unique(self) -> FallbackConfig:
        names = [site.name for site in self.sites]
        if len(set(names)) != len(names):
            raise ValueError(f"sites: every site needs its own name (got {names})")
        return self


class WarnWhen(str, enum.Enum):
    """When the warning device sounds."""

    DESCENT = "descent"
    """From the final descent's start to the touchdown: over the landing point, the walker gate's waits included."""
    WALKER_GATE = "walker_gate"
    """Only while the descent waits at the walker gate for someone to leave or pass."""


class WarningConfig(StrictModel):
    """The mission config's ``guidance.warning``: a siren or strobe for the people below, on an actuator output of
    the autopilot (companion/app/warning_device.py); off by default."""

    enabled: bool = Field(default=False, description="Sound the warning device during the landing.")
    actuator: int = Field(
        default=1,
        ge=1,
        le=6,
        description="The autopilot output the device is wired to: PX4's 'Offboard Actuator Set N' function "
        "(MAV_CMD_DO_SET_ACTUATOR's param N of set 0; MAVSDK's set_actuator index N).",
    )
    on_value: float = Field(default=1.0, ge=-1.0, le=1.0, description="The output's value that sounds it.")
    off_value: float = Field(default=-1.0, ge=-1.0, le=1.0, description="The output's value that silences it.")
    when: WarnWhen = Field(default=WarnWhen.DESCENT, description="During the whole final descent, or at the gate.")

    @model_validator(mode="after")
    def _distinct(self) -> WarningConfig:
        if self.on_value == self.off_value:
            raise ValueError(f"on_value and off_value must differ (both {self.on_value})")
        return self


class GuidanceConfig(StrictModel):
    """Landing logic parameters (metres, seconds, vehicle clock)."""

    search_altitude_m: float = Field(default=20.0, gt=2.0, le=120.0, description="Minimum altitude while searching.")
    search_timeout_s: float = Field(default=6.0, gt=0.0, le=600.0, description="No target this long: search pattern.")
    search_leg_m: float = Field(default=5.0, gt=0.0, le=100.0, description="First leg of the expanding square.")
    approach_height_m: float = Field(default=2.0, gt=0.0, le=20.0, description="Descent goal above ground (paper).")
    land_altitude_m: float = Field(default=2.0, gt=0.0, le=20.0, description="At or below: command the landing.")
    land_tolerance_m: float = Field(
        default=0.3, ge=0.0, le=5.0, description="Slack above land_altitude_m (position control converges slowly)."
    )
    capture_radius_m: float = Field(default=0.75, gt=0.0, le=10.0, description="Horizontal error to start descending.")
    max_step_m: float = Field(
        default=4.0, gt=0.0, le=50.0, description="Farthest horizontal setpoint from the vehicle."
    )
    descent_rate_limit_mps: float = Field(default=1.0, gt=0.0, le=5.0)
    autopilot_z_time_constant_s: float = Field(
        default=1.0, gt=0.0, le=10.0, description="1 / the autopilot's vertical position gain (PX4 MPC_Z_P = 1/s)."
    )
    climb_back_m: float | None = Field(
        default=4.0,
        ge=0.0,
        le=120.0,
        description="Climb after an aborted descent before choosing again (metres, at most back to the altitude the "
        "search started from). None: all the way back there, where the policy sees the whole search area (issue "
        "33: it rescued holds but lost landings that a choice from low down had made; not the default).",
    )
    blind_altitude_m: float = Field(
        default=4.5, gt=0.0, le=50.0, description="Below this the camera cannot see a whole zone on the head plane."
    )
    perception_min_altitude_m: float = Field(
        default=4.5,
        ge=0.0,
        le=50.0,
        description="Below this, maps do not decide: the descent continues on the last map from above it, and a "
        "person who walks into the footprint later is not seen. The model read magnified grass as people below "
        "about 10 m until frames were shrunk to its training scale (perception.model.min_gsd_m_per_px), and the "
        "floor was 12 m; now it is blind_altitude_m: lower, the whole view lies within the footprint and its "
        "margin, so a shadow at the frame's edge aborted descents (models/density/MODEL_CARD.md).",
    )
    landing_map_max_age_s: float = Field(
        default=12.0,
        gt=0.0,
        le=60.0,
        description="The landing needs a map this recent that saw the footprint free (the descent from "
        "perception_min_altitude_m to land_altitude_m must fit in it).",
    )
    footprint_known_fraction: float = Field(default=0.95, gt=0.0, le=1.0)
    unsafe_frames_to_abort: int = Field(
        default=4,
        ge=1,
        le=100,
        description="Consecutive frames with a person seen inside the footprint (or the zone shrunk below the "
        "minimum) to abort the descent. A person stays in the map from frame to frame; the model's false positives "
        "flicker (runs of 1-2 frames measured in SITL descents).",
    )
    max_reselections: int = Field(
        default=12,
        ge=0,
        le=100,
        description="Aborted descents before the failsafe (hold). The mission's time limit is the budget that "
        "bounds the attempts; this only stops a vehicle that keeps being refused from trying for ever.",
    )
    hold_after_silence_s: float = Field(default=1.0, gt=0.0, le=60.0, description="T1: perception silent -> hold.")
    failsafe_after_silence_s: float = Field(default=5.0, gt=0.0, le=600.0, description="T2: -> failsafe action.")
    failsafe_action: FailsafeAction = Field(
        default=FailsafeAction.HOLD,
        description="T2's action. Hold by default: a landing in place lands on whatever is below, where the map "
        "may just have refused to land (deploy/README.md, 'If the companion dies over a crowd'); return is the next "
        "best. Land only where nobody can be below (the SITL's campaigns fly the paper's land).",
    )
    mission_time_limit_s: float = Field(
        default=600.0,
        gt=0.0,
        le=7200.0,
        description="Vehicle time from the start of the search to a landing decision; used up: last_resort (the "
        "pilot or the operator decides). On the vehicle clock, so a lockstep mission ends the same way on any machine.",
    )
    last_resort: FailsafeAction = Field(
        default=FailsafeAction.HOLD,
        description="What the companion asks of the autopilot when a limit ends the mission before a landing (the "
        "mission_time_limit_s, the wall limit of `slz fly --timeout`, max_reselections): hold or return, never land "
        "(a landing the map has not chosen lands on whatever is below).",
    )
    commitment: CommitmentConfig = Field(
        default_factory=CommitmentConfig, description="How firmly a chosen zone is kept (issue 33)."
    )
    walkers: WalkerWatchConfig = Field(
        default_factory=WalkerWatchConfig,
        description="A descent waits above the blind last metres while someone walks towards its landing point.",
    )
    energy: EnergyConfig = Field(
        default_factory=EnergyConfig,
        description="The search's budget from the battery (companion/guidance/energy.py); off by default.",
    )
    fallback: FallbackConfig = Field(
        default_factory=FallbackConfig,
        description="Surveyed fallback sites for when the search's budget ends (companion/guidance/fallback.py).",
    )
    warning: WarningConfig = Field(
        default_factory=WarningConfig,
        description="A siren or strobe for the people below during the landing (an autopilot output); off by default.",
    )
    blind_landing: bool = Field(
        default=False,
        description="Evaluation baseline only (the paper's 'random landing', with the random selection policy): "
        "descend and land on the target without checking the map. Never on a vehicle near people.",
    )

    @model_validator(mode="after")
    def _order(self) -> GuidanceConfig:
        if self.failsafe_after_silence_s <= self.hold_after_silence_s:
            raise ValueError("failsafe_after_silence_s (T2) must exceed hold_after_silence_s (T1)")
        if self.land_altitude_m < self.approach_height_m:
            raise ValueError("land_altitude_m must be at least approach_height_m, or the descent never reaches it")
        if self.last_resort is FailsafeAction.LAND:
            raise ValueError(
                "last_resort: must be hold or return (got land): a landing the map has not chosen lands on whatever "
                "is below"
            )
        return self
