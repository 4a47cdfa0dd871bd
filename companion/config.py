"""Loading typed, validated configuration objects from YAML files in ``mission_configs/``.

Every config is a pydantic model with ``extra="forbid"``: an unknown key is an error, and every bad value is
reported with its dotted field path and the allowed range, e.g.
``perception.zones.n_proposals: Input should be greater than or equal to 1 (got 0)``.

Config files are read by :func:`parse_yaml`, which refuses what a careless or hostile file could do to the reader
before any field is looked at: a file over :data:`MAX_CONFIG_BYTES`, bytes that are not UTF-8, an empty document,
a duplicate key, nesting deeper than :data:`MAX_YAML_DEPTH`, aliases that expand beyond :data:`MAX_YAML_NODES`
nodes (an alias bomb), and NaN or infinite numbers anywhere. Error messages quote at most
:data:`MAX_QUOTE_CHARS` characters of an offending value.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, TypeVar
from urllib.parse import urlparse

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from companion.errors import SlzError

ModelT = TypeVar("ModelT", bound=BaseModel)

MAX_CONFIG_BYTES = 1 << 20  # 1 MiB: the shipped configs are a few kB
MAX_YAML_DEPTH = 32  # nested mappings and sequences
MAX_YAML_NODES = 200_000  # after expanding aliases
MAX_QUOTE_CHARS = 60  # of an offending value, in an error message


class StrictModel(BaseModel):
    """Base of every config section: immutable, unknown keys rejected, no NaN or inf, defaults validated too."""

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True, allow_inf_nan=False)


class ConfigError(SlzError):
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


def cut(text: str, limit: int) -> str:
    """``text`` cut to ``limit`` characters, marked with an ellipsis when cut."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def quote(value: Any, limit: int = MAX_QUOTE_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters (a hostile value may be megabytes long).

    Containers are not walked in full: their repr is built from a bounded prefix of their items.
    """
    if isinstance(value, (dict, list, tuple)):
        items = list(value.items())[:8] if isinstance(value, dict) else list(value)[:8]
        text = f"{type(value).__name__} of {len(value)}: " + ", ".join(quote(i, limit) for i in items)
    elif isinstance(value, (str, bytes)):
        text = repr(value[: limit + 1])
    else:
        text = repr(value)
    return cut(text, limit)


def host_port(url: str, scheme: str) -> tuple[str, int]:
    """The host and port of ``scheme://HOST:PORT``; ValueError saying the form expected when ``url`` is not one."""
    parsed = urlparse(url)
    try:
        port = parsed.port
    except ValueError:
        port = None
    if parsed.scheme != scheme or not parsed.hostname or port is None:
        raise ValueError(f"must be {scheme}://HOST:PORT, got {url!r}")
    return parsed.hostname, port


def format_validation_error(error: ValidationError, prefix: str = "") -> list[str]:
    """One line per pydantic error: ``dotted.field.path: message (got value)``, the value quoted briefly."""
    lines: list[str] = []
    for item in error.errors(include_input=True, include_url=False):
        path = ".".join(str(part) for part in (prefix, *item["loc"]) if part != "")
        got = item.get("input")
        got_text = "" if item["type"] == "missing" or isinstance(got, dict) else f" (got {quote(got)})"
        message = item["msg"]
        if item["type"] == "value_error":  # a validator's own words: they name their fields; no pydantic prefix
            message = message.removeprefix("Value error, ")
            if not item["loc"]:  # a check across sections (the fence against the mission): a line per problem
                lead = f"{prefix}: " if prefix else ""
                lines.extend(f"{lead}{cut(problem, 300)}" for problem in message.split("\n") if problem)
                continue
        lines.append(f"{cut(path, 200) or '<root>'}: {cut(message, 300)}{got_text}")
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


_SafeLoader: type[yaml.SafeLoader] = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's, when built with it


