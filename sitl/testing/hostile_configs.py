"""Hostile and careless mission config files, each with a piece of the refusal it must get.

Built from ``mission_configs/sitl.yaml`` so each file is wrong in one way only. Used by tests/test_hostile_configs.py
(every file refused with a message naming the field, no traceback) and bench/hostile_configs.py (each refused within
a second by ``slz fly --dry-run``).
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sitl.harness.process import REPO_ROOT

SHIPPED = REPO_ROOT / "mission_configs" / "sitl.yaml"
FENCE_LINE = "  polygon_ne_m: [[-25.0, -25.0], [-25.0, 25.0], [25.0, 25.0], [25.0, -25.0]]"


# This project's wording of any refusal by the YAML parser (companion.config): where the parser may refuse a file
# before this project's own check does (nesting, aliases), either refusal is right, and whose it is depends on the
# parser's release. The parser's own words are never asserted.
PARSER_REFUSED = "not valid YAML"


@dataclass(frozen=True)
class HostileConfig:
    """One file, and the refusal it must get.

    Attributes
    ----------
    name : str
        The file's name (no suffix).
    content : bytes
        The file.
    field : str
        What the refusal must name: a problem line begins with this dotted field path, or with ``<root>`` for the
        document as a whole.
    reasons : tuple of str
        Phrases of this project's own messages, one of which the refusal must contain; empty where the words are a
        library's (pydantic's, Python's), so that only the field is asserted.
    """

    name: str
    content: bytes
    field: str
    reasons: tuple[str, ...] = ()

    def refusal_problem(self, message: str) -> str | None:
        """What is wrong with ``message`` (a ``ConfigError``'s text, or ``slz``'s standard error) as this file's
        refusal, or None when it is the refusal it must be."""
        problems = [line.strip()[2:] for line in message.splitlines() if line.strip().startswith("- ")]
        if not any(p.startswith(self.field) and p[len(self.field) : len(self.field) + 1] in ":.[" for p in problems):
            return f"no problem names {self.field!r}: {problems}"
        if self.reasons and not any(reason in message for reason in self.reasons):
            return f"none of {self.reasons} in {problems}"
        return None


def fly_dry_run(config: Path) -> subprocess.CompletedProcess[str]:
    """``slz fly --dry-run --config CONFIG`` as a user runs it (its own process, output captured)."""
    return subprocess.run(
        [sys.executable, "-m", "companion.cli", "fly", "--dry-run", "--config", str(config)],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )


def _with(text: str, old: str, new: str) -> bytes:
    assert old in text, old
    return text.replace(old, new, 1).encode()


def _laughs(levels: int, kind: str) -> bytes:
    """The billion-laughs alias bomb: each level is nine aliases of the one below."""
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, levels):
        refs = ", ".join([f"*a{i - 1}"] * 9)
        lines.append(f"a{i}: &a{i} [{refs}]" if kind == "list" else f"a{i}: &a{i} {{x0: *a{i - 1}, x1: *a{i - 1}}}")
    return ("\n".join(lines) + "\n").encode()


def hostile_configs() -> list[HostileConfig]:
    """32 and more files, each refused for its own reason."""
    base = SHIPPED.read_text()
    rng = np.random.default_rng(23)

    def fence(corners: str) -> bytes:
        return _with(base, FENCE_LINE, f"  polygon_ne_m: {corners}")

    def takeoff(value: str) -> bytes:
        return _with(base, "  takeoff_altitude_m: 20.0", f"  takeoff_altitude_m: {value}")

    deep = 20_000
    too_deep = ("nested deeper than", PARSER_REFUSED)  # our depth check, or the parser's own limit first
    alias_bomb = ("aliases expand beyond", PARSER_REFUSED)
    non_finite = ("must be a finite number",)
    out = [
        HostileConfig("empty", b"", "<root>", ("empty document",)),
        HostileConfig("comment_only", b"# nothing here\n\n", "<root>", ("empty document",)),
        HostileConfig("null_document", b"null\n", "<root>", ("empty document",)),
        HostileConfig("binary_junk", bytes(rng.integers(0, 256, 4096, dtype=np.uint8)), "<root>", ("not UTF-8",)),
        HostileConfig("latin1_bytes", base.encode() + "\n# caf\xe9\n".encode("latin-1"), "<root>", ("not UTF-8",)),
        HostileConfig("nul_bytes", base.encode() + b"\x00\x00", "<root>", ("NUL",)),
        HostileConfig("deep_flow_sequence", b"vehicle: " + b"[" * deep + b"]" * deep + b"\n", "<root>", too_deep),
        HostileConfig(
            "deep_block_mapping",
            "".join(f"{' ' * i}k{i}:\n" for i in range(200)).encode() + b" " * 200 + b"v: 1\n",
            "<root>",
            too_deep,
        ),
        HostileConfig("alias_bomb_lists", _laughs(10, "list"), "<root>", alias_bomb),
        HostileConfig("alias_bomb_mappings", _laughs(24, "map"), "<root>", alias_bomb),
        HostileConfig(
            "megabyte_value",
            _with(base, "url: udpin://0.0.0.0:14540", "url: " + "x" * 1_000_000),
            "vehicle.url",
            ("(got 'xxx",),
        ),
        HostileConfig("over_a_mebibyte", base.encode() + b"#" + b"x" * (1 << 20) + b"\n", "<root>", ("more than the",)),
        HostileConfig(
            "geofence_nan_corner",
            _with(
                base,
                "  polygon_ne_m: [[-25.0, -25.0], [-25.0, 25.0], [25.0, 25.0], [25.0, -25.0]]",
                "  polygon_ne_m: [[.nan, 0], [0, 20], [20, 20], [20, 0]]",
            ),
            "geofence.polygon_ne_m",
            non_finite,
        ),
        HostileConfig(
            "geofence_inf_corner",
            _with(
                base,
                "  polygon_ne_m: [[-25.0, -25.0], [-25.0, 25.0], [25.0, 25.0], [25.0, -25.0]]",
                "  polygon_ne_m: [[-.inf, 0], [0, 20], [20, 20], [20, 0]]",
            ),
            "geofence.polygon_ne_m",
            non_finite,
        ),
        HostileConfig(
            "geofence_bow_tie",
            _with(
                base,
                "  polygon_ne_m: [[-25.0, -25.0], [-25.0, 25.0], [25.0, 25.0], [25.0, -25.0]]",
                "  polygon_ne_m: [[0, 0], [20, 20], [20, 0], [0, 10]]",
            ),
            "geofence",
            ("polygon_ne_m must be a simple polygon",),
        ),
        HostileConfig(
            "geofence_no_area",
            _with(
                base,
                "  polygon_ne_m: [[-25.0, -25.0], [-25.0, 25.0], [25.0, 25.0], [25.0, -25.0]]",
                "  polygon_ne_m: [[0, 0], [10, 10], [20, 20]]",
            ),
            "geofence",
            ("polygon_ne_m must enclose",),
        ),
        HostileConfig(
            "geofence_folded_edge",
            _with(
                base,
                "  polygon_ne_m: [[-25.0, -25.0], [-25.0, 25.0], [25.0, 25.0], [25.0, -25.0]]",
                "  polygon_ne_m: [[-30, -30], [-30, 30], [30, 30], [30, -30], [30, 40]]",
            ),
            "geofence",
            ("polygon_ne_m must be a simple polygon",),
        ),
        HostileConfig(
            "start_north_nan", _with(base, "start:", "start:\n  start_north_m: .nan"), "start.start_north_m", non_finite
        ),
        HostileConfig(
            "takeoff_inf",
            takeoff(".inf"),
            "start.takeoff_altitude_m",
            non_finite,
        ),
        HostileConfig(
            "max_altitude_negative",
            _with(base, "  max_altitude_m: 40.0", "  max_altitude_m: -5"),
            "geofence.max_altitude_m",
            ("(got -5)",),
        ),
        HostileConfig(
            "duplicate_top_key",
            base.encode() + b"\nvehicle: {connect_timeout_s: 1.0}\n",
            "<root>",
            ("duplicate key 'vehicle'",),
        ),
        HostileConfig(
            "duplicate_nested_key",
            _with(base, "start:", "start:\n  takeoff_altitude_m: 10.0\n  takeoff_altitude_m: 30.0"),
            "<root>",
            ("duplicate key 'takeoff_altitude_m'",),
        ),
        HostileConfig("unknown_section", base.encode() + b"\nturbo: true\n", "turbo"),
        HostileConfig(
            "section_not_mapping", _with(base, "geofence:", "geofence: 5\nunused:"), "geofence", ("(got 5)",)
        ),
        HostileConfig("top_level_list", b"- vehicle\n- camera\n", "<root>", ("expected a mapping",)),
        HostileConfig("top_level_string", b"fly safely\n", "<root>", ("expected a mapping",)),
        HostileConfig("two_documents", base.encode() + b"\n---\nvehicle: {}\n", "<root>", (PARSER_REFUSED,)),
        HostileConfig(
            "python_tag", b"vehicle: !!python/object/apply:os.system ['true']\n", "<root>", (PARSER_REFUSED,)
        ),
        HostileConfig("tab_indent", b"vehicle:\n\turl: udpin://0.0.0.0:14540\n", "<root>", (PARSER_REFUSED,)),
        HostileConfig("huge_integer", _with(base, "  frame_every: 10", "  frame_every: " + "9" * 5000), "<root>"),
        HostileConfig(
            "altitude_floor_negative",
            _with(base, "guidance:", "guidance:\n  perception_min_altitude_m: -1"),
            "guidance.perception_min_altitude_m",
            ("(got -1)",),
        ),
        HostileConfig("complex_key", b"? [a, b]\n: 1\n", "<root>", (PARSER_REFUSED,)),
        HostileConfig("string_for_number", takeoff("high"), "start.takeoff_altitude_m", ("(got 'high')",)),
        HostileConfig("long_key", base.encode() + b"\n" + b"k" * 100_000 + b": 1\n", "<root>", (PARSER_REFUSED,)),
    ]
    return out
