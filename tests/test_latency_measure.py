"""scripts/measure_latency.py finds a camera's latency from a recorded flight: frames rendered by the SITL's camera
while the vehicle yaws, logged with poses a known latency error away, give that error back."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.app.mission import MissionConfig
from companion.flightlog.flight_log import RecordKind
from companion.flightlog.recorder import FlightRecorder
from companion.geometry import Pose
from sitl.config import SitlConfig
from sitl.dynamics.base import VehicleState
from sitl.testing.helpers import run_python

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent
RATE_HZ = 10.0
SECONDS = 8.0


def yaw_rad(t_s: float) -> float:
    """The pilot yaws the hovering vehicle left and right: 30 degrees either way, every 2.5 s."""
    return math.radians(30.0) * math.sin(2.0 * math.pi * 0.4 * t_s)


def pose_at(t_s: float) -> tuple[VehicleState, Pose]:
    half = yaw_rad(t_s) / 2.0
    q = np.array([math.cos(half), 0.0, 0.0, math.sin(half)])  # about NED's down axis: clockwise from above
    state = VehicleState(position_ned_m=np.array([2.0, -3.0, -14.0]), quaternion_wxyz=q, on_ground=False)
    return state, Pose.from_ned_quaternion(2.0, -3.0, -14.0, q)


def record_yawing_flight(out: Path, instance: int, configured_s: float, true_s: float) -> None:
    """A flight log as `slz fly` writes one for a camera stamped with ``configured_s`` of latency when it has
    ``true_s``: each frame is what the camera saw at its true exposure, paired with the pose at its logged time."""
    from sitl.vehicle.sim_camera import SimCamera

    mission = MissionConfig.model_validate({"camera": {"latency_s": configured_s}})
    recorder = FlightRecorder(out, frame_every=1, lossless=True)
    recorder.write(RecordKind.HEADER, None, config=mission.model_dump(mode="json"))
    camera = SimCamera(SitlConfig.model_validate({"instance": instance, "seed": 4, "camera": {"enabled": True}}))
    try:
        for seq in range(int(SECONDS * RATE_HZ)):
            exposed_s = seq / RATE_HZ
            logged_s = exposed_s + (true_s - configured_s)  # arrival minus the configured latency
            state, _ = pose_at(exposed_s)
            _, logged_pose = pose_at(logged_s)
            recorder.frame(seq, logged_s, camera.draw(exposed_s, state))
            recorder.write(
                RecordKind.FRAME_RESULT,
                logged_s,
                seq=seq,
                T_world_body=logged_pose.T_world_body,
                tracks=[],
                target=None,
            )
    finally:
        camera.close()
        recorder.close()


def test_the_frames_of_a_yawing_vehicle_show_the_cameras_latency(tmp_path: Path, instance: int) -> None:
    record_yawing_flight(tmp_path / "flight", instance, configured_s=0.05, true_s=0.17)
    done = run_python("scripts/measure_latency.py", str(tmp_path / "flight"))
    assert done.returncode == 0, done.stderr
    first, *rest = done.stdout.splitlines()
    assert first.startswith("flown with camera.latency_s 0.050 s; the frames show +0.1")
    latency_s = float(rest[-1].split(":")[1])
    assert latency_s == pytest.approx(0.17, abs=0.015)


def test_a_flight_that_does_not_turn_says_what_to_do(tmp_path: Path) -> None:
    spec = importlib.util.spec_from_file_location("slz_measure_latency", REPO_ROOT / "scripts" / "measure_latency.py")
    assert spec is not None
    assert spec.loader is not None
    tool = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = tool  # its dataclasses look their module up
    spec.loader.exec_module(tool)
    times = [k / RATE_HZ for k in range(40)]
    with pytest.raises(tool.LatencyError, match=r"turned 0\.0 degrees in all: yaw it left and right"):
        tool.fit_correction(times, [5.0] * 40, [0.0] * 40)
    with pytest.raises(tool.LatencyError, match="4 frame pairs with a measured turn; at least 20 are needed"):
        tool.fit_correction(times, [5.0] * 40, [None] * 36 + [0.0] * 4)
