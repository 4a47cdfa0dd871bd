"""A fallback site flown end to end: the companion flies the SITL, its search's budget ends, it flies to the surveyed
site, checks it with its map and lands there; the flight replays identically. The logic frame by frame is in
tests/test_fallback.py; a 100-mission campaign in docs/results/fallback_crowded.md."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

from companion.app.replay import replay
from sitl.campaign.landing_kinds import LandingKind, landing_outcome_of_run
from sitl.testing.helpers import free_udp_port, sitl_mission_yaml, start_camera_sitl

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent
SITE_NE_M = (21.0, -4.0)  # north of the crowd's ROI, inside the fence; the park keeps objects off it


def test_when_the_search_time_is_used_up_the_vehicle_lands_at_the_surveyed_site_after_checking_it(
    tmp_path: Path, instance: int
) -> None:
    sitl = start_camera_sitl(
        tmp_path,
        instance,
        seed=1,
        gcs_port=free_udp_port(),
        lockstep=True,
        scenario={"clear_ne_m": [[*SITE_NE_M, 3.0]]},
    )
    text = sitl_mission_yaml(instance, flights_dir=tmp_path)
    text = text.replace("frame_every: 10", "frame_every: 1").replace("frame_format: jpeg", "frame_format: png")
    site = f"{{name: north_lawn, north_m: {SITE_NE_M[0]}, east_m: {SITE_NE_M[1]}, radius_m: 3.0}}"
    assert "\nguidance:\n" in text
    text = text.replace("\nguidance:\n", f"\nguidance:\n  mission_time_limit_s: 4.0\n  fallback: {{sites: [{site}]}}\n")
    mission = tmp_path / "mission.yaml"
    mission.write_text(text)
    try:
        fly = subprocess.run(
            [sys.executable, "-m", "companion.cli", "fly", "--config", str(mission), "--out", str(tmp_path / "flight")],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        truth = sitl.state()
    finally:
        sitl.stop()
    assert fly.returncode == 0, fly.stderr[-3000:]
    assert "ended in done (landed)" in fly.stdout
    outcome = landing_outcome_of_run(tmp_path / "flight")
    assert outcome.kind is LandingKind.FALLBACK_SITE
    assert outcome.site_ne_m == SITE_NE_M
    north_m, east_m, _ = truth["position_ned_m"]
    assert math.hypot(north_m - SITE_NE_M[0], east_m - SITE_NE_M[1]) <= 1.5  # down at the site's centre
    report = replay(tmp_path / "flight")
    assert report.identical, report.differences
