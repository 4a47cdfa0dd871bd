"""Preloaded by ``tests/test_warm.py`` into an ``slz serve`` process: at exit, after its commands, it writes a line
to standard error, which must reach the process's own standard error (not a command's log, not ``/dev/null``)."""

from __future__ import annotations

import atexit
import sys

atexit.register(lambda: sys.stderr.write("serve probe: exiting\n"))
