"""The telemetry a PX4 vehicle streams, built from the true state, scheduled per link in simulated time.

Each link has its own rates (SET_MESSAGE_INTERVAL changes them); timestamps are the simulated clock
(``time_boot_ms``, ``time_usec``), the one clock the companion reads. Position outputs carry seeded noise of the
configured size (an estimator's error); the controller flies the true state.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from companion.vehicle.statustext import statustext_chunks
from sitl.autopilot.battery import Battery
from sitl.autopilot.commander import Commander
from sitl.autopilot.controller import Setpoint
from sitl.autopilot.modes import FlightMode
from sitl.autopilot.status import LandedState
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
# PX4's "normal" profile (mavlink_main.cpp) for a ground station: what QGroundControl's fly view, instrument panel
# and setup pages read (speed and climb from VFR_HUD, the vibration and estimator indicators, RC, outputs, targets).
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
    "VFR_HUD": 4.0,
    "ALTITUDE": 1.0,
    "ESTIMATOR_STATUS": 0.5,
    "VIBRATION": 0.5,
    "RC_CHANNELS": 5.0,
    "SERVO_OUTPUT_RAW": 1.0,
    "NAV_CONTROLLER_OUTPUT": 1.0,
    "POSITION_TARGET_LOCAL_NED": 1.5,
    "GPS_GLOBAL_ORIGIN": 0.1,
    "MISSION_CURRENT": 0.5,
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
    "VFR_HUD": mavlink.MAVLINK_MSG_ID_VFR_HUD,
    "ALTITUDE": mavlink.MAVLINK_MSG_ID_ALTITUDE,
    "ESTIMATOR_STATUS": mavlink.MAVLINK_MSG_ID_ESTIMATOR_STATUS,
    "VIBRATION": mavlink.MAVLINK_MSG_ID_VIBRATION,
    "RC_CHANNELS": mavlink.MAVLINK_MSG_ID_RC_CHANNELS,
    "SERVO_OUTPUT_RAW": mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW,
    "NAV_CONTROLLER_OUTPUT": mavlink.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT,
    "POSITION_TARGET_LOCAL_NED": mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED,
    "GPS_GLOBAL_ORIGIN": mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,
    "MISSION_CURRENT": mavlink.MAVLINK_MSG_ID_MISSION_CURRENT,
    "PROTOCOL_VERSION": 300,
}
ONE_SHOT = frozenset({"AUTOPILOT_VERSION", "PROTOCOL_VERSION"})  # sent when asked for, never streamed
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


class ProtocolVersionMessage(mavlink.MAVLink_message):  # type: ignore[misc]
    """PROTOCOL_VERSION (300), which pymavlink's ``common`` dialect lacks: the answer to REQUEST_PROTOCOL_VERSION."""

    id = 300
    msgname = "PROTOCOL_VERSION"
    fieldnames: ClassVar[list[str]] = [
        "version",
        "min_version",
        "max_version",
        "spec_version_hash",
        "library_version_hash",
    ]
    ordered_fieldnames: ClassVar[list[str]] = fieldnames
    crc_extra = 217
    unpacker = struct.Struct("<HHH8s8s")
    instance_field = None
    instance_offset = -1

    def __init__(self, version: int = 200, min_version: int = 100, max_version: int = 200) -> None:
        mavlink.MAVLink_message.__init__(self, self.id, self.msgname)
        self._fieldnames = self.fieldnames
        self._instance_field = None
        self._instance_offset = -1
        self.version, self.min_version, self.max_version = version, min_version, max_version
        self.spec_version_hash = bytes(8)
        self.library_version_hash = bytes(8)

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        """The frame, as the generated classes pack theirs."""
        body = self.unpacker.pack(
            self.version, self.min_version, self.max_version, self.spec_version_hash, self.library_version_hash
        )
        return bytes(self._pack(mav, self.crc_extra, body, force_mavlink1=force_mavlink1))


def statustext_messages(mav: Any, text: str, severity: int, text_id: int) -> list[Any]:
    """STATUSTEXT messages for ``text``, chunked by :func:`companion.vehicle.statustext.statustext_chunks`."""
    return [
        mav.statustext_encode(m.severity, m.text.encode("ascii"), m.id, m.chunk_seq)
        for m in statustext_chunks(text, severity, text_id)
    ]


@dataclass
class Origin:
    """Geodetic position of the local NED origin."""

    lat_deg: float
    lon_deg: float
    alt_m: float


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


# -- messages built from the state, the commander and the battery alone (no noise, no origin) ---------------------
def _boot_ms(t_s: float) -> int:
    return round(t_s * 1000.0) & 0xFFFFFFFF


def euler(s: VehicleState) -> tuple[float, float, float]:
    """Roll, pitch and yaw (rad, ZYX) of the body FRD frame in NED."""
    R = quaternion_to_matrix(s.quaternion_wxyz)
    roll = math.atan2(R[2, 1], R[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, R[2, 0])))
    yaw = math.atan2(R[1, 0], R[0, 0])
    return roll, pitch, yaw