class _StrictLoader(_SafeLoader):  # type: ignore[valid-type,misc]
    """PyYAML's safe loader, refusing duplicate keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
                seen.add(key)
            except TypeError:  # an unhashable key: the base class reports it
                break
            if duplicate:
                mark = key_node.start_mark
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {quote(key)} (line {mark.line + 1})", None
                )
        mapping: dict[Any, Any] = super().construct_mapping(node, deep=deep)
        return mapping


def _yaml_problem(exc: yaml.YAMLError) -> str:
    """A YAML error in one short line naming the document (PyYAML's own message may quote a whole line of the file)."""
    if isinstance(exc, yaml.MarkedYAMLError):
        where = f" (line {exc.problem_mark.line + 1}, column {exc.problem_mark.column + 1})" if exc.problem_mark else ""
        what = " ".join(str(part) for part in (exc.context, exc.problem) if part)
        return f"<root>: not valid YAML: {cut(what, 200)}{where}"
    return f"<root>: not valid YAML: {cut(str(exc), 200)}"


def _check_nesting(text: str, source: str) -> None:
    """Refuse nesting deeper than MAX_YAML_DEPTH from the event stream (no recursion, nothing built yet)."""
    depth = 0
    for event in yaml.parse(text, Loader=_StrictLoader):
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_YAML_DEPTH:
                line = event.start_mark.line + 1 if event.start_mark else 0
                raise ConfigError(source, [f"<root>: nested deeper than {MAX_YAML_DEPTH} levels (line {line})"])
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1


def _expanded_size(root: yaml.Node) -> int:
    """How many nodes the document holds once its aliases are expanded (shared nodes counted each time)."""
    sizes: dict[int, int] = {}
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:  # iterative post-order with memoised sizes: an alias bomb costs its node count, not its expansion
        node, children_done = stack.pop()
        if id(node) in sizes:
            continue
        children: list[yaml.Node] = []
        if isinstance(node, yaml.MappingNode):
            children = [part for pair in node.value for part in pair]
        elif isinstance(node, yaml.SequenceNode):
            children = list(node.value)
        if children_done or not children:
            sizes[id(node)] = min(1 + sum(sizes.get(id(c), 1) for c in children), MAX_YAML_NODES + 1)
            continue
        stack.append((node, True))
        stack.extend((c, False) for c in children if id(c) not in sizes)
    return sizes[id(root)]


def _non_finite_path(data: Any) -> str | None:
    """The dotted path of the first NaN or infinite number in ``data``, or None."""
    stack: list[tuple[str, Any]] = [("", data)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, float) and not math.isfinite(value):
            return path or "<root>"
        if isinstance(value, dict):
            stack.extend((f"{path}.{k}" if path else str(k), v) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((f"{path}[{i}]", v) for i, v in enumerate(value))
    return None


def parse_yaml(raw: bytes | str, source: str) -> Any:
    """Parse one YAML document of a config file, refusing what no config needs (see the module docstring).

    Parameters
    ----------
    raw : bytes or str
        The file's content.
    source : str
        Where it came from, for the error.

    Returns
    -------
    The document: a mapping, a list or a scalar (never None: an empty document is refused).

    Raises
    ------
    ConfigError
        With one short line naming what is wrong (and the field, for non-finite numbers).
    """
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(source, [f"<root>: file of {len(raw)} bytes, more than the {MAX_CONFIG_BYTES} allowed"])
    if isinstance(raw, bytes):
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ConfigError(source, [f"<root>: not UTF-8 text (byte {exc.start})"]) from None
    else:
        text = raw
    if "\x00" in text:
        raise ConfigError(source, ["<root>: not a text file (NUL byte)"])
    try:
        _check_nesting(text, source)
        loader = _StrictLoader(text)
        try:
            node = loader.get_single_node()
            if node is None:
                raise ConfigError(source, ["<root>: empty document (an empty config would fly on defaults)"])
            if _expanded_size(node) > MAX_YAML_NODES:
                raise ConfigError(source, [f"<root>: aliases expand beyond {MAX_YAML_NODES} nodes"])
            data = loader.construct_document(node)
        finally:
            loader.dispose()
        if data is None:
            raise ConfigError(source, ["<root>: empty document (null)"])
    except yaml.YAMLError as exc:
        raise ConfigError(source, [_yaml_problem(exc)]) from None
    except RecursionError:
        raise ConfigError(source, [f"<root>: nested deeper than {MAX_YAML_DEPTH} levels"]) from None
    except ValueError as exc:  # e.g. an integer of more digits than Python converts
        raise ConfigError(source, [f"<root>: {cut(str(exc), 200)}"]) from None
    bad = _non_finite_path(data)
    if bad is not None:
        raise ConfigError(source, [f"{bad}: must be a finite number (NaN and infinity are not allowed)"])
    return data


def read_yaml_file(path: str | Path) -> Any:
    """Read and :func:`parse_yaml` one config file (raises :class:`ConfigError`)."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(str(path), [f"cannot read file: {exc.strerror or exc}"]) from None
    return parse_yaml(raw, str(path))


def paths_from(data: Any, folder: str | Path, fields: tuple[tuple[str, ...], ...]) -> Any:
    """``data`` (a parsed config document) with each path at one of ``fields`` (key paths into nested mappings) that
    is a relative path string taken from ``folder``, made absolute and normalised; everything else as it is (a wrong
    type is left for validation to name). A config file's relative paths thus mean the same files wherever the
    command runs. Returns a new document; ``data`` is not changed."""
    if not isinstance(data, dict):
        return data
    base = Path(folder).absolute()
    out = dict(data)
    for keys in fields:
        node = out
        for key in keys[:-1]:
            child = node.get(key)
            if not isinstance(child, dict):
                break
            node[key] = child = dict(child)
            node = child
        else:
            value = node.get(keys[-1])
            if isinstance(value, str) and value and not Path(value).is_absolute():
                node[keys[-1]] = os.path.normpath(base / value)
    return out


def load_yaml_config(
    model: type[ModelT], path: str | Path, section: str | None = None, path_fields: tuple[tuple[str, ...], ...] = ()
) -> ModelT:
    """Load ``path`` (YAML) and validate it, or only its top-level ``section``, against ``model``; the relative paths
    at ``path_fields`` (key paths within the validated document) are taken from the file's folder (:func:`paths_from`).

    Raises
    ------
    ConfigError
        The file is missing, is not valid YAML (or is refused by :func:`parse_yaml`), lacks the section, or has
        invalid values.
    """
    path = Path(path)
    data = read_yaml_file(path)
    if section is not None:
        if not isinstance(data, dict) or section not in data:
            raise ConfigError(str(path), [f"{section}: missing section"])
        data = data[section]
    data = paths_from(data, path.parent, path_fields)
    return validate_config(model, data, source=str(path), prefix=section or "")
