"""JSON data as Python types: what :func:`json.loads` gives and :func:`json.dumps` takes.

A message, a record or a report built to be written as JSON is a :data:`JsonObject`: its values are checked to be
JSON, where ``dict[str, Any]`` would let anything through.
"""

from __future__ import annotations

JsonValue = str | int | float | bool | None | list["JsonValue"] | dict[str, "JsonValue"]
"""A JSON value."""
JsonObject = dict[str, JsonValue]
"""A JSON object."""
