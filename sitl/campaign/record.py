"""A campaign's results read back as typed records: :class:`FlownMission` (a mission's metrics and the facts of its
run) or :class:`MissionFailure` (a mission the campaign could not fly), from the lines of ``results.jsonl``.

Reading is strict: a field that is not one of the record's (a misspelt or foreign name) or a field that a result of
its metrics version must hold and does not is a :class:`ResultError` naming it, never a silent "n/a". A field that a
later metrics version added (:class:`~sitl.campaign.metric_fields.FieldInfo` ``since``) is absent from an older
result and read as "does not apply" (NaN, None, False or 0); :func:`sitl.campaign.metrics.stale` says which older
results the campaign flies again, and the report completes the rest where that needs no flight
(:func:`sitl.campaign.report.completed`) before reading them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from typing import Any

from companion.errors import SlzError
from sitl.campaign.metric_fields import field_infos, result_field
from sitl.campaign.metrics import METRICS_VERSION, MissionMetrics


class ResultError(SlzError):
    """A result line that is not a campaign result (which mission, which field)."""


@dataclasses.dataclass
class FlownMission(MissionMetrics):
    """A flown mission's metrics (:class:`~sitl.campaign.metrics.MissionMetrics`) and the facts of its run (None where
    the line does not say: a result not written by a campaign)."""

    wall_s: float | None = result_field(compared=False, default=None)
    """Wall seconds the mission took, processes included."""
    node: str | None = result_field(compared=False, default=None)
    """The machine (and Ray node) that flew it."""
    segment: int | None = result_field(compared=False, default=None)
    """The run of the campaign that flew it (``segments.jsonl``)."""
    commit: str | None = result_field(compared=False, default=None)
    """The code it flew (the repository's commit)."""
    finished_utc: str | None = result_field(compared=False, default=None)
    """When it finished (ISO 8601, UTC)."""


@dataclasses.dataclass(frozen=True)
class MissionFailure:
    """A mission the campaign could not fly (an infrastructure error, not a landing): flown again on resume."""

    mission_id: str
    condition: str
    strategy: str
    run: int
    seed: int
    error: str
    wall_s: float | None = None
    node: str | None = None
    segment: int | None = None
    commit: str | None = None
    finished_utc: str | None = None


CampaignResult = FlownMission | MissionFailure

_ABSENT = {"float": math.nan, "bool": False, "int": 0}
"""A field a later metrics version added, in an older result, by its type: "does not apply" (others: None)."""


def _value(name: str, kind: str, value: Any, mission: str) -> Any:
    """A line's value as the field's type holds it (a float's NaN is written as null)."""
    if kind == "float":
        if value is None:
            return math.nan
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ResultError(f"result of {mission}: {name} must be a number or null, got {value!r}")
        return float(value)
    if kind == "bool" and not isinstance(value, bool):
        raise ResultError(f"result of {mission}: {name} must be true or false, got {value!r}")
    if kind == "int" and (isinstance(value, bool) or not isinstance(value, int)):
        raise ResultError(f"result of {mission}: {name} must be an integer, got {value!r}")
    return value


def parse_result(line: Mapping[str, Any]) -> CampaignResult:
    """One line of ``results.jsonl`` as its typed record.

    Raises
    ------
    ResultError
        A field the record does not have, a field its metrics version must hold that is missing, or a value of the
        wrong type: each named, with the mission.
    """
    mission = str(line.get("mission_id", "?"))
    cls: type[FlownMission] | type[MissionFailure] = MissionFailure if "error" in line else FlownMission
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(line) - set(fields))
    if unknown:
        raise ResultError(f"result of {mission}: unknown field(s) {', '.join(unknown)} (a {cls.__name__} has none)")
    infos = field_infos(cls)
    version = int(line.get("metrics_version", 1))
    values: dict[str, Any] = {}
    for name, f in fields.items():
        kind = str(f.type)
        if name in line:
            values[name] = _value(name, kind, line[name], mission)
        elif f.default is not dataclasses.MISSING:
            continue
        elif infos[name].since > version or infos[name].optional:
            values[name] = _ABSENT.get(kind)
        else:
            raise ResultError(f"result of {mission}: missing field {name} (metrics version {version})")
    return cls(**values)


def parse_results(lines: Iterable[Mapping[str, Any]]) -> list[CampaignResult]:
    """:func:`parse_result` of each line, in order."""
    return [parse_result(line) for line in lines]


def flown_missions(results: Iterable[CampaignResult]) -> list[FlownMission]:
    """The flown missions among the results (no failures)."""
    return [r for r in results if isinstance(r, FlownMission)]


def compared_fields() -> tuple[str, ...]:
    """The fields two flights of one mission are compared on: every outcome, none of the run's facts."""
    return tuple(name for name, info in field_infos(FlownMission).items() if info.compared)


__all__ = ["METRICS_VERSION", "CampaignResult", "FlownMission", "MissionFailure", "ResultError", "parse_result"]
