"""The warning for the people below, flown end to end: `slz fly` over the SITL in lockstep with people who may notice
the vehicle's warning and step away (scenario.reaction). The companion switches its warning output on at the final
descent's start and off at the touchdown through MAVSDK (MAV_CMD_DO_SET_ACTUATOR); the SITL's autopilot accepts it,
its warning device sounds during the descent, people near the landing point react, and the flight lands and replays
identically. The logic alone: tests/test_warning_device.py and tests/test_reaction.py; the paired campaign:
docs/results/warning_walkers.md."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.flightlog.flight_log import FlightLog, RecordKind
from companion.tools.replay import replay
from sitl.testing.helpers import fly_to_the_end, free_udp_port, start_camera_sitl, write_sitl_mission

pytestmark = pytest.mark.sitl


def test_the_warning_sounds_from_the_descents_start_to_the_touchdown_and_people_near_the_vehicle_react(
    tmp_path: Path, instance: int
) -> None:
    scenario = {"moving_fraction": 0.2, "reaction": {"enabled": True, "warning_actuator": 2}}
    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port(), lockstep=True, scenario=scenario)
    warning = "  warning: {enabled: true, actuator: 2}"
    mission = write_sitl_mission(tmp_path, instance, replayable=True, guidance=warning)
    fly = fly_to_the_end(sitl, mission, tmp_path / "flight")
    assert fly.returncode == 0, fly.stderr[-3000:]
    assert "ended in done (landed)" in fly.stdout
    log = FlightLog.read(tmp_path / "flight")
    switches = log.of(RecordKind.WARNING)
    assert [(r["on"], r["sent"]) for r in switches] == [(True, True), (False, True)]
    assert switches[0]["phase"] == "descent"
    assert switches[-1]["event"] == "landed"
    first_descent = next(r for r in log.of(RecordKind.DECISION) if r["decision"]["phase"] == "descent")
    assert switches[0]["t_s"] == first_descent["t_s"]
    assert not [r for r in log.of(RecordKind.ERROR) if r.get("where") == "warning"]  # the autopilot accepted both
    # The SITL's autopilot took both commands on output 2: its device sounded once and is silent after the touchdown;
    # people within 12 m of the point under the vehicle reacted to it.
    assert fly.truth["warning"]["times_on"] == 1
    assert fly.truth["warning"]["on"] is False
    assert fly.truth["warning"]["reactions"] > 0
    report = replay(tmp_path / "flight")
    assert report.identical, report.differences
