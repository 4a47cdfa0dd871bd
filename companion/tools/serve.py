"""``slz serve``: run ``slz`` commands one after another in one warm process (a campaign's worker).

Starting a Python process that imports the flight stack (numpy, OpenCV, onnxruntime, MAVSDK; the SITL's renderer and
its OpenGL context) costs seconds of CPU, several times a short mission's share of it. A warm process pays that once:
it reads one request per line of standard input and runs the command it names exactly as ``slz <argv>`` would in a
fresh process (the same parser, config checks and exit codes), each in fresh objects. What the process keeps between
commands is only what a command never changes: imported modules and process-wide caches such as the SITL's
offscreen renderer.

Protocol (JSON, one object per line):

- the process says ``{"ready": pid}`` on standard output once its ``--preload`` modules are imported;
- a request is ``{"argv": [...], "log": "path"}``: the command's standard output and error (file descriptors 1
  and 2, so the output of native libraries and of child processes too) go to ``log`` (truncated) while it runs;
  between commands standard output goes nowhere and standard error to the process's own (its start-up log);
- its reply is ``{"exit_code": n}``, plus ``"error"`` when it raised (the traceback is in its log);
- end of input ends the process (exit 0);
- when the process that started it (its owner) ends, a command still running gets ``OWNER_GONE_GRACE_S`` to end on
  the SIGTERM the owner's death sent it (``die_with_parent``), then the process exits (code 1): a warm process never
  outlives the worker it serves, whatever its command is doing.

Replies go to a private copy of the original standard output, which no command and no child process can write to.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import logging
import os
import select
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, TextIO

from companion.errors import SlzError
from companion.json_value import JsonObject

logger = logging.getLogger(__name__)

OWNER_GONE_GRACE_S = 10.0
"""What a command still running gets to end once the owner is gone (s): a flight's own SIGTERM handling takes 3 s."""


class ServeError(SlzError):
    """A request that cannot be served (what was wrong with it)."""


def _stdout_to_null() -> None:
    """Point file descriptor 1 at ``/dev/null``."""
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    os.close(null)


@contextlib.contextmanager
def output_to(log_path: Path, stderr_after: int) -> Iterator[None]:
    """Point file descriptors 1 and 2 at ``log_path`` (created, truncated) for the block; then 1 at ``/dev/null`` and
    2 back at ``stderr_after`` (the process's own log)."""
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    log_path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        os.dup2(fd, 1)
        os.dup2(fd, 2)
    finally:
        os.close(fd)
    try:
        yield
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        _stdout_to_null()
        os.dup2(stderr_after, 2)


def parse_request(line: str) -> tuple[list[str], Path]:
    """A request line's command and log path; :class:`ServeError` naming the fault."""
    try:
        request: Any = json.loads(line)
    except json.JSONDecodeError as exc:
        raise ServeError(f"not JSON: {exc}") from None
    if not isinstance(request, dict):
        raise ServeError("a request is a JSON object with 'argv' and 'log'")
    argv, log = request.get("argv"), request.get("log")
    if not isinstance(argv, list) or not all(isinstance(a, str) for a in argv) or not argv:
        raise ServeError("'argv' must be a non-empty list of strings")
    if not isinstance(log, str) or not log:
        raise ServeError("'log' must be a file path")
    return argv, Path(log)


def run_one(run: Callable[[Sequence[str]], int], argv: list[str]) -> JsonObject:
    """``run(argv)``'s exit code as a reply; an exception is written to the command's log and named in the reply.

    Signal handlers a command installs (``slz sitl`` stops its vehicle on SIGTERM) are put back when it ends, so
    between commands SIGTERM and SIGINT end the process as they would end a fresh one."""
    handlers = {signum: signal.getsignal(signum) for signum in (signal.SIGTERM, signal.SIGINT)}
    try:
        return {"exit_code": int(run(argv))}
    except SystemExit as exc:  # argparse's usage errors, sys.exit() in a command
        code = exc.code
        return {"exit_code": code if isinstance(code, int) else (0 if code is None else 1)}
    except Exception as exc:
        traceback.print_exc()
        return {"exit_code": 1, "error": f"{type(exc).__name__}: {exc}"}
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)


def watch_owner(
    owner_pid: int,
    finished: threading.Event,
    grace_s: float = OWNER_GONE_GRACE_S,
    exit_now: Callable[[int], object] = os._exit,
) -> None:
    """Wait for the process ``owner_pid`` to end, then up to ``grace_s`` for ``finished`` (the serve loop's end);
    unless it came, ``exit_now(1)``.

    Runs in a daemon thread of :func:`serve` for as long as the process lives. The wait is on a pidfd of the owner
    (Linux; elsewhere, as :func:`sitl.harness.process.die_with_parent`, there is no watch)."""
    if sys.platform != "linux":
        return
    try:
        owner: int | None = os.pidfd_open(owner_pid)
    except ProcessLookupError:  # gone before the watch began
        owner = None
    if owner is not None:
        try:
            select.select([owner], [], [])  # readable once the owner has ended: no deadline, the watch is the process's
        finally:
            os.close(owner)
    if finished.wait(grace_s):
        return
    logger.warning("the process that owned this one ended %g s ago and its command still runs: exiting", grace_s)
    exit_now(1)


def serve(run: Callable[[Sequence[str]], int], preload: Sequence[str] = (), requests: TextIO | None = None) -> int:
    """Serve requests from ``requests`` (standard input) until its end (see the module docstring); returns 0."""
    finished = threading.Event()
    owner = threading.Thread(target=watch_owner, args=(os.getppid(), finished), name="serve-owner-watch", daemon=True)
    owner.start()  # a daemon: nothing joins it, the process's end stops it
    for module in preload:
        importlib.import_module(module)
    reply = os.fdopen(os.dup(1), "w", buffering=1)  # os.dup: not inherited by child processes
    own_stderr = os.dup(2)  # the process's own log, between commands
    _stdout_to_null()  # between commands nothing may reach the reply stream
    reply.write(json.dumps({"ready": os.getpid()}) + "\n")
    for line in requests if requests is not None else sys.stdin:
        if not line.strip():
            continue
        try:
            argv, log_path = parse_request(line)
        except ServeError as exc:
            reply.write(json.dumps({"exit_code": 2, "error": str(exc)}) + "\n")
            continue
        with output_to(log_path, own_stderr):
            answer = run_one(run, argv)
        reply.write(json.dumps(answer) + "\n")
    finished.set()
    reply.close()
    return 0
