"""Parts of the SITL vehicle process on their own: its fault schedule, its run end, its truth and trajectory writers,
and the lockstep gate's check that an acknowledgement does not overtake the client's MAVLink."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from companion.vehicle.sim_control import LockstepAck, SetpointNedYaw
from sitl.config import FaultConfig, FaultKind
from sitl.timing.lockstep_gate import LockstepGate
from sitl.vehicle.fault_schedule import FaultSchedule
from sitl.vehicle.run_end import RunEnd
from sitl.vehicle.trajectory_log import HEADER, TrajectoryLog
from sitl.vehicle.truth import TruthRecord, TruthWriter, read_truth

pytestmark = pytest.mark.unit


def test_faults_come_once_each_in_time_order() -> None:
    schedule = FaultSchedule(
        [FaultConfig(kind=FaultKind.LINK_LOSS, at_s=5.0), FaultConfig(kind=FaultKind.CAMERA_FAIL, at_s=2.0)]
    )
    assert schedule
    assert schedule.due(1.9) == []
    assert [f.kind for f in schedule.due(2.0)] == [FaultKind.CAMERA_FAIL]
    assert schedule.due(3.0) == []
    assert [f.kind for f in schedule.due(9.0)] == [FaultKind.LINK_LOSS]
    assert not schedule


def test_a_released_run_ends_when_disarmed_or_after_its_time_on_the_ground() -> None:
    assert RunEnd(None).reached(100.0, released=True, armed=False, on_ground=True) is None  # never by itself
    end = RunEnd(2.0)
    assert end.reached(10.0, released=False, armed=False, on_ground=True) is None  # the client still steps
    assert end.reached(10.0, released=True, armed=True, on_ground=False) is None
    assert end.reached(11.0, released=True, armed=True, on_ground=True) is None  # first seen on the ground
    assert end.grounded_s == 11.0
    assert end.reached(12.9, released=True, armed=True, on_ground=True) is None
    why = end.reached(13.0, released=True, armed=True, on_ground=True)
    assert why is not None
    assert "on the ground since 11.000 s" in why
    disarmed = RunEnd(2.0).reached(10.0, released=True, armed=False, on_ground=False)
    assert disarmed is not None
    assert disarmed.startswith("disarmed")


def test_the_truth_writer_writes_what_the_reader_reads(tmp_path: Path) -> None:
    path = tmp_path / "run" / "truth.jsonl"
    writer = TruthWriter(path, seed=7)
    people = {"t_s": 0.0, "positions_ne_m": [[1.0, 2.0], [3.0, 4.0]], "radii_m": [0.3, 0.25], "moving": [False, True]}
    writer.write(0.0, people, TruthRecord(0.0, (0.0, 0.0, -10.0), True, "OFFBOARD", "IN_AIR", False))
    people["positions_ne_m"] = [[1.0, 2.0], [3.5, 4.0]]
    writer.write(0.1, people, TruthRecord(0.1, (0.1, 0.0, -9.9), True, "OFFBOARD", "IN_AIR", False))
    writer.close()
    header, records = read_truth(path)
    assert header.seed == 7
    assert header.moving == (False, True)
    assert [r.t_s for r in records] == [0.0, 0.1]
    assert records[1].people_ne_m is not None
    np.testing.assert_array_equal(records[1].people_ne_m, [[1.0, 2.0], [3.5, 4.0]])


def test_the_trajectory_log_writes_at_its_rate_and_when_forced(tmp_path: Path) -> None:
    class State:
        position_ned_m = np.array([1.0, 2.0, -3.0])
        velocity_ned_mps = np.zeros(3)
        quaternion_wxyz = np.array([1.0, 0.0, 0.0, 0.0])

    log = TrajectoryLog(tmp_path / "log.csv", rate_hz=10.0)
    for k in range(30):  # 100 Hz for 0.3 s: rows at 0, 0.1, 0.2
        t_s = 0.01 * k
        if log.due(t_s):
            log.write(t_s, State(), True, "OFFBOARD", "IN_AIR", force=False)  # type: ignore[arg-type]
    log.write(0.295, State(), True, "AUTO.LAND", "LANDING", force=True)  # type: ignore[arg-type]
    log.close()
    lines = (tmp_path / "log.csv").read_text().splitlines()
    assert lines[0] + "\n" == HEADER
    assert [float(line.split(",")[0]) for line in lines[1:]] == pytest.approx([0.0, 0.1, 0.2, 0.295])
    assert lines[-1].endswith(",1,AUTO.LAND,LANDING")


def test_an_acknowledgement_passes_only_once_the_clients_mavlink_has_arrived() -> None:
    received = {(245, 191): 3}
    counted = LockstepAck(1, counted=(4, 245, 191))
    assert not LockstepGate.ack_covers_mavlink(counted, None, {}, lambda s: received.get(s, 0))
    received[(245, 191)] = 4
    assert LockstepGate.ack_covers_mavlink(counted, None, {}, lambda s: received.get(s, 0))
    setpoint = SetpointNedYaw(1.0, 2.0, -10.0, 0.5)
    expects = LockstepAck(1, expect_setpoint=(1.0, 2.0, -10.0, 0.5), expect_commands={176: 1})
    assert not LockstepGate.ack_covers_mavlink(expects, None, {176: 1}, lambda s: 0)  # no setpoint yet
    assert not LockstepGate.ack_covers_mavlink(expects, setpoint, {}, lambda s: 0)  # the command not yet
    assert LockstepGate.ack_covers_mavlink(expects, setpoint, {176: 1}, lambda s: 0)
