"""PX4's parameters as this SITL's autopilot knows them: names, types, defaults and ranges (the table only).

The list is what PX4 v1.15 names, defaults and ranges for the parameters this autopilot flies with, and those a
QGroundControl connect and its setup pages read (airframe, sensors, radio, flight modes, power, safety, tuning). The
autopilot serves them over MAVLink (:mod:`sitl.autopilot.params`); the SITL's config checks its overrides against
them (:mod:`sitl.config`), which is why the table sits below both.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class ParamType(enum.IntEnum):
    """MAV_PARAM_TYPE values used here."""

    INT32 = 6
    REAL32 = 9


@dataclass(frozen=True)
class ParamSpec:
    """One parameter's definition."""

    name: str
    param_type: ParamType
    default: float
    minimum: float
    maximum: float
    description: str


_I, _F = ParamType.INT32, ParamType.REAL32
_BIG = 1e9


def _rc_channel(n: int) -> tuple[ParamSpec, ...]:
    return (
        ParamSpec(f"RC{n}_MIN", _F, 1000.0, 800.0, 1500.0, f"RC channel {n} minimum, us"),
        ParamSpec(f"RC{n}_TRIM", _F, 1500.0, 800.0, 2200.0, f"RC channel {n} trim, us"),
        ParamSpec(f"RC{n}_MAX", _F, 2000.0, 1500.0, 2200.0, f"RC channel {n} maximum, us"),
        ParamSpec(f"RC{n}_REV", _F, 1.0, -1.0, 1.0, f"RC channel {n} reversed (-1) or not (1)"),
        ParamSpec(f"RC{n}_DZ", _F, 10.0, 0.0, 100.0, f"RC channel {n} dead zone, us"),
    )


def _calibration(sensor: str, device_id: int) -> tuple[ParamSpec, ...]:
    axes = ("X", "Y", "Z")
    return (
        ParamSpec(f"CAL_{sensor}0_ID", _I, device_id, 0, 2**31 - 1, f"{sensor} 0 device id (calibrated when non-zero)"),
        ParamSpec(f"CAL_{sensor}0_PRIO", _I, 50, -1, 100, f"{sensor} 0 priority"),
        *(ParamSpec(f"CAL_{sensor}0_{a}OFF", _F, 0.0, -_BIG, _BIG, f"{sensor} 0 {a} offset") for a in axes),
        *(ParamSpec(f"CAL_{sensor}0_{a}SCALE", _F, 1.0, 0.1, 3.0, f"{sensor} 0 {a} scale") for a in axes),
    )


