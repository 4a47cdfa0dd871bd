"""Fallback sites: places the operator surveyed where a landing is acceptable, for when the search's budget ends.

When the mission's time limit or the energy budget ends the search without a landing, the landing logic
(:mod:`companion.guidance.landing`) does not go straight to its last resort: it flies to the nearest fallback site it
can still reach (with the energy budget on: no farther than home, whose return the budget keeps energy for), and
checks it with its own map as it checks a zone: the descent over the site's centre is refused for a person in the
footprint, a walker at the gate or no free map, exactly as over a zone. A refused site, or one not landed on within
``site_time_s``, is given up for the next site in reach; with none left, the last resort the budget's end named
(``guidance.last_resort``, or the energy budget's action). When the energy budget ends during the stay of a site chosen
before it (by the time limit or the ground station), the site is flown on to only if in reach, and the energy budget
names the last resort from then on. Every choice is a decision with its reason.

No I/O; times are the vehicle's clock.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from companion.guidance.config import FailsafeAction, FallbackConfig
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionEvent, RefusalCause
from companion.perception.selection import Target


@dataclass(frozen=True)
class FallbackSite:
    """A site, with its index in the config (its target's track id is ``-1 - index``: no tracked zone has it)."""

    index: int
    name: str
    north_m: float
    east_m: float
    radius_m: float

    @property
    def target(self) -> Target:
        """The site as a landing target: its centre, its radius."""
        return Target(self.north_m, self.east_m, self.radius_m, -1 - self.index)


@dataclass(frozen=True)
class BudgetEnd:
    """What ended the search: its words, its event, and the last resort it names once no site is left."""

    reason: str
    event: DecisionEvent
    action: FailsafeAction


class FallbackPlan:
    """The sites of one flight and the one being tried.

    Parameters
    ----------
    config : FallbackConfig
        The sites and the time each may take.
    """

    def __init__(self, config: FallbackConfig) -> None:
        self.config = config
        self.sites = [FallbackSite(k, s.name, s.north_m, s.east_m, s.radius_m) for k, s in enumerate(config.sites)]
        self.current: FallbackSite | None = None
        """The site flown to now (None: none)."""
        self.ended_by: BudgetEnd | None = None
        """What ended the search (set once, when the first site is chosen or none is)."""
        self.reach_m: float | None = None
        """How far a site may lie from the vehicle (None: any; the energy budget's home distance)."""
        self._tried: set[int] = set()
        self._since_s = 0.0

    def untried(self, state: VehicleState) -> list[tuple[float, int, FallbackSite]]:
        """The sites not tried yet in reach of ``state``: (distance m, index, site) each."""
        in_reach = [
            (math.hypot(s.north_m - state.north_m, s.east_m - state.east_m), s.index, s)
            for s in self.sites
            if s.index not in self._tried
        ]
        return [entry for entry in in_reach if self.reach_m is None or entry[0] <= self.reach_m]

    def next(self, state: VehicleState) -> FallbackSite | None:
        """Choose the nearest untried site in reach of ``state`` (it becomes :attr:`current`), or None."""
        self.current = None
        in_reach = self.untried(state)
        if not in_reach:
            return None
        _, _, site = min(in_reach)
        self._tried.add(site.index)
        self.current, self._since_s = site, state.t_s
        return site

    def end_stay_by(self, energy_low: str, action: FailsafeAction, reach_m: float | None) -> bool:
        """The energy budget used up (``energy_low``: why, in words; ``action``: its last resort; ``reach_m``: home's
        distance) during the stay of a site chosen before it, by the time limit or the ground station: from now on it
        has ended the search, for this site and the next. False when it already had (or no site is flown to)."""
        if self.current is None or self.ended_by is None or self.ended_by.event is DecisionEvent.ENERGY_LOW:
            return False
        self.ended_by, self.reach_m = BudgetEnd(energy_low, DecisionEvent.ENERGY_LOW, action), reach_m
        return True

    def in_reach(self, state: VehicleState) -> bool:
        """The current site lies within :attr:`reach_m` of ``state``."""
        return self.reach_m is None or self.distance_m(state) <= self.reach_m

    def overdue(self, t_s: float) -> bool:
        """The current site's time is used up."""
        return self.current is not None and t_s - self._since_s >= self.config.site_time_s

    def distance_m(self, state: VehicleState) -> float:
        """From the vehicle to the current site's centre (horizontal)."""
        assert self.current is not None
        return math.hypot(self.current.north_m - state.north_m, self.current.east_m - state.east_m)


class BudgetStepKind(str, enum.Enum):
    """What the search's budget asks of the landing logic at a tick."""

    NEXT_SITE = "next_site"
    """Fly to the nearest fallback site left in reach; with none left, the last resort the search's end named."""
    FLY_ON = "fly_on"
    """Keep flying to the site flown to: the energy budget ended during its stay, and it lies in reach."""


@dataclass(frozen=True)
class BudgetStep:
    """A step of the search's budget: its kind, its words, and the cause that ended a site (None: none did)."""

    kind: BudgetStepKind
    reason: str
    cause: RefusalCause | None = None


class SearchBudget:
    """When the search ends without a landing, and what becomes of the fallback site flown to then (pure; vehicle
    time).

    Parameters
    ----------
    time_limit_s : float
        The mission's time limit from :meth:`start` (``guidance.mission_time_limit_s``).
    last_resort : FailsafeAction
        The time limit's last resort (``guidance.last_resort``).
    energy_action : FailsafeAction
        The energy budget's last resort (``guidance.energy.action``).
    plan : FallbackPlan
        The flight's sites; the budget's end is recorded in it (:attr:`FallbackPlan.ended_by`, ``reach_m``).
    """

    def __init__(
        self, time_limit_s: float, last_resort: FailsafeAction, energy_action: FailsafeAction, plan: FallbackPlan
    ) -> None:
        self.time_limit_s, self.plan = time_limit_s, plan
        self.last_resort, self.energy_action = last_resort, energy_action
        self.started_s: float | None = None
        """When the mission started (None: not yet)."""

    def elapsed_s(self, t_s: float) -> float:
        """Vehicle time since the start (0 before it)."""
        return t_s - (self.started_s if self.started_s is not None else t_s)

    def step(self, state: VehicleState, energy_low: str | None, reach_m: float | None) -> BudgetStep | None:
        """At ``state``, with the energy budget's word ``energy_low`` (None: not used up) and its reach: once the time
        limit has passed or the energy budget is used up, the next site in ``reach_m``; at a site, its time, and the
        energy budget ending during the stay of a site chosen before it (by the time limit or the ground station): the
        site is flown on to if in reach, else given up. None: nothing to do. Call after :attr:`started_s` is set."""
        site = self.plan.current
        if site is not None:
            if energy_low is not None and self.plan.end_stay_by(energy_low, self.energy_action, reach_m):
                if self.plan.in_reach(state):
                    return BudgetStep(BudgetStepKind.FLY_ON, f"{energy_low}: site {site.name} in reach, flown on")
                return BudgetStep(BudgetStepKind.NEXT_SITE, f"{energy_low}: site {site.name} out of reach")
            if not self.plan.overdue(state.t_s):
                return None
            late = f"not landed at site {site.name} within {self.plan.config.site_time_s:g} s"
            return BudgetStep(BudgetStepKind.NEXT_SITE, late, RefusalCause.SITE_TIMED_OUT)
        if energy_low is not None:
            end = BudgetEnd(energy_low, DecisionEvent.ENERGY_LOW, self.energy_action)
        elif self.elapsed_s(state.t_s) >= self.time_limit_s:
            said = f"no landing within {self.time_limit_s:g} s of the start"
            end = BudgetEnd(said, DecisionEvent.TIME_LIMIT, self.last_resort)
        else:
            return None
        self.plan.ended_by, self.plan.reach_m = end, reach_m
        return BudgetStep(BudgetStepKind.NEXT_SITE, end.reason)
