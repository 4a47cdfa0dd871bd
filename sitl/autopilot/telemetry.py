"""The telemetry a PX4 vehicle streams, built from the true state, scheduled per link in simulated time.

Each link has its own rates (SET_MESSAGE_INTERVAL changes them); timestamps are the simulated clock
(``time_boot_ms``, ``time_usec``), the one clock the companion reads. Position outputs carry seeded noise of the
configured size (an estimator's error); the controller flies the true state.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from sitl.autopilot.commander import Commander
from sitl.dynamics.base import VehicleState
from sitl.dynamics.rigid_body import quaternion_to_matrix
from sitl.geodesy import ned_to_geodetic

# Default stream rates, Hz (PX4's "onboard" profile for the API link, "normal" for the ground station).
API_RATES_HZ = {
    "SYS_STATUS": 2.0,
    "EXTENDED_SYS_STATE": 5.0,
    "ATTITUDE": 50.0,
    "ATTITUDE_QUATERNION": 50.0,
    "LOCAL_POSITION_NED": 50.0,
    "GLOBAL_POSITION_INT": 20.0,
    "GPS_RAW_INT": 5.0,
    "BATTERY_STATUS": 1.0,
    "HOME_POSITION": 0.5,
}
GCS_RATES_HZ = {
    "SYS_STATUS": 1.0,
    "EXTENDED_SYS_STATE": 1.0,
    "ATTITUDE": 10.0,
    "ATTITUDE_QUATERNION": 5.0,
    "LOCAL_POSITION_NED": 5.0,
    "GLOBAL_POSITION_INT": 5.0,
    "GPS_RAW_INT": 1.0,
    "BATTERY_STATUS": 0.5,
    "HOME_POSITION": 0.5,
}
MESSAGE_IDS = {
    "SYS_STATUS": mavlink.MAVLINK_MSG_ID_SYS_STATUS,
    "EXTENDED_SYS_STATE": mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
    "ATTITUDE": mavlink.MAVLINK_MSG_ID_ATTITUDE,
    "ATTITUDE_QUATERNION": mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
    "LOCAL_POSITION_NED": mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
    "GLOBAL_POSITION_INT": mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    "GPS_RAW_INT": mavlink.MAVLINK_MSG_ID_GPS_RAW_INT,
    "BATTERY_STATUS": mavlink.MAVLINK_MSG_ID_BATTERY_STATUS,
    "HOME_POSITION": mavlink.MAVLINK_MSG_ID_HOME_POSITION,
    "AUTOPILOT_VERSION": mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
}
NAMES_BY_ID = {v: k for k, v in MESSAGE_IDS.items()}

SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mavlink.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
    | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
)
PREARM_CHECK = 0x10000000  # MAV_SYS_STATUS_PREARM_CHECK


@dataclass
class Origin:
    """Geodetic position of the local NED origin."""

    lat_deg: float
    lon_deg: float
    alt_m: float


class Battery:
    """A 4S pack drained by thrust: voltage and remaining fraction."""

    def __init__(self, capacity_mah: float = 5000.0) -> None:
        self.capacity_mah = capacity_mah
        self.used_mah = 0.0
        self.current_a = 0.0

    def update(self, collective: float, dt_s: float, armed: bool) -> None:
        """Draw current for ``dt_s`` at a collective thrust in [0, 1]."""
        self.current_a = (0.5 + 40.0 * collective**1.5) if armed else 0.3
        self.used_mah += self.current_a * dt_s / 3.6

    @property
    def remaining(self) -> float:
        """Fraction of capacity left, [0, 1]."""
        return max(0.0, 1.0 - self.used_mah / self.capacity_mah)

    @property
    def voltage_v(self) -> float:
        """Pack voltage under load."""
        return 4 * (3.5 + 0.7 * self.remaining) - 0.01 * self.current_a


class StreamSchedule:
    """When each stream of one link is next due, in simulated seconds."""

    def __init__(self, rates_hz: dict[str, float]) -> None:
        self.intervals_s = {name: (1.0 / hz if hz > 0 else math.inf) for name, hz in rates_hz.items()}
        self._defaults = dict(self.intervals_s)
        self._next = dict.fromkeys(self.intervals_s, 0.0)

    def set_interval(self, name: str, interval_us: float) -> None:
        """SET_MESSAGE_INTERVAL semantics: -1 disables, 0 restores the default, > 0 sets the period."""
        if interval_us < 0:
            self.intervals_s[name] = math.inf
        elif interval_us == 0:
            self.intervals_s[name] = self._defaults.get(name, 1.0)
        else:
            self.intervals_s[name] = interval_us / 1e6
        self._next[name] = 0.0

    def due(self, t_s: float) -> list[str]:
        """Streams due at ``t_s``; each is rescheduled."""
        out = []
        for name, interval in self.intervals_s.items():
            if math.isfinite(interval) and t_s >= self._next.get(name, 0.0) - 1e-9:  # float sums of the period
                out.append(name)
                following = self._next.get(name, 0.0) + interval
                self._next[name] = following if following > t_s + 1e-9 else t_s + interval  # fell behind: re-phase
        return out


class TelemetryBuilder:
    """Builds telemetry messages from the state, commander and battery.

    Parameters
    ----------
    origin : Origin
        Geodetic origin of local NED.
    rng : numpy Generator
        Seeded source of position noise.
    position_noise_m : float
        Standard deviation of the noise added to reported positions.
    """

    def __init__(self, origin: Origin, rng: np.random.Generator, position_noise_m: float) -> None:
        self.origin = origin
        self.rng = rng
        self.position_noise_m = position_noise_m
        self._builders: dict[str, Callable[[Any, float, VehicleState, Commander, Battery], Any]] = {
            "SYS_STATUS": self._sys_status,
            "EXTENDED_SYS_STATE": self._extended_sys_state,
            "ATTITUDE": self._attitude,
            "ATTITUDE_QUATERNION": self._attitude_quaternion,
            "LOCAL_POSITION_NED": self._local_position,
            "GLOBAL_POSITION_INT": self._global_position,
            "GPS_RAW_INT": self._gps_raw,
            "BATTERY_STATUS": self._battery,
            "HOME_POSITION": self._home,
            "AUTOPILOT_VERSION": self._autopilot_version,
        }

    def can_build(self, name: str) -> bool:
        """True for the messages this autopilot sends."""
        return name in self._builders

    def build(self, name: str, mav: Any, t_s: float, state: VehicleState, cmd: Commander, battery: Battery) -> Any:
        """One message by name."""
        return self._builders[name](mav, t_s, state, cmd, battery)

    @staticmethod
    def heartbeat(mav: Any, cmd: Commander) -> Any:
        """HEARTBEAT as PX4 sends it."""
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if cmd.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        status = mavlink.MAV_STATE_ACTIVE if cmd.armed else mavlink.MAV_STATE_STANDBY
        if cmd.failsafe:
            status = mavlink.MAV_STATE_CRITICAL
        return mav.heartbeat_encode(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base, cmd.mode.custom_mode, status
        )

    def _noisy(self, p: np.ndarray) -> np.ndarray:
        if self.position_noise_m <= 0:
            return p
        return p + self.rng.normal(0.0, self.position_noise_m, size=3)

    @staticmethod
    def _boot_ms(t_s: float) -> int:
        return round(t_s * 1000.0) & 0xFFFFFFFF

    def _sys_status(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        health = SENSORS
        if cmd.rc_lost:
            health &= ~mavlink.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
        if cmd.armed or cmd.prearm_problem() is None:
            health |= PREARM_CHECK
        return mav.sys_status_encode(
            SENSORS | PREARM_CHECK,
            SENSORS | PREARM_CHECK,
            health,
            500,
            int(bat.voltage_v * 1000),
            int(bat.current_a * 100),
            int(bat.remaining * 100),
            0,
            0,
            0,
            0,
            0,
            0,
        )

    def _extended_sys_state(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        return mav.extended_sys_state_encode(mavlink.MAV_VTOL_STATE_UNDEFINED, int(cmd.landed_state))

    @staticmethod
    def _euler(s: VehicleState) -> tuple[float, float, float]:
        R = quaternion_to_matrix(s.quaternion_wxyz)
        roll = math.atan2(R[2, 1], R[2, 2])
        pitch = -math.asin(max(-1.0, min(1.0, R[2, 0])))
        yaw = math.atan2(R[1, 0], R[0, 0])
        return roll, pitch, yaw

    def _attitude(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        roll, pitch, yaw = self._euler(s)
        p, q, r = (float(v) for v in s.rates_frd_radps)
        return mav.attitude_encode(self._boot_ms(t_s), roll, pitch, yaw, p, q, r)

    def _attitude_quaternion(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        w, x, y, z = (float(v) for v in s.quaternion_wxyz)
        p, q, r = (float(v) for v in s.rates_frd_radps)
        return mav.attitude_quaternion_encode(self._boot_ms(t_s), w, x, y, z, p, q, r, [0.0, 0.0, 0.0, 0.0])

    def _local_position(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        n, e, d = (float(v) for v in self._noisy(s.position_ned_m))
        vn, ve, vd = (float(v) for v in s.velocity_ned_mps)
        return mav.local_position_ned_encode(self._boot_ms(t_s), n, e, d, vn, ve, vd)

    def _global_position(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        n, e, d = (float(v) for v in self._noisy(s.position_ned_m))
        lat, lon, alt = ned_to_geodetic(n, e, d, self.origin.lat_deg, self.origin.lon_deg, self.origin.alt_m)
        rel = float(cmd.home_ned_m[2]) - d
        vn, ve, vd = (float(v) for v in s.velocity_ned_mps)
        yaw = self._euler(s)[2]
        hdg = round(math.degrees(yaw) % 360.0 * 100) % 36000
        return mav.global_position_int_encode(
            self._boot_ms(t_s),
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            round(rel * 1000),
            round(vn * 100),
            round(ve * 100),
            round(vd * 100),
            hdg,
        )

    def _gps_raw(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        n, e, d = (float(v) for v in self._noisy(s.position_ned_m))
        lat, lon, alt = ned_to_geodetic(n, e, d, self.origin.lat_deg, self.origin.lon_deg, self.origin.alt_m)
        vn, ve, _vd = (float(v) for v in s.velocity_ned_mps)
        cog = round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100) % 36000
        return mav.gps_raw_int_encode(
            int(t_s * 1e6),
            mavlink.GPS_FIX_TYPE_3D_FIX,
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            80,
            120,
            round(math.hypot(vn, ve) * 100),
            cog,
            14,
        )

    def _battery(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        cell_mv = int(bat.voltage_v * 1000 / 4)
        voltages = [cell_mv] * 4 + [65535] * 6
        return mav.battery_status_encode(
            0,
            mavlink.MAV_BATTERY_FUNCTION_ALL,
            mavlink.MAV_BATTERY_TYPE_LIPO,
            2500,
            voltages,
            int(bat.current_a * 100),
            int(bat.used_mah),
            -1,
            int(bat.remaining * 100),
        )

    def _home(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        n, e, d = (float(v) for v in cmd.home_ned_m)
        lat, lon, alt = ned_to_geodetic(n, e, d, self.origin.lat_deg, self.origin.lon_deg, self.origin.alt_m)
        return mav.home_position_encode(
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            n,
            e,
            d,
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            int(t_s * 1e6),
        )

    def _autopilot_version(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        capabilities = (
            mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
            | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
        )
        version = (1 << 24) | (15 << 16) | (0 << 8) | 255  # 1.15.0 release
        return mav.autopilot_version_encode(
            capabilities, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0x26AC, 0x0011, 1, [0] * 18
        )
