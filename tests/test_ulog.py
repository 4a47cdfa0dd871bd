"""The SITL's PX4 ULog writer read back by pyulog (the reader Flight Review uses), and the report's reader of a
ULog refusing what does not belong with a flight (issue 67)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from companion.tools.autopilot_log import AutopilotLogError, check_same_flight, read_autopilot_log
from sitl.autopilot.flight_ulog import TOPICS
from sitl.autopilot.ulog import Topic, ULogError, ULogWriter

pytestmark = pytest.mark.unit
pyulog = pytest.importorskip("pyulog")


def _write(path: Path, start_s: float) -> None:
    writer = ULogWriter(path, 0)
    writer.start(
        TOPICS,
        {"sys_name": "test", "ver_sw_release": "v1.15.0"},
        {"COM_OF_LOSS_T": (1.0, False), "MAV_SYS_ID": (7, True)},
    )
    for k in range(100):  # 2 s at 50 Hz: armed in AUTO.LOITER (4), then OFFBOARD (14) from 1 s, a failsafe at 1.5 s
        us = round((start_s + k / 50.0) * 1e6)
        nav = 4 if k < 50 else 14
        writer.data("vehicle_status", us, 0, 0, 2, nav, 1, k >= 75, 7, 1)
        writer.data("vehicle_local_position", us, us, True, True, True, True, 1.0, 2.0, -0.1 * k, 0.0, 0.0, -5.0, 0.5)
        writer.data("vehicle_attitude", us, us, 1.0, 0.0, 0.0, 0.0)
        writer.data("trajectory_setpoint", us, 1.0, 2.0, -10.0, *(math.nan,) * 9, 0.5, math.nan)
    writer.data("vehicle_command_ack", round(start_s * 1e6), 400, 0, 255)
    writer.log(round((start_s + 1.5) * 1e6), 2, "Failsafe: Offboard lost, position")
    writer.parameter("COM_OF_LOSS_T", 2.0, False)
    writer.close()


def test_a_written_ulog_reads_back_in_pyulog_field_for_field(tmp_path: Path) -> None:
    path = tmp_path / "flight.ulg"
    _write(path, 10.0)
    ulog = pyulog.ULog(str(path))
    assert ulog.msg_info_dict["sys_name"] == "test"
    assert ulog.initial_parameters == {"COM_OF_LOSS_T": 1.0, "MAV_SYS_ID": 7}
    assert [(name, value) for _, name, value in ulog.changed_parameters] == [("COM_OF_LOSS_T", 2.0)]
    assert {d.name for d in ulog.data_list} == {
        "vehicle_status",
        "vehicle_local_position",
        "vehicle_attitude",
        "trajectory_setpoint",
        "vehicle_command_ack",
    }
    position = ulog.get_dataset("vehicle_local_position").data
    assert position["timestamp"][0] == 10_000_000
    assert position["timestamp"][-1] == 11_980_000
    np.testing.assert_allclose(position["z"][:3], [0.0, -0.1, -0.2], atol=1e-6)
    assert position["x"].dtype == np.float32
    setpoint = ulog.get_dataset("trajectory_setpoint").data
    assert setpoint["position[2]"][0] == -10.0
    assert math.isnan(setpoint["velocity[0]"][0])
    assert [m.message for m in ulog.logged_messages] == ["Failsafe: Offboard lost, position"]
    assert ulog.logged_messages[0].log_level_str() == "CRITICAL"


def test_the_reports_reader_takes_modes_failsafes_and_commands_and_refuses_another_flight(tmp_path: Path) -> None:
    path = tmp_path / "flight.ulg"
    _write(path, 10.0)
    log = read_autopilot_log(path)
    assert log.modes == [(10.0, "AUTO.LOITER"), (11.0, "OFFBOARD")]
    assert log.failsafes == [(10.0, False), (11.5, True)]
    assert log.commands == [(10.0, "arm/disarm", "accepted")]
    assert log.messages == [(11.5, "critical", "Failsafe: Offboard lost, position")]
    check_same_flight(log, 9.0, 30.0)  # overlaps: fine
    with pytest.raises(AutopilotLogError, match=r"does not overlap the flight log's .* another flight or another boot"):
        check_same_flight(log, 100.0, 200.0)


def test_what_is_not_an_autopilots_ulog_is_refused_naming_the_file(tmp_path: Path) -> None:
    junk = tmp_path / "junk.ulg"
    junk.write_bytes(b"not a ulog at all")
    with pytest.raises(AutopilotLogError, match=r"junk\.ulg: not a readable ULog"):
        read_autopilot_log(junk)
    bare = tmp_path / "bare.ulg"
    writer = ULogWriter(bare, 0)
    writer.start([Topic("sensor", (("uint64_t", "timestamp"), ("float", "x")))], {}, {})
    writer.data("sensor", 1, 0.5)
    writer.close()
    with pytest.raises(AutopilotLogError, match="no vehicle_status topic"):
        read_autopilot_log(bare)
    with pytest.raises(AutopilotLogError, match="no such file"):
        read_autopilot_log(tmp_path / "missing.ulg")


def test_the_writer_refuses_what_the_format_cannot_say(tmp_path: Path) -> None:
    with pytest.raises(ULogError, match="the first field must be uint64_t timestamp"):
        Topic("bad", (("float", "x"),))
    with pytest.raises(ULogError, match="unknown field type 'half'"):
        Topic("bad", (("uint64_t", "timestamp"), ("half", "x")))
    writer = ULogWriter(tmp_path / "w.ulg", 0)
    writer.start([Topic("t", (("uint64_t", "timestamp"), ("float[2]", "v")))], {}, {})
    with pytest.raises(ULogError, match="topic 'u' was not defined"):
        writer.data("u", 1)
    with pytest.raises(ULogError, match="topic t:"):
        writer.data("t", 1, 0.5)  # one value for float[2]
    with pytest.raises(ULogError, match="written already"):
        writer.start([], {}, {})
    writer.close()
