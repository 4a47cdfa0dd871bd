"""The companion's MAVSDK link flies the SITL over real UDP: stamped poses, takeoff, offboard, land."""

from __future__ import annotations

import json
import subprocess
import sys
import time
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


async def test_the_link_takes_the_autopilots_system_id_or_refuses_one_that_differs(tmp_path: Path) -> None:
    # Issue 65: with `slz sitl --instance 5` the vehicle is system 6 and the companion stayed 1: ground-station
    # commands to system 6 never reached it. An instance above 0, so that the autopilot is not system 1.

    from companion.vehicle.link import VehicleError
    from companion.vehicle.mavsdk_link import MavsdkVehicleLink
    from sitl.config import SitlConfig
    from sitl.harness.instances import leased_instance

    with leased_instance(range(1, 40)) as lease:
        sysid = SitlConfig(instance=lease.instance).system_id
        sitl = SitlProcess([], lease.instance, tmp_path).start()
        url = f"udpin://0.0.0.0:{api_port(lease.instance)}"

        async def link_with(system_id: int | None) -> int:
            link = MavsdkVehicleLink(url, system_id=system_id)
            try:
                await link.connect(20.0)
                deadline = time.monotonic() + 20.0
                await link.telemetry.wait_for(
                    lambda: bool(link.telemetry.received.get("LOCAL_POSITION_NED")), deadline, "positions"
                )
                return link.system_id
            finally:
                await link.close()

        try:
            assert await link_with(None) == sysid  # taken from the heartbeat, telemetry flowing
            with pytest.raises(VehicleError, match=f"the autopilot is system {sysid}, vehicle.system_id says 1"):
                await link_with(1)
            assert await link_with(sysid) == sysid  # the right one, given
        finally:
            sitl.stop()
    assert sysid != 1
