"""People who notice the vehicle's warning and step away from it, in simulated time (issue 53).

Who notices, how quickly and how fast they walk are drawn once per scene from their own random stream, so a scene
looks and walks the same with the model on or off until a warning sounds, and the same seed and warnings give the
same steps at any simulation speed. Positions are head-plane (north_m, east_m) in world NED, as the crowd's.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from sitl.world.scenario import Range, ReactionConfig

F64Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


class Reaction:
    """The reaction of ``count`` people of one scene to the vehicle's warning.

    A noticer within ``notice_radius_m`` of the point under the vehicle reacts after their reaction time: inside
    ``keep_away_m`` they walk straight out to it at walking speed, then stand and watch; outside it they stop where
    they are (a walker does not walk on towards the vehicle). When the warning stops, everyone is free again (walkers
    walk on).

    Parameters
    ----------
    config : ReactionConfig
        Who may notice, how far, how quickly; disabled: nobody ever reacts.
    walking_speed_mps : Range
        The scene's walking speeds (a noticer steps away at one of them).
    count : int
        People in the scene.
    seed : int
        The scene's seed.
    """

    def __init__(self, config: ReactionConfig, walking_speed_mps: Range, count: int, seed: int) -> None:
        self.config = config
        rng = np.random.default_rng([seed, 9])
        notices = rng.random(count) < config.notice_share
        self.reactive: BoolArray = notices & config.enabled
        """Who would react to a warning (fixed for the scene; the renderer draws them as movers)."""
        self.delay_s = rng.uniform(config.reaction_time_s.low, config.reaction_time_s.high, size=count)
        self.speed_mps = rng.uniform(walking_speed_mps.low, walking_speed_mps.high, size=count)
        self.anchor_ne_m: tuple[float, float] | None = None
        """The point under the vehicle while the warning sounds; None when silent."""
        self.start_s = np.full(count, math.inf)
        """When each person reacts to the warning sounding now (inf: not reacting)."""
        self.reactions = 0
        """Reactions over the scene's life (a person reacting to two warnings counts twice)."""
        self.stepped_m = 0.0
        """Distance walked away from warnings over the scene's life, everyone together."""

    def warn(self, north_m: float, east_m: float, on: bool) -> None:
        """The warning starts (``on``, the vehicle over (``north_m``, ``east_m``)) or stops, at the crowd's time.

        The same warning said again (within 1 m of where it sounds) changes nothing; one from elsewhere is a new
        warning, which everyone may react to again. When it stops, everyone is free again.
        """
        anchor = self.anchor_ne_m
        if on and anchor is not None and math.hypot(north_m - anchor[0], east_m - anchor[1]) < 1.0:
            return
        self.anchor_ne_m = (north_m, east_m) if on else None
        self.start_s[:] = math.inf

    def step(self, positions_ne_m: F64Array, t_s: float, dt_s: float) -> BoolArray:
        """Move the reacting people in ``positions_ne_m`` (N, 2; in place) over the walk tick that ends at ``t_s``;
        returns who reacted (their walk is overridden for this tick: they step away or stand)."""
        anchor = self.anchor_ne_m
        if anchor is None:
            return np.zeros(len(positions_ne_m), dtype=bool)
        offset = positions_ne_m - np.asarray(anchor)
        distance = np.hypot(offset[:, 0], offset[:, 1])
        notices = self.reactive & ~np.isfinite(self.start_s) & (distance < self.config.notice_radius_m)
        self.start_s[notices] = t_s + self.delay_s[notices]
        active = self.start_s <= t_s
        self.reactions += int(np.count_nonzero(active & (self.start_s > t_s - dt_s)))
        inside = np.nonzero(active & (distance < self.config.keep_away_m))[0]
        if len(inside):
            # Straight out from the anchor (someone right under it steps north), at most to keep_away_m.
            d = distance[inside]
            unit = np.where(d[:, None] > 1e-6, offset[inside] / np.maximum(d, 1e-6)[:, None], [1.0, 0.0])
            reach = np.minimum(self.speed_mps[inside] * dt_s, self.config.keep_away_m - d)
            positions_ne_m[inside] = positions_ne_m[inside] + unit * reach[:, None]
            self.stepped_m += float(reach.sum())
        return np.asarray(active)
