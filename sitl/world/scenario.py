"""Scenario configuration: every domain-randomization range of the paper's evaluation, validated at load.

Paper ("Domain randomization"): a 30 m x 30 m region of interest, 80-120 people with non-overlapping initial
positions, random appearance, floor, illumination, weather, and the drone's initial pose in the ROI; some people
walk on a lattice (0.2 m steps, 10 per second).
"""

from __future__ import annotations

import enum
import math

from pydantic import Field, model_validator

from companion.config import StrictModel

# Random sequential placement of discs jams at about 55 % coverage; beyond ~45 % it needs very many attempts.
MAX_COVERAGE = 0.45


class WeatherKind(str, enum.Enum):
    """Image-space weather and light conditions."""

    CLEAR = "clear"
    FOG = "fog"
    RAIN = "rain"
    SNOW = "snow"
    DUST = "dust"
    DUSK = "dusk"
    """Dusk / overcast: darker, warmer or greyer light, lower contrast."""


class Style(str, enum.Enum):
    """Appearance families, for datasets whose held-out part must look unlike the training part."""

    ANY = "any"
    """Everything (SITL missions)."""
    TRAIN = "train"
    """Half the grass colours, warm clothing hues, all but three body types."""
    HELDOUT = "heldout"
    """The other grass colours, cool clothing hues, and three body types training never sees."""


class GroundKind(str, enum.Enum):
    """What the park's ground is made of."""

    PROCEDURAL = "procedural"
    """Grass colours with noise, sand, a plaza, a court and paths, painted from the seed."""
    REAL = "real"
    """Real drone photographs of the scenario's ``ground_site`` (``sitl/world/ground.py``; Caliterra by default): the
    ground real cameras see and synthetic-only models misread."""


class RealSite(str, enum.Enum):
    """Which real site's photographs a real ground is painted from (``sitl/world/ground/<site>``)."""

    CALITERRA = "caliterra"
    """A construction site in Texas (CC0): dirt, gravel, grass, tree crowns, machinery. Painted from the frames held
    out from ``slz_lite_wide_real``'s training."""
    GARFIELD = "garfield"
    """A park in Ohio in November (CC0): lawns, paths, roads, parking lots with cars, leafless forest. No shipped
    model trained on it: painted from all its frames."""
    BORUSZYN = "boruszyn"
    """A village in Poland from a kite (CC BY 3.0, "Photos: Andrew Zaborowski, with attribution to
    OpenStreetMap-PL"): roofs, farm yards, fields. No shipped model trained on it: painted from all its frames."""


class WalkerKind(str, enum.Enum):
    """How moving people move."""

    LATTICE = "lattice"
    """The paper's random walk: each axis steps by ``step * alpha``, alpha in {-1, 0, 1}, ``rate_hz`` times a second."""
    PERSISTENT = "persistent"
    """A pedestrian: walking speed, heading that persists and turns slowly."""


class PeopleModel(str, enum.Enum):
    """How people are drawn."""

    PROCEDURAL = "procedural"
    """Cylinders, boxes and spheres per body type (the first SITL's people; its campaigns' records before issue 63):
    an option."""
    MAKEHUMAN = "makehuman"
    """MakeHuman's CC0 bodies: sex, age, ancestry and shape targets, fitted clothes, hair, skinned to a skeleton,
    posed from MakeHuman's poses; walking people step through a walk cycle (``sitl/render/bodies``). The default
    since issue 63: the paper's SITL drew people as UE4 characters."""


class Range(StrictModel):
    """A closed interval ``[low, high]`` sampled uniformly."""

    low: float
    high: float

    @model_validator(mode="after")
    def _ordered(self) -> Range:
        if not (math.isfinite(self.low) and math.isfinite(self.high)) or self.low > self.high:
            raise ValueError(f"need finite low <= high, got [{self.low}, {self.high}]")
        return self


def _range(low: float, high: float) -> Range:
    return Range(low=low, high=high)


class ReactionConfig(StrictModel):
    """People who notice the vehicle's warning (a siren or strobe) and step away from it (issue 53; off by default).

    While the warning sounds, each person within ``notice_radius_m`` of the point under the vehicle who is one of the
    ``notice_share`` who notice (a seeded draw per person, the same in every run of the scene) starts, after their
    reaction time, to walk straight away from that point at walking speed until ``keep_away_m`` from it, then stands
    (or walks on, a walker). Each reacts once per warning.
    """

    enabled: bool = Field(default=False, description="Model people's reaction to the vehicle's warning.")
    warning_actuator: int = Field(
        default=1,
        ge=1,
        le=6,
        description="The vehicle's actuator output the warning device is wired to (MAV_CMD_DO_SET_ACTUATOR's param "
        "1-6 of actuator set 0: MAVSDK's set_actuator index); a value above 0 sounds it.",
    )
    notice_share: float = Field(default=0.7, ge=0.0, le=1.0, description="Share of people who notice the warning.")
    notice_radius_m: float = Field(default=12.0, gt=0.0, le=100.0, description="How far away the warning is noticed.")
    keep_away_m: float = Field(
        default=6.0, gt=0.0, le=50.0, description="How far from the point under the vehicle a noticer steps."
    )
    reaction_time_s: Range = Field(
        default_factory=lambda: _range(1.0, 3.0), description="From the warning to the first step, per person."
    )

    @model_validator(mode="after")
    def _sane(self) -> ReactionConfig:
        if self.reaction_time_s.low < 0.0 or self.reaction_time_s.high > 60.0:
            raise ValueError(f"reaction_time_s must lie in [0, 60] s, got {self.reaction_time_s}")
        return self


