"""The README's and the docs' examples are tests.

- Every ``python`` code block of README.md and docs/*.md runs, as a user would paste it: its own interpreter, from the
  repository root, and must exit 0.
- Every code block whose info string is ``sh test`` (rendered as shell) runs, each line a command in bash from the
  repository root with this venv's ``bin`` first on ``PATH``, and must exit 0.
- Every code block whose info string is ``sh terminals`` runs as two terminals would: the commands under
  ``# terminal 1`` start in the background (a SITL), then those under ``# terminal 2`` run one after another and must
  exit 0. The SITL runs on a leased instance (``--instance N``) and ``mission_configs/sitl.yaml`` is read on that
  instance's ports, so the test shares the machine; otherwise the commands are the documented ones.
- Every ``slz`` command line shown (code blocks and inline code, synopses included) names commands and options
  that ``slz`` has, and every ``make TARGET`` shown is a target of the Makefile: a renamed option or target fails here.

Other shell blocks are synopses or need a vehicle, a Jetson or root (``/etc/slz``), and are not run.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from companion.cli import build_parser

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parent.parent
DOCS = [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md")), REPO_ROOT / "deploy" / "README.md"]
FENCE = re.compile(r"^```([^\n`]*)\n(.*?)^```", re.S | re.M)
INLINE = re.compile(r"`([^`\n]+)`")


@dataclass(frozen=True)
class Block:
    """One fenced code block: where it is, its info string and its text."""

    path: Path
    line: int
    info: str
    text: str

    @property
    def id(self) -> str:
        return f"{self.path.relative_to(REPO_ROOT)}:{self.line}"


def blocks() -> list[Block]:
    found = []
    for path in DOCS:
        text = path.read_text()
        for match in FENCE.finditer(text):
            line = text.count("\n", 0, match.start()) + 1
            found.append(Block(path, line, match.group(1).strip(), match.group(2)))
    return found


def runnable(language: str) -> list[Block]:
    if language == "python":
        return [b for b in blocks() if b.info.split()[:1] == ["python"]]
    return [b for b in blocks() if b.info.split() in (["sh", "test"], ["bash", "test"])]


def shown_commands(program: str) -> list[tuple[str, str]]:
    """``(where, words after the program)`` for every ``program ...`` line in a code block or an inline code span of
    the docs (``program`` also as a path, ``/opt/slz/venv/bin/slz doctor ...``); comments cut off."""
    call = re.compile(rf"(?:^|\s)(?:\S*/)?{program} ((?:[a-z]|--).*)")
    shown: list[tuple[str, str]] = []
    for path in DOCS:
        text = path.read_text()
        pieces = [(m.start(), line) for m in FENCE.finditer(text) for line in m.group(2).splitlines()]
        pieces += [
            (m.start(), m.group(1)) for m in INLINE.finditer(FENCE.sub(lambda f: "\n" * f.group(0).count("\n"), text))
        ]
        for pos, piece in pieces:
            hit = call.search(piece)
            if hit is not None:
                where = f"{path.relative_to(REPO_ROOT)}:{text.count(chr(10), 0, pos) + 1}"
                shown.append((where, hit.group(1).split(" #", 1)[0].strip()))
    return shown


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def option_names(parser: argparse.ArgumentParser) -> set[str]:
    return {option for action in parser._actions for option in action.option_strings}


def problems_with(command: str, parser: argparse.ArgumentParser) -> list[str]:
    """What in ``command`` (the words after ``slz``) the parser does not have: commands, then options."""
    words = [w.strip("[]()") for w in command.replace("\\|", "|").split()]
    path = ["slz"]
    for word in words:  # the command path: slz campaign replay ...
        choices = subcommands(parser)
        if word in choices:
            parser = choices[word]
            path.append(word)
        elif not word.startswith("-") and choices and len(path) == 1:
            return [f"slz has no command {word!r}"]
        else:
            break
    known = option_names(parser)
    return [
        f"{' '.join(path)} has no option {option}"
        for word in words
        if word.startswith("--") and (option := word.split("=", 1)[0]) not in known
    ]


def make_targets() -> set[str]:
    text = (REPO_ROOT / "Makefile").read_text()
    return set(re.findall(r"^([A-Za-z][\w-]*):", text, re.M))


def test_the_docs_have_examples_to_check() -> None:
    assert runnable("python"), "the README's library example is gone"
    assert runnable("sh"), "no `sh test` block left to run"
    assert len(shown_commands("slz")) >= 30
    assert len(shown_commands("make")) >= 5


@pytest.mark.parametrize("block", runnable("python"), ids=lambda b: b.id)
def test_a_python_example_runs_as_written(block: Block) -> None:
    run = subprocess.run(
        [sys.executable, "-c", block.text],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    assert "Traceback" not in run.stderr


@pytest.mark.parametrize("block", runnable("sh"), ids=lambda b: b.id)
def test_a_shell_example_marked_test_runs_as_written(block: Block) -> None:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    run = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", block.text],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        check=False,
    )
    assert run.returncode == 0, (run.stdout[-2000:], run.stderr[-2000:])
    assert "Traceback" not in run.stderr


def terminals(block: Block) -> dict[int, list[str]]:
    """The commands of a ``sh terminals`` block by terminal number (``# terminal N`` comment lines start each)."""
    found: dict[int, list[str]] = {}
    current = None
    for line in block.text.splitlines():
        header = re.match(r"#\s*terminal (\d+)", line.strip())
        if header:
            current = int(header.group(1))
            found[current] = []
        elif line.strip() and not line.strip().startswith("#"):
            assert current is not None, f"{block.id}: a command before the first '# terminal N'"
            found[current].append(line.split(" #", 1)[0].strip())
    return found


TERMINAL_BLOCKS = [b for b in blocks() if b.info.split() == ["sh", "terminals"]]


@pytest.mark.sitl
@pytest.mark.parametrize("block", TERMINAL_BLOCKS, ids=lambda b: b.id)
def test_a_two_terminal_example_runs_as_written(block: Block, tmp_path: Path, instance: int) -> None:
    from sitl.testing.helpers import sitl_mission_yaml

    steps = terminals(block)
    assert sorted(steps) == [1, 2], steps
    assert steps[1] == ["slz sitl"], "terminal 1 starts the SITL alone"
    mission = tmp_path / "sitl.yaml"  # mission_configs/sitl.yaml on the leased instance's ports, logs in tmp_path
    mission.write_text(sitl_mission_yaml(instance, flights_dir=tmp_path))
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    log = (tmp_path / "sitl.log").open("wb")
    sitl = subprocess.Popen(
        ["bash", "-c", f"exec {steps[1][0]} --instance {instance}"],
        cwd=REPO_ROOT,
        stdout=log,
        stderr=subprocess.STDOUT,
        env=env,
    )
    outputs = []
    try:
        for command in steps[2]:
            run = subprocess.run(
                ["bash", "-euo", "pipefail", "-c", command.replace("mission_configs/sitl.yaml", str(mission))],
                cwd=REPO_ROOT,
                capture_output=True,
                text=True,
                timeout=240,
                env=env,
                check=False,
            )
            assert run.returncode == 0, (command, run.stdout[-3000:], run.stderr[-3000:])
            assert "Traceback" not in run.stderr
            outputs.append(run.stdout)
    finally:
        sitl.terminate()
        try:
            sitl.wait(timeout=10)
        except subprocess.TimeoutExpired:
            sitl.kill()
            sitl.wait()
        log.close()
    assert sitl.returncode is not None
    doctor, flown = outputs
    assert doctor.rstrip().endswith("ready to fly")
    assert "PASS camera:" in doctor
    assert "fly: landed; ended in done (landed)" in flown


def test_every_slz_command_shown_has_its_command_and_options() -> None:
    parser = build_parser()
    problems = [f"{where}: {p}" for where, command in shown_commands("slz") for p in problems_with(command, parser)]
    assert problems == []


def test_every_make_target_shown_exists() -> None:
    targets = make_targets()
    missing = []
    for where, command in shown_commands("make"):
        words = [w for w in command.split() if re.fullmatch(r"[a-z][\w-]*", w)]  # not VAR=value, not options
        missing += [f"{where}: make {w}" for w in words if w not in targets]
    assert missing == []


def test_the_checker_finds_a_wrong_option_and_a_wrong_command() -> None:
    parser = build_parser()
    assert problems_with("campaign --spec F --workers 2", parser) == []
    assert problems_with("campaign replay DIR MISSION", parser) == []
    assert problems_with("fly --config F --dryrun", parser) == ["slz fly has no option --dryrun"]
    assert problems_with("takeoff --now", parser) == ["slz has no command 'takeoff'"]
