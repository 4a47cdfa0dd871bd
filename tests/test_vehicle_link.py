"""The companion's MAVSDK link flies the SITL over real UDP: stamped poses, takeoff, offboard, land."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from sitl.harness.process import SitlProcess
from sitl.testing.helpers import api_port

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent


def test_the_link_takes_off_flies_offboard_and_lands(tmp_path: Path, instance: int) -> None:
    sitl = SitlProcess(["--speed", "2"], instance, tmp_path).start()
    try:
        client = subprocess.run(
            [sys.executable, str(REPO_ROOT / "tests/clients/companion_link.py"), "--port", str(api_port(instance))],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
            timeout=120,
        )
    finally:
        sitl.stop()
    events = [json.loads(line) for line in client.stdout.splitlines() if line.startswith("{")]
    names = [e["event"] for e in events]
    assert client.returncode == 0, f"{events}\n{client.stderr[-2000:]}\n{sitl.log_tail()}"
    assert names == ["connected", "poses", "took_off", "reached", "landed"]
    poses = events[1]
    assert poses["clock_now_s"] >= poses["latest_t_s"] - 0.05  # the clock follows the autopilot's stamps
    reached = events[3]
    assert reached["mode"] == "OFFBOARD"
    assert reached["north_m"] == pytest.approx(3.0, abs=0.3)
    assert reached["altitude_m"] == pytest.approx(5.0, abs=0.3)
    assert reached["interpolation_step_m"] < 0.05  # 5 ms earlier, a few millimetres away
    assert events[4]["dropped"] == 0
