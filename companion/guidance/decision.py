"""The landing logic's output: its phases, the commands it asks of the vehicle, and one decision.

Times are vehicle-clock seconds; setpoints local NED (:class:`~companion.vehicle.link.Setpoint`).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from companion.guidance.config import FailsafeAction
from companion.guidance.vocabulary import CommitmentEvent, DecisionEvent, RefusalCause
from companion.perception.selection import Target
from companion.vehicle.link import Setpoint


class LandingPhase(str, enum.Enum):
    """States of the landing logic."""

    IDLE = "idle"
    SEARCH = "search"
    APPROACH = "approach"
    DESCENT = "descent"
    LAND = "land"
    DONE = "done"
    HOLD = "hold"
    FAILSAFE = "failsafe"
    YIELDED = "yielded"


ACTIVE_PHASES = frozenset({LandingPhase.SEARCH, LandingPhase.APPROACH, LandingPhase.DESCENT})


class CommandKind(str, enum.Enum):
    """What a decision asks of the vehicle link."""

    NONE = "none"
    SETPOINT = "setpoint"
    LAND = "land"
    HOLD = "hold"
    RETURN = "return"


ENDING_KINDS = (CommandKind.LAND, CommandKind.HOLD, CommandKind.RETURN)
"""The commands that hand the vehicle's end to the autopilot: a landing or a last resort."""

COMMAND_OF_ACTION = {
    FailsafeAction.HOLD: CommandKind.HOLD,
    FailsafeAction.LAND: CommandKind.LAND,
    FailsafeAction.RETURN: CommandKind.RETURN,
}
"""What the vehicle link is asked for each failsafe action."""


@dataclass(frozen=True)
class Decision:
    """One decision: the phase after it, the command, and why.

    ``reason`` says it in words, for people; ``event``, ``cause`` (a refused or waited-on landing point's) and
    ``zone_changes`` (the commitment's changes that this decision reports) say it as data
    (:mod:`companion.guidance.vocabulary`), for everything that counts.
    """

    t_s: float
    phase: LandingPhase
    kind: CommandKind
    setpoint: Setpoint | None
    target: Target | None
    reason: str
    event: DecisionEvent
    cause: RefusalCause | None = None
    zone_changes: tuple[CommitmentEvent, ...] = ()