class ScenarioConfig(StrictModel):
    """All randomization ranges of one scenario family."""

    roi_side_m: float = Field(default=30.0, gt=0.0, le=500.0, description="Side of the square region of interest.")
    clear_ne_m: list[tuple[float, float, float]] = Field(
        default_factory=list,
        description="Ground no park object is placed on: discs [north_m, east_m, radius_m], as an operator's surveyed "
        "landing sites (fallback sites); people may still stand or walk there. Empty: the park as always.",
    )
    people_min: int = Field(default=80, ge=0, le=5000)
    people_max: int = Field(default=120, ge=0, le=5000)
    person_radius_m: Range = Field(default_factory=lambda: _range(0.2, 0.3), description="Body radius seen from above.")
    child_fraction: float = Field(default=0.15, ge=0.0, le=1.0)
    group_fraction: float = Field(default=0.3, ge=0.0, le=1.0, description="People placed in small groups.")
    min_gap_m: float = Field(default=0.1, ge=0.0, le=5.0, description="Free space between two bodies at the start.")
    moving_fraction: float = Field(default=0.0, ge=0.0, le=1.0, description="Paper: 0, 0.1, 0.2.")
    walker: WalkerKind = WalkerKind.LATTICE
    lattice_step_m: float = Field(default=0.2, gt=0.0, le=2.0)
    walk_rate_hz: float = Field(default=10.0, gt=0.0, le=100.0)
    walking_speed_mps: Range = Field(default_factory=lambda: _range(0.8, 1.6))
    heading_persistence_s: float = Field(default=5.0, gt=0.0, le=600.0, description="Correlation time of headings.")
    weather: list[WeatherKind] = Field(default_factory=lambda: [WeatherKind.CLEAR], min_length=1)
    weather_strength: Range = Field(default_factory=lambda: _range(0.2, 0.8))
    dynamic_weather: bool = Field(default=False, description="Change weather during the mission.")
    weather_period_s: float = Field(default=20.0, gt=0.0, le=3600.0, description="Time between weather changes.")
    sun_elevation_deg: Range = Field(default_factory=lambda: _range(20.0, 80.0))
    sun_azimuth_deg: Range = Field(default_factory=lambda: _range(0.0, 360.0))
    ambient: Range = Field(default_factory=lambda: _range(0.3, 0.7), description="Ambient light fraction.")
    start_altitude_m: Range = Field(default_factory=lambda: _range(15.0, 40.0))
    style: Style = Field(default=Style.ANY, description="Appearance family (datasets: a train/held-out style split).")
    ground: GroundKind = Field(default=GroundKind.PROCEDURAL, description="The park's ground texture.")
    ground_site: RealSite = Field(default=RealSite.CALITERRA, description="Real ground: the site it is painted from.")
    people: PeopleModel = Field(
        default=PeopleModel.MAKEHUMAN,
        description="How people are drawn: makehuman (bodies, clothes and poses; the default) or procedural (the "
        "first SITL's shapes, cheaper to draw).",
    )
    reaction: ReactionConfig = Field(
        default_factory=ReactionConfig, description="People stepping away from the vehicle's warning (off by default)."
    )
    bright_clothing_share: float = Field(
        default=0.25, ge=0.0, le=1.0, description="MakeHuman people: share of tops in a bright colour (the rest muted)."
    )

    @model_validator(mode="after")
    def _feasible(self) -> ScenarioConfig:
        if self.people_min > self.people_max:
            raise ValueError(f"people_min ({self.people_min}) must be <= people_max ({self.people_max})")
        r = self.person_radius_m
        if r.low <= 0 or r.high > 2.0:
            raise ValueError(f"person_radius_m must lie in (0, 2] m, got [{r.low}, {r.high}]")
        footprint = math.pi * (r.high + self.min_gap_m / 2) ** 2
        coverage = self.people_max * footprint / self.roi_side_m**2
        if coverage > MAX_COVERAGE:
            fit = int(MAX_COVERAGE * self.roi_side_m**2 / footprint)
            raise ValueError(
                f"people_max ({self.people_max}) cannot be placed without overlap in a {self.roi_side_m} m square "
                f"(at most about {fit} people of radius {r.high} m with {self.min_gap_m} m gaps)"
            )
        for name in ("walking_speed_mps", "weather_strength", "ambient"):
            rng: Range = getattr(self, name)
            if rng.low < 0:
                raise ValueError(f"{name} must not be negative, got [{rng.low}, {rng.high}]")
        if self.weather_strength.high > 1.0 or self.ambient.high > 1.0:
            raise ValueError("weather_strength and ambient must lie in [0, 1]")
        if not (self.sun_elevation_deg.low >= 0.0 and self.sun_elevation_deg.high <= 90.0):
            raise ValueError("sun_elevation_deg must lie in [0, 90]")
        if self.start_altitude_m.low <= 2.0:
            raise ValueError("start_altitude_m must stay above 2 m")
        return self
