"""What each field of a campaign result is, as metadata on the field itself: how the report summarises it, which
metrics version added it, and whether it is an outcome of the flight (compared between two flights of one mission)
or a fact about the run (its wall time, node, commit).

The report's rates and means, the stale rule's versions and the benchmark's comparison read this metadata
(:func:`fields_of`), so a new metric is one field with its metadata, and a name that is not a field fails loudly.
"""

from __future__ import annotations

import dataclasses
import enum
from typing import Any


class Summary(enum.Enum):
    """How the campaign report summarises a field over a cell's missions."""

    RATE = "rate"
    """A share of missions where it holds, with Wilson's 95 % interval (a boolean)."""
    MEAN = "mean"
    """A mean with a bootstrap 95 % interval over the missions where it applies (a number; NaN where it does not)."""
    NONE = "none"
    """Not summarised: who the mission is, a detail, or a fact about the run."""


@dataclasses.dataclass(frozen=True)
class FieldInfo:
    """One result field's metadata (see the module docstring).

    Attributes
    ----------
    summary : Summary
        How the report summarises it.
    order : int
        Its place among the fields of its summary in the report (and the seed of a mean's bootstrap).
    since : int
        The metrics version that added it: a stored result of an earlier version lacks it.
    compared : bool
        An outcome of the flight, the same for the same seed and config at any speed (the benchmark compares two
        flights of a mission on these); False for a fact about the run.
    optional : bool
        A detail a stored result may leave out at any version (read as None).
    """

    summary: Summary = Summary.NONE
    order: int = 0
    since: int = 1
    compared: bool = True
    optional: bool = False


def result_field(
    summary: Summary = Summary.NONE,
    *,
    order: int = 0,
    since: int = 1,
    compared: bool = True,
    optional: bool = False,
    default: Any = dataclasses.MISSING,
) -> Any:
    """A dataclass field of a campaign result with its :class:`FieldInfo`."""
    info = FieldInfo(summary, order, since, compared, optional)
    if default is dataclasses.MISSING:
        return dataclasses.field(metadata={"result": info})
    return dataclasses.field(default=default, metadata={"result": info})


def field_infos(cls: type) -> dict[str, FieldInfo]:
    """Every field of a result dataclass with its metadata (a field without any counts as an outcome, added at 1)."""
    return {f.name: f.metadata.get("result", FieldInfo()) for f in dataclasses.fields(cls)}


def fields_of(cls: type, summary: Summary) -> tuple[str, ...]:
    """The fields a report summarises this way, in the report's order."""
    infos = field_infos(cls)
    return tuple(sorted((n for n, i in infos.items() if i.summary is summary), key=lambda n: infos[n].order))