def _sys_status(mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
    # The geofence as PX4 reports it: present (the module runs), enabled while a fence is in force, healthy
    # unless breached. Without the bit, a ground station reads "no fence, unhealthy": MAVProxy said "fence breach".
    fence = mavlink.MAV_SYS_STATUS_GEOFENCE
    health = SENSORS | (0 if cmd.fence_breached else fence)
    if cmd.rc_lost:
        health &= ~mavlink.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
    if cmd.armed or cmd.prearm_problem() is None:
        health |= PREARM_CHECK
    return mav.sys_status_encode(
        SENSORS | PREARM_CHECK | fence,
        SENSORS | PREARM_CHECK | (fence if cmd.fence_limited else 0),
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


def _extended_sys_state(mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
    return mav.extended_sys_state_encode(mavlink.MAV_VTOL_STATE_UNDEFINED, int(cmd.landed_state))


def _attitude(mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
    roll, pitch, yaw = euler(s)
    p, q, r = (float(v) for v in s.rates_frd_radps)
    return mav.attitude_encode(_boot_ms(t_s), roll, pitch, yaw, p, q, r)


def _attitude_quaternion(mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
    w, x, y, z = (float(v) for v in s.quaternion_wxyz)
    p, q, r = (float(v) for v in s.rates_frd_radps)
    return mav.attitude_quaternion_encode(_boot_ms(t_s), w, x, y, z, p, q, r, [0.0, 0.0, 0.0, 0.0])


def _battery(mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
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
        round(min(bat.time_remaining_s, 2**31 - 1)),
        int(cmd.battery_level),  # MAV_BATTERY_CHARGE_STATE: OK, LOW, CRITICAL, EMERGENCY
    )


def _autopilot_version(mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
    capabilities = (
        mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
        | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
        | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
        | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
        | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
        | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
        | mavlink.MAV_PROTOCOL_CAPABILITY_FTP
    )
    version = (1 << 24) | (15 << 16) | (0 << 8) | 255  # 1.15.0 release
    return mav.autopilot_version_encode(
        capabilities, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0x26AC, 0x0011, 1, [0] * 18
    )


def _vibration(mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
    level = 0.5 if cmd.landed_state is not LandedState.ON_GROUND else 0.05
    return mav.vibration_encode(int(t_s * 1e6), level, level, level, 0, 0, 0)


def _rc_channels(mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
    if cmd.rc_lost:
        return mav.rc_channels_encode(_boot_ms(t_s), 0, *([65535] * 18), 0)
    sticks = cmd.pilot_sticks if cmd.mode is FlightMode.POSCTL else np.zeros(3)
    pitch, roll, throttle = 1500 - 500 * sticks[0], 1500 + 500 * sticks[1], 1500 - 500 * sticks[2]
    channels = [round(float(v)) for v in (roll, pitch, throttle, 1500)] + [1500] * 4 + [65535] * 10
    return mav.rc_channels_encode(_boot_ms(t_s), 8, *channels, 255)


def _mission_current(mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
    nav = cmd.navigator
    total = len(nav.mission)
    if total == 0:
        state = mavlink.MISSION_STATE_NO_MISSION
    elif nav.mission_current >= total:
        state = mavlink.MISSION_STATE_COMPLETE
    elif cmd.mode is FlightMode.AUTO_MISSION:
        state = mavlink.MISSION_STATE_ACTIVE
    else:
        state = mavlink.MISSION_STATE_NOT_STARTED if nav.mission_current == 0 else mavlink.MISSION_STATE_PAUSED
    in_mission = 1 if cmd.mode is FlightMode.AUTO_MISSION else 2
    return mav.mission_current_encode(min(nav.mission_current, 65535), total, state, in_mission)


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
        self.motor_outputs = np.zeros(4)  # the latest motor commands, [0, 1] (SERVO_OUTPUT_RAW)
        self.setpoint: Setpoint | None = None  # what the position controller follows now (targets, errors)
        self._builders: dict[str, Callable[[Any, float, VehicleState, Commander, Battery], Any]] = {
            "SYS_STATUS": _sys_status,
            "EXTENDED_SYS_STATE": _extended_sys_state,
            "ATTITUDE": _attitude,
            "ATTITUDE_QUATERNION": _attitude_quaternion,
            "LOCAL_POSITION_NED": self._local_position,
            "GLOBAL_POSITION_INT": self._global_position,
            "GPS_RAW_INT": self._gps_raw,
            "BATTERY_STATUS": _battery,
            "HOME_POSITION": self._home,
            "AUTOPILOT_VERSION": _autopilot_version,
            "VFR_HUD": self._vfr_hud,
            "ALTITUDE": self._altitude,
            "ESTIMATOR_STATUS": self._estimator_status,
            "VIBRATION": _vibration,
            "RC_CHANNELS": _rc_channels,
            "SERVO_OUTPUT_RAW": self._servo_output_raw,
            "NAV_CONTROLLER_OUTPUT": self._nav_controller_output,
            "POSITION_TARGET_LOCAL_NED": self._position_target,
            "GPS_GLOBAL_ORIGIN": self._gps_global_origin,
            "MISSION_CURRENT": _mission_current,
            "PROTOCOL_VERSION": lambda mav, t_s, s, cmd, bat: ProtocolVersionMessage(),
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

    def _local_position(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        n, e, d = (float(v) for v in self._noisy(s.position_ned_m))
        vn, ve, vd = (float(v) for v in s.velocity_ned_mps)
        return mav.local_position_ned_encode(_boot_ms(t_s), n, e, d, vn, ve, vd)

    def _global_position(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        n, e, d = (float(v) for v in self._noisy(s.position_ned_m))
        lat, lon, alt = ned_to_geodetic(n, e, d, self.origin.lat_deg, self.origin.lon_deg, self.origin.alt_m)
        rel = float(cmd.home_ned_m[2]) - d
        vn, ve, vd = (float(v) for v in s.velocity_ned_mps)
        yaw = euler(s)[2]
        hdg = round(math.degrees(yaw) % 360.0 * 100) % 36000
        return mav.global_position_int_encode(
            _boot_ms(t_s),
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

    # -- what a ground station's instruments read (true state: no draw from the noise generator) ---------------
    def _vfr_hud(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        vn, ve, vd = (float(v) for v in s.velocity_ned_mps)
        speed = math.hypot(vn, ve)
        heading = round(math.degrees(euler(s)[2]) % 360.0) % 360
        throttle = round(100 * float(np.mean(self.motor_outputs))) if cmd.armed else 0
        alt_amsl = self.origin.alt_m - float(s.position_ned_m[2])
        return mav.vfr_hud_encode(speed, speed, heading, throttle, alt_amsl, -vd)

    def _altitude(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        down = float(s.position_ned_m[2])
        amsl = self.origin.alt_m - down
        relative = float(cmd.home_ned_m[2]) - down
        return mav.altitude_encode(int(t_s * 1e6), amsl, amsl, -down, relative, math.nan, math.nan)

    def _estimator_status(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        flags = (
            mavlink.ESTIMATOR_ATTITUDE
            | mavlink.ESTIMATOR_VELOCITY_HORIZ
            | mavlink.ESTIMATOR_VELOCITY_VERT
            | mavlink.ESTIMATOR_POS_HORIZ_REL
            | mavlink.ESTIMATOR_POS_HORIZ_ABS
            | mavlink.ESTIMATOR_POS_VERT_ABS
            | mavlink.ESTIMATOR_PRED_POS_HORIZ_REL
            | mavlink.ESTIMATOR_PRED_POS_HORIZ_ABS
        )
        sigma = max(self.position_noise_m, 0.01)
        return mav.estimator_status_encode(int(t_s * 1e6), flags, 0.1, 0.1, 0.1, 0.05, 0.0, 0.0, sigma, sigma)

    def _servo_output_raw(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        pwm = [round(1000 + 1000 * float(min(max(m, 0.0), 1.0))) if cmd.armed else 900 for m in self.motor_outputs]
        return mav.servo_output_raw_encode(int(t_s * 1e6) & 0xFFFFFFFF, 0, *(pwm + [0] * (16 - len(pwm))))

    def _target(self, s: VehicleState) -> np.ndarray:
        """The position the controller steers to (its position setpoint, the vehicle's position where it has none)."""
        if self.setpoint is None:
            return np.asarray(s.position_ned_m, dtype=np.float64)
        return np.where(np.isnan(self.setpoint.position_ned_m), s.position_ned_m, self.setpoint.position_ned_m)

    def _nav_controller_output(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        target = self._target(s)
        dn, de = float(target[0] - s.position_ned_m[0]), float(target[1] - s.position_ned_m[1])
        bearing = round(math.degrees(math.atan2(de, dn)))
        roll, pitch, yaw = euler(s)
        return mav.nav_controller_output_encode(
            math.degrees(roll),
            math.degrees(pitch),
            round(math.degrees(yaw)),
            bearing,
            min(round(math.hypot(dn, de)), 65535),
            float(s.position_ned_m[2] - target[2]),
            0.0,
            0.0,
        )

    def _position_target(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        sp = self.setpoint
        nan3 = np.full(3, math.nan)
        position = sp.position_ned_m if sp is not None else nan3
        velocity = sp.velocity_ned_mps if sp is not None else nan3
        yaw = sp.yaw_rad if sp is not None else math.nan
        mask = 0b0000_1101_1100_0000  # accelerations and yaw rate ignored
        for bit, value in zip((1, 2, 4, 8, 16, 32), [*position, *velocity], strict=True):
            if math.isnan(value):
                mask |= bit
        if math.isnan(yaw):
            mask |= 1024
        p, v = (float(x) for x in position), (float(x) for x in velocity)
        return mav.position_target_local_ned_encode(
            _boot_ms(t_s), mavlink.MAV_FRAME_LOCAL_NED, mask, *p, *v, 0.0, 0.0, 0.0, float(yaw), 0.0
        )

    def _gps_global_origin(self, mav: Any, t_s: float, s: VehicleState, cmd: Commander, bat: Battery) -> Any:
        o = self.origin
        return mav.gps_global_origin_encode(
            round(o.lat_deg * 1e7), round(o.lon_deg * 1e7), round(o.alt_m * 1000), int(t_s * 1e6)
        )
