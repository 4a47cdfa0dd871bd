"""What the landing logic reacts to, as frozen types: the one input of :meth:`LandingGuidance.on
<companion.guidance.landing.LandingGuidance.on>`.

Each stimulus carries the vehicle ``state`` it came at (vehicle-clock time, local NED) and what else the logic decides
on; its ``source`` names it in the flight log. The flight log records each decision's stimulus (:func:`to_json`: its
type and inputs, the state beside it), and a replay hands the same stimulus back (:func:`stimulus_of_record`; a log from
before stimuli were recorded gives the same from its ``source`` and ``inputs``). A frame's result is not in the log: it
is recomputed from the saved frame, and found by ``seq``.

At a vehicle tick several stimuli may be due at once; :data:`TICK_PRIORITY` orders them, once for every reader.
"""

from __future__ import annotations

import typing
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionSource, OperatorCommand

if TYPE_CHECKING:
    from companion.perception.pipeline import FrameResult

InputValue = float | int | str | bool | None
"""One logged input of a stimulus (JSON scalar)."""


@dataclass(frozen=True)
class Started:
    """The start sequence's conditions hold: the mission begins from ``state``."""

    source: ClassVar[DecisionSource] = DecisionSource.START
    name: ClassVar[str] = "started"
    state: VehicleState

    def inputs(self) -> dict[str, InputValue]:
        """What besides the state the logic decides on (the log's record of it)."""
        return {}


@dataclass(frozen=True)
class FrameSeen:
    """A processed frame: its ``result`` (tracks, target, maps), decided at ``state``; ``seq`` is the frame's number."""

    source: ClassVar[DecisionSource] = DecisionSource.FRAME
    name: ClassVar[str] = "frame_seen"
    state: VehicleState
    result: FrameResult
    seq: int

    def inputs(self) -> dict[str, InputValue]:
        """The frame's number (the replay recomputes its result from the saved frame)."""
        return {"seq": self.seq}


@dataclass(frozen=True)
class Silence:
    """No processed frame for ``silent_s`` seconds (vehicle time)."""

    source: ClassVar[DecisionSource] = DecisionSource.SILENCE
    name: ClassVar[str] = "silence"
    state: VehicleState
    silent_s: float

    def inputs(self) -> dict[str, InputValue]:
        """How long perception has been silent."""
        return {"silent_s": self.silent_s}


@dataclass(frozen=True)
class Landed:
    """The autopilot reports the vehicle on the ground after the landing was commanded."""

    source: ClassVar[DecisionSource] = DecisionSource.LANDED
    name: ClassVar[str] = "landed"
    state: VehicleState

    def inputs(self) -> dict[str, InputValue]:
        """Nothing besides the state."""
        return {}


@dataclass(frozen=True)
class TimeUp:
    """A tick of the search's time budget (the logic decides whether the mission's time is used up)."""

    source: ClassVar[DecisionSource] = DecisionSource.TIME
    name: ClassVar[str] = "time_up"
    state: VehicleState

    def inputs(self) -> dict[str, InputValue]:
        """Nothing besides the state."""
        return {}


@dataclass(frozen=True)
class EnergyLow:
    """The energy budget is used up (:mod:`companion.guidance.energy`): ``reason`` in words, the pack's ``remaining``
    fraction, and ``reach_m``, how far a fallback site may be (None: no limit)."""

    source: ClassVar[DecisionSource] = DecisionSource.ENERGY
    name: ClassVar[str] = "energy_low"
    state: VehicleState
    reason: str
    reach_m: float | None = None
    remaining: float | None = None

    def inputs(self) -> dict[str, InputValue]:
        """The budget's word, the charge left and the reach."""
        return {"reason": self.reason, "remaining": self.remaining, "reach_m": self.reach_m}


@dataclass(frozen=True)
class PilotTookOver:
    """The autopilot reports a mode of the pilot's (``mode``, PX4's name) while the companion flew the vehicle."""

    source: ClassVar[DecisionSource] = DecisionSource.TAKEOVER
    name: ClassVar[str] = "pilot_took_over"
    state: VehicleState
    mode: str

    def inputs(self) -> dict[str, InputValue]:
        """The pilot's mode."""
        return {"mode": self.mode}


@dataclass(frozen=True)
class LimitReached:
    """A limit of the program (``slz fly --timeout``), in words: the mission gives up."""

    source: ClassVar[DecisionSource] = DecisionSource.LIMIT
    name: ClassVar[str] = "limit_reached"
    state: VehicleState
    reason: str

    def inputs(self) -> dict[str, InputValue]:
        """The limit, in words."""
        return {"reason": self.reason}


