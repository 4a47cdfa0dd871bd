"""A seeded crowd: who stands where, what they look like, and how the moving ones move, in simulated time.

Positions are head-plane (north_m, east_m) in world NED, around the region of interest centred at the origin.
Walks advance in fixed ticks of ``1 / walk_rate_hz`` simulated seconds from their own random stream, so the same seed
gives the same tracks at any simulation speed and however often :meth:`Crowd.advance_to` is called.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from companion.errors import SlzError
from sitl.world.reaction import Reaction
from sitl.world.scenario import ScenarioConfig, Style, WalkerKind

F64Array = npt.NDArray[np.float64]


class BodyType(enum.Enum):
    """Procedural body types (the renderer builds a distinct mesh for each)."""

    ADULT_SLIM = "adult_slim"
    ADULT_BROAD = "adult_broad"
    ADULT_WALKING = "adult_walking"
    ADULT_SITTING = "adult_sitting"
    ADULT_WITH_BACKPACK = "adult_with_backpack"
    ADULT_WITH_HAT = "adult_with_hat"
    ADULT_WITH_UMBRELLA = "adult_with_umbrella"
    ADULT_ARMS_OUT = "adult_arms_out"
    ELDERLY_WITH_CANE = "elderly_with_cane"
    TEEN = "teen"
    CHILD_STANDING = "child_standing"
    CHILD_WALKING = "child_walking"
    CHILD_SITTING = "child_sitting"
    PERSON_WITH_STROLLER = "person_with_stroller"


CHILD_TYPES = (BodyType.CHILD_STANDING, BodyType.CHILD_WALKING, BodyType.CHILD_SITTING)
ADULT_TYPES = tuple(t for t in BodyType if t not in CHILD_TYPES)
HELDOUT_ONLY_TYPES = (BodyType.ELDERLY_WITH_CANE, BodyType.PERSON_WITH_STROLLER, BodyType.ADULT_WITH_UMBRELLA)


def _adult_types(style: Style) -> tuple[BodyType, ...]:
    if style is Style.TRAIN:
        return tuple(t for t in ADULT_TYPES if t not in HELDOUT_ONLY_TYPES)
    return ADULT_TYPES


def hue_range(style: Style) -> tuple[int, int]:
    """OpenCV hue (0-179) range of clothing colours: warm for training, cool for held-out, all otherwise."""
    return {Style.TRAIN: (0, 45), Style.HELDOUT: (90, 150)}.get(style, (0, 180))


PATTERNS = ("solid", "striped", "checked", "two_tone")
HAIR_BGR = ((20, 20, 25), (30, 50, 80), (60, 90, 140), (160, 200, 220), (200, 200, 200), (40, 40, 120))


@dataclass(frozen=True)
class Appearance:
    """What one person looks like."""

    body: BodyType
    height_m: float
    radius_m: float
    top_bgr: tuple[int, int, int]
    bottom_bgr: tuple[int, int, int]
    pattern: str
    hair_bgr: tuple[int, int, int]
    hat_bgr: tuple[int, int, int] | None


class CrowdError(SlzError):
    """A crowd cannot be generated as configured (what failed, with the numbers)."""


class Crowd:
    """People of one scenario, drawn from ``seed``; some may walk.

    Parameters
    ----------
    config : ScenarioConfig
        Ranges and walk model.
    seed : int
        Fixes the count, positions, appearances, who moves and every step they take.
    """

    def __init__(self, config: ScenarioConfig, seed: int) -> None:
        self.config = config
        self.seed = seed
        rng = np.random.default_rng([seed, 1])
        n = int(rng.integers(config.people_min, config.people_max + 1))
        self.radii_m = rng.uniform(config.person_radius_m.low, config.person_radius_m.high, size=n)
        self.positions_ne_m = self._place(rng, self.radii_m)
        self.appearances = [self._appearance(rng, float(r)) for r in self.radii_m]
        n_moving = round(config.moving_fraction * n)
        self.moving = np.zeros(n, dtype=bool)
        self.moving[rng.choice(n, size=n_moving, replace=False)] = True
        self._walk_rng = np.random.default_rng([seed, 2])
        self._ticks = 0
        self.t_s = 0.0
        mover_count = int(self.moving.sum())
        self._speed_mps = rng.uniform(config.walking_speed_mps.low, config.walking_speed_mps.high, size=mover_count)
        self._heading_rad = rng.uniform(-math.pi, math.pi, size=mover_count)
        self._bound_m = config.roi_side_m / 2 + 10.0
        self.walked_m = np.zeros(n)
        """Distance each person has walked (a walking body's step follows it)."""
        self.step_heading_rad = np.random.default_rng([seed, 8]).uniform(-math.pi, math.pi, size=n)
        """Direction of each person's last step, from north towards east (a walking body faces it)."""
        self.reaction = Reaction(config.reaction, config.walking_speed_mps, n, seed)
        """Who steps away from the vehicle's warning, and how (nobody, unless ``config.reaction`` is enabled)."""

    def __len__(self) -> int:
        return len(self.radii_m)

    @property
    def mobile(self) -> npt.NDArray[np.bool_]:
        """Who may move during the scene (N,): the walkers and those who would step away from a warning."""
        return np.asarray(self.moving | self.reaction.reactive)

    def place(self, north_m: float, east_m: float) -> int:
        """Move the person nearest to (``north_m``, ``east_m``) among those who may move (:attr:`mobile`) there, now;
        their index (:class:`CrowdError` when nobody may move: the renderer draws the others in one still mesh).

        A test's injection, as the control channel's ``place_person`` (a person stepping under the vehicle); a walker
        walks on from there."""
        mobile = np.nonzero(self.mobile)[0]
        if not len(mobile):
            raise CrowdError("nobody in this scene may move (scenario.moving_fraction or scenario.reaction)")
        d = np.hypot(self.positions_ne_m[mobile, 0] - north_m, self.positions_ne_m[mobile, 1] - east_m)
        index = int(mobile[int(np.argmin(d))])
        self.positions_ne_m[index] = (north_m, east_m)
        return index

    def warn(self, t_s: float, north_m: float, east_m: float, on: bool) -> None:
        """The vehicle's warning starts (``on``; the vehicle over (``north_m``, ``east_m``), NED) or stops at
        simulated ``t_s``: the crowd walks up to then first (:class:`~sitl.world.reaction.Reaction`)."""
        self.advance_to(t_s)
        self.reaction.warn(north_m, east_m, on)

    # -- generation --------------------------------------------------------------------------------------------
    def _place(self, rng: np.random.Generator, radii: F64Array) -> F64Array:
        c = self.config
        half, gap = c.roi_side_m / 2, c.min_gap_m
        positions = np.zeros((len(radii), 2))
        placed = 0
        attempts = 0
        group_anchor: F64Array | None = None
        while placed < len(radii):
            attempts += 1
            if attempts > 2000 * max(len(radii), 1):
                raise CrowdError(
                    f"could place only {placed} of {len(radii)} people without overlap in {c.roi_side_m} m"
                )
            r = radii[placed]
            if group_anchor is not None and rng.random() < 0.8:  # groups: near the previous person
                candidate = group_anchor + rng.normal(0.0, 0.6, size=2)
            else:
                candidate = rng.uniform(-half + r, half - r, size=2)
            if np.any(np.abs(candidate) > half - r):
                continue
            if placed:
                d = np.hypot(*(positions[:placed] - candidate).T)
                if np.any(d < radii[:placed] + r + gap):
                    continue
            positions[placed] = candidate
            placed += 1
            group_anchor = candidate if rng.random() < c.group_fraction else None
        return positions

    def _appearance(self, rng: np.random.Generator, radius_m: float) -> Appearance:
        style = self.config.style
        adults = _adult_types(style)
        child = rng.random() < self.config.child_fraction
        body = CHILD_TYPES[int(rng.integers(len(CHILD_TYPES)))] if child else adults[int(rng.integers(len(adults)))]
        height = float(rng.uniform(1.0, 1.4) if child else rng.uniform(1.55, 1.95))
        hat = body is BodyType.ADULT_WITH_HAT or rng.random() < 0.15

        hue_low, hue_high = hue_range(style)

        def colour() -> tuple[int, int, int]:
            hsv = np.array(
                [[[rng.integers(hue_low, hue_high), rng.integers(60, 256), rng.integers(40, 240)]]], dtype=np.uint8
            )
            b, g, r = (int(v) for v in cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0])
            return b, g, r

        return Appearance(
            body=body,
            height_m=height,
            radius_m=radius_m * (0.75 if child else 1.0),
            top_bgr=colour(),
            bottom_bgr=colour(),
            pattern=PATTERNS[int(rng.integers(len(PATTERNS)))],
            hair_bgr=HAIR_BGR[int(rng.integers(len(HAIR_BGR)))],
            hat_bgr=colour() if hat else None,
        )

    # -- motion ------------------------------------------------------------------------------------------------
    def advance_to(self, t_s: float) -> None:
        """Walk every moving person up to simulated time ``t_s`` (ticks at ``walk_rate_hz``)."""
        if t_s < self.t_s:
            raise CrowdError(f"time went backwards: {t_s} s after {self.t_s} s")
        period = 1.0 / self.config.walk_rate_hz
        target_ticks = math.floor(t_s / period + 1e-9)
        movers = np.nonzero(self.moving)[0]
        while self._ticks < target_ticks:
            self._ticks += 1
            warned = self.reaction.anchor_ne_m is not None
            if warned:
                before, walked_before = self.positions_ne_m.copy(), self.walked_m.copy()
            if len(movers):
                if self.config.walker is WalkerKind.LATTICE:
                    alpha = self._walk_rng.integers(-1, 2, size=(len(movers), 2))
                    step = self.config.lattice_step_m * alpha
                else:
                    step = self._persistent_step(period)
                new = self.positions_ne_m[movers] + step
                length = np.hypot(step[:, 0], step[:, 1])
                self.walked_m[movers] += length
                stepped = length > 0
                self.step_heading_rad[movers[stepped]] = np.arctan2(step[stepped, 1], step[stepped, 0])
                # Reflect at a boundary 10 m outside the ROI so the crowd does not drift away.
                over = np.abs(new) > self._bound_m
                new[over] = np.sign(new[over]) * (2 * self._bound_m - np.abs(new[over]))
                self.positions_ne_m[movers] = new
            if warned:
                self._react(before, walked_before, self._ticks * period, period)
        self.t_s = t_s

    def _react(self, before: F64Array, walked_before: F64Array, t_s: float, dt_s: float) -> None:
        """Those reacting to the warning at the tick ending at ``t_s`` step away or stand instead of their walk
        (``before``: everyone's positions before this tick's walk, ``walked_before`` their distances walked)."""
        stepped_to = before.copy()
        reacting = self.reaction.step(stepped_to, t_s, dt_s)
        if not reacting.any():
            return
        delta = stepped_to[reacting] - before[reacting]
        length = np.hypot(delta[:, 0], delta[:, 1])
        self.walked_m[reacting] = walked_before[reacting] + length
        who = np.nonzero(reacting)[0]
        stepped = length > 0
        self.step_heading_rad[who[stepped]] = np.arctan2(delta[stepped, 1], delta[stepped, 0])
        self.positions_ne_m[reacting] = stepped_to[reacting]

    def _persistent_step(self, dt_s: float) -> F64Array:
        # Heading follows an Ornstein-Uhlenbeck turn: its direction decorrelates over heading_persistence_s.
        tau = self.config.heading_persistence_s
        self._heading_rad += self._walk_rng.normal(0.0, math.sqrt(2.0 * dt_s / tau), size=len(self._heading_rad))
        return np.column_stack([np.cos(self._heading_rad), np.sin(self._heading_rad)]) * (
            self._speed_mps[:, None] * dt_s
        )

    def clearance_m(self, north_m: float, east_m: float) -> float:
        """Distance from a point to the nearest person's body edge, now (negative inside a body)."""
        if not len(self):
            return math.inf
        d = np.hypot(self.positions_ne_m[:, 0] - north_m, self.positions_ne_m[:, 1] - east_m) - self.radii_m
        return float(d.min())
