"""The environment of a mission's processes: one thread each, unless set by hand."""

from __future__ import annotations

import pytest

from sitl.harness.process import SINGLE_THREAD_ENV, child_env

pytestmark = pytest.mark.unit


def test_mission_processes_compute_on_one_thread_unless_told_otherwise(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in SINGLE_THREAD_ENV:
        monkeypatch.delenv(name, raising=False)
    env = child_env()
    assert env["OPENCV_FOR_THREADS_NUM"] == "1"
    assert env["OPENBLAS_NUM_THREADS"] == "1"
    assert env["LP_NUM_THREADS"] == "0"  # Mesa's llvmpipe draws in the rendering thread itself
    assert env["PYTHONUNBUFFERED"] == "1"
    monkeypatch.setenv("LP_NUM_THREADS", "4")  # by hand: the user's choice wins
    assert child_env()["LP_NUM_THREADS"] == "4"