@dataclass(frozen=True)
class StopAsked:
    """The program was asked to stop (a signal, the service stopped), in words: the mission gives up."""

    source: ClassVar[DecisionSource] = DecisionSource.STOP
    name: ClassVar[str] = "stop_asked"
    state: VehicleState
    reason: str

    def inputs(self) -> dict[str, InputValue]:
        """Why, in words."""
        return {"reason": self.reason}


@dataclass(frozen=True)
class OperatorOrder:
    """A ground station's landing ``command``; ``person_seen``: the newest map sees a person in the footprint at the
    target (or has no map or target); ``force``: land even so."""

    source: ClassVar[DecisionSource] = DecisionSource.OPERATOR
    name: ClassVar[str] = "operator_order"
    state: VehicleState
    command: OperatorCommand
    person_seen: bool
    force: bool

    def inputs(self) -> dict[str, InputValue]:
        """The command, whether a person was seen, and whether it forces the landing."""
        return {"command": self.command.value, "force": self.force, "person_seen": self.person_seen}


@dataclass(frozen=True)
class Denied:
    """The logic's answer to an operator's command it will not carry out: why, in words (nothing changed)."""

    reason: str


Stimulus = (
    Started
    | FrameSeen
    | Silence
    | Landed
    | TimeUp
    | EnergyLow
    | PilotTookOver
    | LimitReached
    | StopAsked
    | OperatorOrder
)
"""Everything the landing logic reacts to."""

TICK_PRIORITY: tuple[type[Stimulus], ...] = (
    PilotTookOver,
    StopAsked,
    LimitReached,
    OperatorOrder,
    Started,
    Landed,
    TimeUp,
    Silence,
)
"""The order in which a vehicle tick looks for its stimuli; the first that decides ends the tick, but the operator's
commands, which are all taken and then let the tick go on. The pilot comes first (never take control back), then the
program's own stop and limit, then the ground station; the start sequence before anything a started mission sees; the
touchdown before the budget (``TimeUp``, with the energy budget's :class:`EnergyLow` in its place when it is used
up), and perception's silence last."""

_KINDS: tuple[type[Stimulus], ...] = typing.get_args(Stimulus)
"""Every kind of stimulus, as :data:`Stimulus` names them."""
_BY_NAME: dict[str, type[Stimulus]] = {kind.name: kind for kind in _KINDS}
_BY_SOURCE: dict[DecisionSource, type[Stimulus]] = {kind.source: kind for kind in _KINDS}


def to_json(stimulus: Stimulus) -> dict[str, InputValue]:
    """The stimulus as a decision record carries it (schema 3), beside the decision's ``source`` and ``state``: its
    type's name and its inputs."""
    return {"type": stimulus.name, **stimulus.inputs()}


def stimulus_of_record(record: dict[str, Any], state: VehicleState, results: dict[int, FrameResult]) -> Stimulus | None:
    """The stimulus a ``decision`` record names, taken at ``state``: its ``stimulus`` (schema 3), or its ``source``
    and ``inputs`` (a log from before); a frame's result from ``results`` by its ``seq`` (None when that frame has no
    result).

    Raises
    ------
    KeyError, ValueError
        The record names no known stimulus, or lacks an input its stimulus needs.
    """
    if "stimulus" in record:
        inputs = dict(record["stimulus"])
        kind = _BY_NAME[str(inputs.pop("type"))]
    else:
        kind, inputs = _BY_SOURCE[DecisionSource(record["source"])], record.get("inputs") or {}
    if kind is FrameSeen:
        seq = int(inputs["seq"])
        result = results.get(seq)
        return None if result is None else FrameSeen(state, result, seq)
    if kind is Silence:
        return Silence(state, float(inputs["silent_s"]))
    if kind is EnergyLow:
        reach, remaining = inputs.get("reach_m"), inputs.get("remaining")
        reach_m, left = (None if v is None else float(v) for v in (reach, remaining))
        return EnergyLow(state, str(inputs["reason"]), reach_m, left)
    if kind is PilotTookOver:
        return PilotTookOver(state, str(inputs["mode"]))
    if kind is LimitReached:
        return LimitReached(state, str(inputs["reason"]))
    if kind is StopAsked:
        return StopAsked(state, str(inputs["reason"]))
    if kind is OperatorOrder:
        command = OperatorCommand(str(inputs["command"]))
        return OperatorOrder(state, command, bool(inputs["person_seen"]), bool(inputs["force"]))
    return Started(state) if kind is Started else Landed(state) if kind is Landed else TimeUp(state)
