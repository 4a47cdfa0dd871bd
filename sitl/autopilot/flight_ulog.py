"""The SITL's flight as a PX4 ULog (``ulog_path``), as PX4's own SITL logs every flight: the topics a Flight Review
page and pyulog users read first, under PX4 v1.15's names and fields, on the vehicle's clock.

Written: ``vehicle_status`` (arming, ``nav_state``, the failsafe flag), ``vehicle_local_position`` (NED, m and m/s,
the heading), ``vehicle_attitude`` (the quaternion), ``trajectory_setpoint`` (what the position controller follows,
NaN where not controlled), ``vehicle_land_detected``, ``battery_status`` at ``rate_hz`` (status, land and battery at a
tenth of it, and at once on a change of mode, arming or failsafe); ``vehicle_command`` and ``vehicle_command_ack`` for
every command the autopilot took; every STATUSTEXT it sent as a logged string; the parameters at the start and each
change. Timestamps are microseconds of the simulated time, the boot clock MAVLink's ``time_boot_ms`` counts, so a
companion's flight log (whose ``t_s`` is that clock) lines up with it to the sample.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sitl.autopilot.modes import FlightMode
from sitl.autopilot.status import LandedState, Severity
from sitl.autopilot.ulog import Topic, ULogWriter
from sitl.px4_params import ParamType

if TYPE_CHECKING:
    from sitl.autopilot.battery import Battery
    from sitl.autopilot.commander import Commander
    from sitl.autopilot.controller import Setpoint
    from sitl.autopilot.params import ParameterStore
    from sitl.dynamics.base import VehicleState

# vehicle_status.nav_state of PX4 v1.15 for each mode this autopilot flies.
NAV_STATE = {
    FlightMode.POSCTL: 2,
    FlightMode.AUTO_MISSION: 3,
    FlightMode.AUTO_LOITER: 4,
    FlightMode.AUTO_RTL: 5,
    FlightMode.OFFBOARD: 14,
    FlightMode.AUTO_TAKEOFF: 17,
    FlightMode.AUTO_LAND: 18,
    FlightMode.ORBIT: 21,
}
ARMING_STATE_DISARMED, ARMING_STATE_ARMED = 1, 2
VEHICLE_TYPE_ROTARY_WING = 1

TOPICS = [
    Topic(
        "vehicle_status",
        (
            ("uint64_t", "timestamp"),
            ("uint64_t", "armed_time"),
            ("uint64_t", "nav_state_timestamp"),
            ("uint8_t", "arming_state"),
            ("uint8_t", "nav_state"),
            ("uint8_t", "vehicle_type"),
            ("bool", "failsafe"),
            ("uint8_t", "system_id"),
            ("uint8_t", "component_id"),
        ),
    ),
    Topic(
        "vehicle_local_position",
        (
            ("uint64_t", "timestamp"),
            ("uint64_t", "timestamp_sample"),
            ("bool", "xy_valid"),
            ("bool", "z_valid"),
            ("bool", "v_xy_valid"),
            ("bool", "v_z_valid"),
            ("float", "x"),
            ("float", "y"),
            ("float", "z"),
            ("float", "vx"),
            ("float", "vy"),
            ("float", "vz"),
            ("float", "heading"),
        ),
    ),
    Topic("vehicle_attitude", (("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"), ("float[4]", "q"))),
    Topic(
        "trajectory_setpoint",
        (
            ("uint64_t", "timestamp"),
            ("float[3]", "position"),
            ("float[3]", "velocity"),
            ("float[3]", "acceleration"),
            ("float[3]", "jerk"),
            ("float", "yaw"),
            ("float", "yawspeed"),
        ),
    ),
    Topic(
        "vehicle_land_detected",
        (("uint64_t", "timestamp"), ("bool", "landed"), ("bool", "maybe_landed"), ("bool", "ground_contact")),
    ),
    Topic(
        "battery_status",
        (
            ("uint64_t", "timestamp"),
            ("float", "voltage_v"),
            ("float", "current_a"),
            ("float", "discharged_mah"),
            ("float", "remaining"),
            ("uint8_t", "warning"),
            ("bool", "connected"),
        ),
    ),
    Topic(
        "vehicle_command",
        (
            ("uint64_t", "timestamp"),
            ("double", "param5"),
            ("double", "param6"),
            ("float", "param1"),
            ("float", "param2"),
            ("float", "param3"),
            ("float", "param4"),
            ("float", "param7"),
            ("uint32_t", "command"),
            ("uint8_t", "target_system"),
            ("uint8_t", "target_component"),
            ("uint8_t", "source_system"),
            ("uint8_t", "source_component"),
            ("bool", "from_external"),
        ),
    ),
    Topic(
        "vehicle_command_ack",
        (("uint64_t", "timestamp"), ("uint32_t", "command"), ("uint8_t", "result"), ("uint8_t", "target_system")),
    ),
]


def _us(t_s: float) -> int:
    return max(0, round(t_s * 1e6))


class FlightULog:
    """The ULog of one SITL run (:mod:`sitl.autopilot.ulog` writes the format).

    Parameters
    ----------
    path : Path
        The ``.ulg`` file.
    rate_hz : float
        Samples of position, attitude and setpoint per simulated second.
    params : ParameterStore
        The parameters, logged at the start (changes: :meth:`parameter`).
    system_id : int
        The vehicle's MAVLink system id.
    """

    def __init__(self, path: Path, rate_hz: float, params: ParameterStore, system_id: int) -> None:
        self.writer = ULogWriter(path, 0)
        info = {
            "sys_name": "SLZ Lander SITL (PX4 v1.15 emulation)",
            "ver_sw_release": "v1.15.0",
            "ver_hw": "SITL",
            "sys_mcu": "none",
            "sys_os_name": "Linux",
            "sys_vehicle_type": "multirotor",
        }
        values = {name: (params.raw(name), params.spec(name).param_type is ParamType.INT32) for name in params.names()}
        self.writer.start(TOPICS, info, values)
        self.rate_hz = rate_hz
        self.system_id = system_id
        self._next_s = 0.0
        self._samples = 0
        self._last_status: tuple[int, int, bool] | None = None
        self._armed_at_us = 0
        self._mode_since_us = 0

    def due(self, t_s: float) -> bool:
        """Whether a sample is due at simulated ``t_s`` (s)."""
        return t_s >= self._next_s - 1e-9

    def sample(
        self,
        t_s: float,
        state: VehicleState,
        commander: Commander,
        setpoint: Setpoint | None,
        battery: Battery,
        battery_warning: int,
    ) -> None:
        """One sample at ``t_s``: position, attitude, setpoint; status, land and battery every tenth sample and at a
        change of mode, arming or failsafe."""
        self._next_s = t_s + 1.0 / self.rate_hz
        us = _us(t_s)
        w = self.writer
        n, e, d = (float(v) for v in state.position_ned_m)
        vn, ve, vd = (float(v) for v in state.velocity_ned_mps)
        qw, qx, qy, qz = (float(v) for v in state.quaternion_wxyz)
        heading = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        w.data("vehicle_local_position", us, us, True, True, True, True, n, e, d, vn, ve, vd, heading)
        w.data("vehicle_attitude", us, us, qw, qx, qy, qz)
        nan3 = (math.nan,) * 3
        if setpoint is not None:
            pos = tuple(float(v) for v in setpoint.position_ned_m)
            vel = tuple(float(v) for v in setpoint.velocity_ned_mps)
            w.data("trajectory_setpoint", us, *pos, *vel, *nan3, *nan3, float(setpoint.yaw_rad), math.nan)
        nav_state = NAV_STATE.get(commander.mode, 4)
        arming = ARMING_STATE_ARMED if commander.armed else ARMING_STATE_DISARMED
        status = (nav_state, arming, commander.failsafe is not None)
        if self._last_status is None or status[1] != self._last_status[1]:
            self._armed_at_us = us if commander.armed else 0
        if self._last_status is None or status[0] != self._last_status[0]:
            self._mode_since_us = us
        if status != self._last_status or self._samples % 10 == 0:
            w.data(
                "vehicle_status",
                us,
                self._armed_at_us,
                self._mode_since_us,
                arming,
                nav_state,
                VEHICLE_TYPE_ROTARY_WING,
                status[2],
                self.system_id,
                1,
            )
            landed = commander.landed_state is LandedState.ON_GROUND
            maybe = commander.landed_state in (LandedState.ON_GROUND, LandedState.LANDING)
            w.data("vehicle_land_detected", us, landed, maybe, bool(state.on_ground))
            w.data(
                "battery_status",
                us,
                battery.voltage_v,
                battery.current_a,
                battery.used_mah,
                battery.remaining,
                battery_warning,
                True,
            )
        if status != self._last_status:
            w.flush()  # a mode, arming or failsafe change reaches the disk at once
        self._last_status = status
        self._samples += 1

    def statustext(self, t_s: float, severity: Severity, text: str) -> None:
        """A STATUSTEXT the vehicle sent, as a logged string."""
        self.writer.log(_us(t_s), int(severity), text)

    def statustext_at(self, clock: Any, severity: Severity, text: str) -> None:
        """A STATUSTEXT sent now on ``clock`` (anything with ``now_s``, the simulated time)."""
        self.statustext(float(clock.now_s), severity, text)

    def command(self, t_s: float, msg: Any, result: int) -> None:
        """A COMMAND_LONG or COMMAND_INT the autopilot took (``msg``, pymavlink's) and its result."""
        us = _us(t_s)
        params = [float(getattr(msg, f"param{i}")) for i in range(1, 8)]
        if msg.get_type() == "COMMAND_INT":  # x, y, z in place of params 5-7
            params[4], params[5], params[6] = float(msg.x), float(msg.y), float(msg.z)
        self.writer.data(
            "vehicle_command",
            us,
            params[4],
            params[5],
            *params[:4],
            params[6],
            int(msg.command),
            int(msg.target_system),
            int(msg.target_component),
            int(msg.get_srcSystem()),
            int(msg.get_srcComponent()),
            True,
        )
        self.writer.data("vehicle_command_ack", us, int(msg.command), int(result), int(msg.get_srcSystem()))

    def parameter(self, name: str, value: float, is_int: bool) -> None:
        """A parameter set in flight."""
        self.writer.parameter(name, value, is_int)

    def close(self) -> None:
        """Flush and close the file."""
        self.writer.flush()
        self.writer.close()