# What the autopilot flies with, and what a QGroundControl connect and its setup pages read (airframe, sensors,
# radio, flight modes, power, safety, tuning), with PX4 v1.15's defaults and ranges. Listed, sent and indexed in
# alphabetical order, as PX4 does (its parameter hash walks them in that order).
PARAMS: tuple[ParamSpec, ...] = tuple(
    sorted(
        (
            # flown by this autopilot
            ParamSpec("MIS_TAKEOFF_ALT", _F, 2.5, 0.0, 100.0, "Takeoff altitude above home, m"),
            ParamSpec("MPC_TKO_SPEED", _F, 1.5, 0.5, 5.0, "Takeoff climb rate, m/s"),
            ParamSpec("MPC_LAND_SPEED", _F, 0.7, 0.3, 3.0, "Landing descent rate, m/s"),
            ParamSpec("MPC_XY_VEL_MAX", _F, 5.0, 0.5, 20.0, "Maximum horizontal speed, m/s"),
            ParamSpec("MPC_XY_CRUISE", _F, 5.0, 0.5, 20.0, "Horizontal speed in missions and go-to, m/s"),
            ParamSpec("MPC_Z_VEL_MAX_UP", _F, 3.0, 0.5, 8.0, "Maximum ascent rate, m/s"),
            ParamSpec("MPC_Z_VEL_MAX_DN", _F, 1.5, 0.5, 4.0, "Maximum descent rate, m/s"),
            ParamSpec("MPC_TILTMAX_AIR", _F, 35.0, 20.0, 89.0, "Maximum tilt in the air, deg"),
            ParamSpec("MPC_THR_HOVER", _F, 0.5, 0.1, 0.8, "Hover thrust, normalized"),
            ParamSpec("COM_OF_LOSS_T", _F, 1.0, 0.0, 60.0, "Offboard setpoint loss timeout, s"),
            ParamSpec(
                "COM_OBL_RC_ACT",
                _I,
                0,
                0,
                7,
                "Offboard loss failsafe mode (PX4 v1.14+): 0 position, 1 altitude, 2 manual (each needs RC, else "
                "hold), 3 return, 4 land, 5 hold, 6 terminate, 7 disarm",
            ),
            ParamSpec("NAV_RCL_ACT", _I, 2, 0, 3, "RC loss action: 0 none, 1 hold, 2 return, 3 land"),
            ParamSpec("COM_RCL_EXCEPT", _I, 0, 0, 7, "RC loss exceptions bitmask: 4 = offboard"),
            ParamSpec("COM_RC_LOSS_T", _F, 0.5, 0.0, 35.0, "RC loss timeout, s"),
            ParamSpec("COM_DISARM_LAND", _F, 2.0, -1.0, 20.0, "Auto-disarm delay after landing, s (-1 off)"),
            ParamSpec("COM_DISARM_PRFLT", _F, 10.0, -1.0, 20.0, "Auto-disarm if no takeoff after arming, s"),
            ParamSpec("RTL_RETURN_ALT", _F, 30.0, 0.0, 150.0, "Return altitude above home, m"),
            ParamSpec("MAV_SYS_ID", _I, 1, 1, 250, "MAVLink system id"),
            ParamSpec("NAV_ACC_RAD", _F, 2.0, 0.05, 200.0, "Mission waypoint acceptance radius, m"),
            ParamSpec("NAV_MC_ALT_RAD", _F, 0.8, 0.05, 200.0, "Mission waypoint altitude acceptance, m"),
            # identity and system
            ParamSpec("SYS_AUTOSTART", _I, 4001, 0, 9_999_999, "Airframe (4001: generic quadcopter x500)"),
            ParamSpec("SYS_AUTOCONFIG", _I, 0, 0, 2, "Reset parameters to the airframe's on next boot"),
            ParamSpec("SYS_HITL", _I, 0, -1, 2, "Hardware in the loop"),
            ParamSpec("SYS_HAS_MAG", _I, 1, 0, 2, "Magnetometers expected"),
            ParamSpec("SYS_HAS_BARO", _I, 1, 0, 1, "Barometer expected"),
            ParamSpec("SYS_MC_EST_GROUP", _I, 2, 1, 3, "Estimator: 2 = EKF2"),
            ParamSpec("MAV_COMP_ID", _I, 1, 1, 250, "MAVLink component id"),
            ParamSpec("MAV_TYPE", _I, 2, 0, 22, "MAV_TYPE: 2 = quadrotor"),
            ParamSpec("MAV_PROTO_VER", _I, 0, 0, 2, "MAVLink protocol version (0: default)"),
            ParamSpec("MAV_0_FORWARD", _I, 1, 0, 1, "Forward MAVLink between links"),
            ParamSpec("CA_AIRFRAME", _I, 0, 0, 10, "Control allocation airframe: 0 multirotor"),
            ParamSpec("CA_ROTOR_COUNT", _I, 4, 0, 12, "Rotors"),
            ParamSpec("SDLOG_MODE", _I, 0, -1, 4, "Logging: 0 from arming to disarming"),
            ParamSpec("SDLOG_PROFILE", _I, 1, 0, 4095, "Logged topics"),
            ParamSpec("CBRK_SUPPLY_CHK", _I, 894281, 0, 894281, "Circuit breaker: power supply check"),
            ParamSpec("CBRK_IO_SAFETY", _I, 22027, 0, 22027, "Circuit breaker: safety switch"),
            ParamSpec("CBRK_USB_CHK", _I, 197848, 0, 197848, "Circuit breaker: USB link check"),
            ParamSpec("EKF2_GPS_CTRL", _I, 7, 0, 15, "GPS aiding"),
            ParamSpec("EKF2_HGT_REF", _I, 1, 0, 3, "Height reference: 1 GPS"),
            ParamSpec("EKF2_MAG_TYPE", _I, 0, 0, 6, "Magnetometer fusion"),
            # sensors
            *_calibration("ACC", 1310988),
            *_calibration("GYRO", 1310988),
            *_calibration("MAG", 197388),
            ParamSpec("CAL_MAG0_ROT", _I, 0, -1, 40, "Magnetometer 0 rotation"),
            ParamSpec("CAL_BARO0_ID", _I, 6620172, 0, 2**31 - 1, "Barometer 0 device id"),
            ParamSpec("SENS_BOARD_ROT", _I, 0, -1, 40, "Board rotation"),
            ParamSpec("SENS_BOARD_X_OFF", _F, 0.0, -_BIG, _BIG, "Board roll offset, deg"),
            ParamSpec("SENS_BOARD_Y_OFF", _F, 0.0, -_BIG, _BIG, "Board pitch offset, deg"),
            ParamSpec("SENS_BOARD_Z_OFF", _F, 0.0, -_BIG, _BIG, "Board yaw offset, deg"),
            ParamSpec("SENS_DPRES_OFF", _F, 0.0, -_BIG, _BIG, "Differential pressure offset"),
            # radio
            *(spec for n in range(1, 9) for spec in _rc_channel(n)),
            ParamSpec("RC_CHAN_CNT", _I, 0, 0, 18, "RC channels found by calibration"),
            ParamSpec("RC_MAP_ROLL", _I, 1, 0, 18, "Roll channel"),
            ParamSpec("RC_MAP_PITCH", _I, 2, 0, 18, "Pitch channel"),
            ParamSpec("RC_MAP_THROTTLE", _I, 3, 0, 18, "Throttle channel"),
            ParamSpec("RC_MAP_YAW", _I, 4, 0, 18, "Yaw channel"),
            ParamSpec("RC_MAP_FLTMODE", _I, 0, 0, 18, "Flight mode channel"),
            ParamSpec("RC_MAP_KILL_SW", _I, 0, 0, 18, "Kill switch channel"),
            ParamSpec("RC_MAP_RETURN_SW", _I, 0, 0, 18, "Return switch channel"),
            ParamSpec("RC_MAP_OFFB_SW", _I, 0, 0, 18, "Offboard switch channel"),
            ParamSpec("RC_MAP_AUX1", _I, 0, 0, 18, "Auxiliary 1 channel"),
            ParamSpec("COM_RC_IN_MODE", _I, 1, 0, 4, "Manual control input: 1 MAVLink (joystick)"),
            # flight modes
            *(ParamSpec(f"COM_FLTMODE{n}", _I, -1, -1, 13, f"Flight mode slot {n}") for n in range(1, 7)),
            # power
            ParamSpec("BAT1_N_CELLS", _I, 4, 0, 16, "Battery 1 cells in series"),
            ParamSpec("BAT1_V_CHARGED", _F, 4.05, 0.0, 5.0, "Full cell voltage, V"),
            ParamSpec("BAT1_V_EMPTY", _F, 3.6, 0.0, 5.0, "Empty cell voltage, V"),
            ParamSpec("BAT1_CAPACITY", _F, 5000.0, -1.0, 100000.0, "Battery 1 capacity, mAh"),
            ParamSpec("BAT1_SOURCE", _I, 0, -1, 2, "Battery 1 monitoring source"),
            ParamSpec("BAT1_V_DIV", _F, -1.0, -1.0, _BIG, "Voltage divider"),
            ParamSpec("BAT1_A_PER_V", _F, -1.0, -1.0, _BIG, "Amps per volt"),
            ParamSpec("BAT_LOW_THR", _F, 0.15, 0.12, 0.5, "Low battery threshold"),
            ParamSpec("BAT_CRIT_THR", _F, 0.07, 0.05, 0.25, "Critical battery threshold"),
            ParamSpec("BAT_EMERGEN_THR", _F, 0.05, 0.03, 0.1, "Emergency battery threshold"),
            # safety
            ParamSpec("COM_LOW_BAT_ACT", _I, 0, 0, 3, "Low battery action"),
            ParamSpec("COM_DL_LOSS_T", _I, 10, 5, 300, "Data link loss timeout, s"),
            ParamSpec("NAV_DLL_ACT", _I, 0, 0, 6, "Data link loss action"),
            ParamSpec("COM_ARM_WO_GPS", _I, 1, 0, 1, "Arming without GPS"),
            ParamSpec("COM_PREARM_MODE", _I, 0, 0, 2, "Pre-arm mode"),
            ParamSpec("GF_ACTION", _I, 2, 0, 5, "Geofence breach action"),
            ParamSpec("GF_MAX_HOR_DIST", _F, 0.0, 0.0, 10000.0, "Maximum horizontal distance from home, m (0 off)"),
            ParamSpec("GF_MAX_VER_DIST", _F, 0.0, 0.0, 10000.0, "Maximum height above home, m (0 off)"),
            ParamSpec("GF_SOURCE", _I, 0, 0, 1, "Geofence position source"),
            ParamSpec("RTL_DESCEND_ALT", _F, 30.0, 0.0, 100.0, "Return: loiter altitude, m"),
            ParamSpec("RTL_LAND_DELAY", _F, 0.0, -1.0, 300.0, "Return: delay before landing, s"),
            ParamSpec("LNDMC_Z_VEL_MAX", _F, 0.5, 0.0, 10.0, "Land detector: maximum climb rate, m/s"),
            # tuning pages
            ParamSpec("MC_ROLL_P", _F, 6.5, 0.0, 12.0, "Roll P gain"),
            ParamSpec("MC_PITCH_P", _F, 6.5, 0.0, 12.0, "Pitch P gain"),
            ParamSpec("MC_YAW_P", _F, 2.8, 0.0, 5.0, "Yaw P gain"),
            ParamSpec("MC_ROLLRATE_P", _F, 0.15, 0.01, 0.5, "Roll rate P gain"),
            ParamSpec("MC_PITCHRATE_P", _F, 0.15, 0.01, 0.6, "Pitch rate P gain"),
            ParamSpec("MC_YAWRATE_P", _F, 0.2, 0.0, 0.6, "Yaw rate P gain"),
            ParamSpec("MPC_XY_P", _F, 0.95, 0.0, 2.0, "Horizontal position P gain"),
            ParamSpec("MPC_Z_P", _F, 1.0, 0.0, 1.5, "Vertical position P gain"),
            ParamSpec("MPC_XY_VEL_P_ACC", _F, 1.8, 1.2, 5.0, "Horizontal velocity P gain"),
            ParamSpec("MPC_Z_VEL_P_ACC", _F, 4.0, 2.0, 15.0, "Vertical velocity P gain"),
            ParamSpec("MPC_POS_MODE", _I, 4, 0, 4, "Position mode stick input"),
            ParamSpec("MPC_MAN_TILT_MAX", _F, 35.0, 0.0, 90.0, "Maximum tilt in manual modes, deg"),
            ParamSpec("MPC_ACC_HOR", _F, 3.0, 2.0, 15.0, "Horizontal acceleration in auto modes, m/s^2"),
            ParamSpec("MPC_LAND_ALT1", _F, 10.0, 0.0, 122.0, "Landing: slow-down altitude, m"),
            ParamSpec("MPC_LAND_ALT2", _F, 5.0, 0.0, 122.0, "Landing: land-speed altitude, m"),
            ParamSpec("MNT_MODE_IN", _I, -1, -1, 4, "Gimbal input (-1 none)"),
        ),
        key=lambda spec: spec.name,
    )
)
