"""Loading typed, validated configuration objects from YAML files in ``mission_configs/``.

Every config is a pydantic model with ``extra="forbid"``: an unknown key is an error, and every bad value is
reported with its dotted field path and the allowed range, e.g.
``perception.zones.n_proposals: Input should be greater than or equal to 1 (got 0)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

ModelT = TypeVar("ModelT", bound=BaseModel)


class StrictModel(BaseModel):
    """Base of every config section: immutable, unknown keys rejected, defaults validated too."""

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True)


class ConfigError(Exception):
    """A configuration could not be loaded or is invalid.

    Parameters
    ----------
    source : str
        Where the configuration came from (a file path or ``"<dict>"``).
    problems : list of str
        One line per problem, each naming the field (dotted path) and what is allowed.
    """

    def __init__(self, source: str, problems: list[str]) -> None:
        self.source = source
        self.problems = problems
        super().__init__(f"invalid configuration in {source}:\n" + "\n".join(f"  - {p}" for p in problems))


def format_validation_error(error: ValidationError, prefix: str = "") -> list[str]:
    """One line per pydantic error: ``dotted.field.path: message (got value)``."""
    lines = []
    for item in error.errors():
        path = ".".join(str(part) for part in (prefix, *item["loc"]) if part != "")
        got = item.get("input")
        got_text = "" if item["type"] == "missing" or isinstance(got, dict) else f" (got {got!r})"
        lines.append(f"{path or '<root>'}: {item['msg']}{got_text}")
    return lines


def validate_config(model: type[ModelT], data: Any, source: str = "<dict>", prefix: str = "") -> ModelT:
    """Validate ``data`` (a mapping) against ``model``; raise :class:`ConfigError` naming each bad field."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(source, [f"{prefix or '<root>'}: expected a mapping, got {type(data).__name__}"])
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(source, format_validation_error(exc, prefix)) from None


def load_yaml_config(model: type[ModelT], path: str | Path, section: str | None = None) -> ModelT:
    """Load ``path`` (YAML) and validate it, or only its top-level ``section``, against ``model``.

    Raises
    ------
    ConfigError
        The file is missing, is not valid YAML, lacks the section, or has invalid values.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(str(path), [f"cannot read file: {exc.strerror or exc}"]) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(str(path), [f"not valid YAML: {exc}"]) from None
    if section is not None:
        if not isinstance(data, dict) or section not in data:
            raise ConfigError(str(path), [f"{section}: missing section"])
        data = data[section]
    return validate_config(model, data, source=str(path), prefix=section or "")
