"""The autopilot's commander: arming, modes, takeoff and landing, failsafes, and the setpoint each mode flies.

Times are simulated seconds. Results follow MAVLink's MAV_RESULT: ACCEPTED, TEMPORARILY_REJECTED (try again
later: e.g. OFFBOARD without a setpoint stream, takeoff while disarmed), DENIED (pre-arm checks failed, disarming
in the air without force), UNSUPPORTED (a mode this autopilot does not fly).
"""

from __future__ import annotations

import enum
import logging
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from sitl.autopilot.controller import Setpoint
from sitl.autopilot.modes import FlightMode
from sitl.autopilot.params import ParameterStore
from sitl.dynamics.base import F64Array, VehicleState
from sitl.dynamics.rigid_body import quaternion_to_matrix

logger = logging.getLogger(__name__)


class MavResult(enum.IntEnum):
    """MAV_RESULT values."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4


class LandedState(enum.IntEnum):
    """MAV_LANDED_STATE values."""

    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class ControlSource(enum.Enum):
    """Who asked for a mode change."""

    MAVLINK = "mavlink"
    PILOT = "pilot"
    FAILSAFE = "failsafe"
    AUTOPILOT = "autopilot"


@dataclass(frozen=True)
class OffboardSetpoint:
    """An accepted SET_POSITION_TARGET_LOCAL_NED, NaN where the type mask ignores the field."""

    position_ned_m: F64Array
    velocity_ned_mps: F64Array
    yaw_rad: float
    received_s: float


FORCE_MAGIC = 21196  # ARM_DISARM param2 that forces the action


class Commander:
    """Mode and arming state machine (see the module docstring).

    Parameters
    ----------
    params : ParameterStore
        Live parameters (takeoff altitude, speeds, failsafe timeouts and actions).
    home_ned_m : ndarray, shape (3,)
        Home position (on the ground) in world NED.
    """

    def __init__(self, params: ParameterStore, home_ned_m: F64Array) -> None:
        self.params = params
        self.home_ned_m = np.asarray(home_ned_m, dtype=np.float64).copy()
        self.armed = False
        self.mode = FlightMode.AUTO_LOITER
        self.landed_state = LandedState.ON_GROUND
        self.events: deque[str] = deque(maxlen=32)
        self.offboard: OffboardSetpoint | None = None
        self.rc_lost = False
        self._rc_lost_since_s = math.nan
        self.pilot_sticks = np.zeros(3)  # north, east, down velocity fractions in POSCTL
        self.failsafe: str | None = None
        self.failsafe_since_s = math.nan
        self._armed_at_s = math.nan
        self._landed_since_s = math.nan
        self._hold_ned_m = self.home_ned_m.copy()
        self._hold_yaw_rad = math.nan
        self._rtl_phase = 0
        self._braking = False
        self._now_s = 0.0
        self._state: VehicleState | None = None
        self.changed = False  # set on every arm/mode change, cleared by whoever announces it

    # -- helpers ---------------------------------------------------------------------------------------------
    def _event(self, text: str) -> None:
        logger.info(text)
        self.events.append(text)
        self.changed = True

    def _position(self) -> F64Array:
        source = self._state.position_ned_m if self._state is not None else self.home_ned_m
        return np.array(source, dtype=np.float64)

    def _yaw(self) -> float:
        if self._state is None:
            return 0.0
        R = quaternion_to_matrix(self._state.quaternion_wxyz)
        return math.atan2(R[1, 0], R[0, 0])

    def altitude_above_home_m(self) -> float:
        """Height of the vehicle above home, m."""
        return float(self.home_ned_m[2] - self._position()[2])

    def _capture_hold(self) -> None:
        self._hold_ned_m = self._position()
        self._hold_yaw_rad = self._yaw()

    def offboard_stream_ok(self) -> bool:
        """A valid setpoint arrived within COM_OF_LOSS_T."""
        return self.offboard is not None and self._now_s - self.offboard.received_s <= self.params["COM_OF_LOSS_T"]

    # -- requests --------------------------------------------------------------------------------------------
    def arm(self, force: bool = False) -> MavResult:
        """Arm after pre-arm checks (force skips them)."""
        if self.armed:
            return MavResult.ACCEPTED
        if not force:
            problem = self.prearm_problem()
            if problem:
                self._event(f"Arming denied: {problem}")
                return MavResult.DENIED
        self.armed = True
        self._armed_at_s = self._now_s
        self._landed_since_s = math.nan
        self._capture_hold()
        self._event("Armed")
        return MavResult.ACCEPTED

    def prearm_problem(self) -> str | None:
        """Why arming would be denied now, or None when the pre-arm checks pass."""
        if self.landed_state is not LandedState.ON_GROUND:
            return "not landed"
        if self.mode in (FlightMode.AUTO_LAND, FlightMode.AUTO_RTL):
            return f"mode {self.mode.px4_name} is not armable"
        if self.mode is FlightMode.OFFBOARD and not self.offboard_stream_ok():
            return "no offboard setpoints"
        if self.rc_lost and self.mode is FlightMode.POSCTL:
            return "no RC"
        return None

    def disarm(self, force: bool = False, reason: str = "Disarmed") -> MavResult:
        """Disarm; refused in the air unless forced (it would drop the vehicle)."""
        if not self.armed:
            return MavResult.ACCEPTED
        if self.landed_state is not LandedState.ON_GROUND and not force:
            self._event("Disarming denied: in the air")
            return MavResult.DENIED
        self.armed = False
        self._event(reason)
        return MavResult.ACCEPTED

    def set_mode(self, mode: FlightMode, source: ControlSource = ControlSource.MAVLINK) -> MavResult:
        """Switch mode; OFFBOARD needs a live setpoint stream; the pilot's switch always wins."""
        if mode is FlightMode.OFFBOARD and not self.offboard_stream_ok() and source is not ControlSource.FAILSAFE:
            self._event("Offboard rejected: no setpoint stream")
            return MavResult.TEMPORARILY_REJECTED
        if mode is FlightMode.AUTO_TAKEOFF and not self.armed:
            return MavResult.TEMPORARILY_REJECTED
        if mode is self.mode:
            return MavResult.ACCEPTED
        if source is ControlSource.PILOT:
            self.failsafe = None
        self.mode = mode
        self._capture_hold()
        self._rtl_phase = 0
        self._braking = mode in (FlightMode.POSCTL, FlightMode.AUTO_LOITER)
        if mode is FlightMode.AUTO_TAKEOFF:
            self._hold_ned_m = self._position()
        self._event(f"Mode {mode.px4_name} ({source.value})")
        return MavResult.ACCEPTED

    def takeoff(self, altitude_m: float) -> MavResult:
        """NAV_TAKEOFF: climb to ``altitude_m`` above home (NaN: MIS_TAKEOFF_ALT), then hold."""
        if not self.armed:
            return MavResult.TEMPORARILY_REJECTED
        if math.isfinite(altitude_m) and altitude_m > 0:
            self.params.set("MIS_TAKEOFF_ALT", min(altitude_m, 100.0))
        return self.set_mode(FlightMode.AUTO_TAKEOFF)

    def land(self) -> MavResult:
        """NAV_LAND: descend at MPC_LAND_SPEED where the vehicle is (refused while disarmed: on the ground it would
        leave the vehicle in a mode it cannot be armed in)."""
        if not self.armed:
            return MavResult.TEMPORARILY_REJECTED
        return self.set_mode(FlightMode.AUTO_LAND)

    def return_to_launch(self) -> MavResult:
        """NAV_RETURN_TO_LAUNCH."""
        if not self.armed:
            return MavResult.TEMPORARILY_REJECTED
        return self.set_mode(FlightMode.AUTO_RTL)

    def offboard_setpoint(
        self, position_ned_m: F64Array, velocity_ned_mps: F64Array, yaw_rad: float
    ) -> tuple[bool, str]:
        """Store a setpoint (NaN = not controlled); returns (accepted, reason)."""
        used = np.concatenate(
            [position_ned_m[~np.isnan(position_ned_m)], velocity_ned_mps[~np.isnan(velocity_ned_mps)]]
        )
        if used.size == 0:
            return False, "no position or velocity"
        if not np.all(np.isfinite(used)):
            return False, "non-finite value"
        if np.any(np.abs(position_ned_m[~np.isnan(position_ned_m)]) > 10_000.0):
            return False, "position beyond 10 km"
        if np.any(np.abs(velocity_ned_mps[~np.isnan(velocity_ned_mps)]) > 50.0):
            return False, "velocity beyond 50 m/s"
        if math.isinf(yaw_rad):
            return False, "infinite yaw"
        self.offboard = OffboardSetpoint(position_ned_m.copy(), velocity_ned_mps.copy(), yaw_rad, self._now_s)
        return True, ""

    def set_rc_lost(self, lost: bool) -> None:
        """The simulated pilot's RC link goes away or comes back."""
        if lost and not self.rc_lost:
            self._rc_lost_since_s = self._now_s
            self._event("RC lost")
        elif not lost and self.rc_lost:
            self._event("RC regained")
        self.rc_lost = lost

    # -- the periodic update ---------------------------------------------------------------------------------
    def update(self, t_s: float, state: VehicleState, collective: float) -> Setpoint | None:
        """Advance the state machine to ``t_s``; returns the setpoint to fly, or None for motors off/idle."""
        self._now_s = t_s
        self._state = state
        self._land_detector(t_s, state, collective)
        self._failsafes(t_s)
        if not self.armed:
            return None
        if (
            not math.isnan(self._armed_at_s)
            and self.landed_state is LandedState.ON_GROUND
            and self.params["COM_DISARM_PRFLT"] > 0
            and t_s - self._armed_at_s > self.params["COM_DISARM_PRFLT"]
            and math.isnan(self._landed_since_s)
        ):
            self.disarm(reason="Disarmed: no takeoff after arming")
            return None
        setpoint = self._mode_setpoint(state)
        if self.landed_state is LandedState.ON_GROUND and not self._wants_to_climb(setpoint, state):
            return None  # armed on the ground: motors idle until something asks to climb
        if self.landed_state is LandedState.ON_GROUND:
            self.landed_state = LandedState.TAKEOFF
            self._armed_at_s = math.nan
            self._landed_since_s = math.nan
            self._event("Takeoff")
        return setpoint

    @staticmethod
    def _wants_to_climb(setpoint: Setpoint, state: VehicleState) -> bool:
        pos_down = setpoint.position_ned_m[2]
        vel_down = setpoint.velocity_ned_mps[2]
        return (not math.isnan(pos_down) and pos_down < state.position_ned_m[2] - 0.3) or (
            not math.isnan(vel_down) and vel_down < -0.2
        )

    def _land_detector(self, t_s: float, state: VehicleState, collective: float) -> None:
        alt = float(self.home_ned_m[2] - state.position_ned_m[2])
        if self.landed_state in (LandedState.TAKEOFF, LandedState.IN_AIR, LandedState.LANDING):
            if self.landed_state is LandedState.TAKEOFF and alt > 0.5:
                self.landed_state = LandedState.IN_AIR
            if self.landed_state is LandedState.IN_AIR and self.mode is FlightMode.AUTO_LAND:
                self.landed_state = LandedState.LANDING
            if self.landed_state is LandedState.LANDING and self.mode is not FlightMode.AUTO_LAND:
                self.landed_state = LandedState.IN_AIR
            touching = state.on_ground and float(np.linalg.norm(state.velocity_ned_mps)) < 0.3
            if touching and (not self.armed or collective < 0.9 * self.params["MPC_THR_HOVER"]):
                if math.isnan(self._landed_since_s):
                    self._landed_since_s = t_s
                elif t_s - self._landed_since_s >= 0.5 or not self.armed:
                    self.landed_state = LandedState.ON_GROUND
                    self._event("Landing detected")
            else:
                self._landed_since_s = math.nan
        elif self.armed and not math.isnan(self._landed_since_s):
            delay = self.params["COM_DISARM_LAND"]
            if delay >= 0 and t_s - self._landed_since_s >= 0.5 + delay:
                self.disarm(reason="Disarmed after landing")
                self._landed_since_s = math.nan

    def _failsafes(self, t_s: float) -> None:
        if not self.armed:
            return
        if self.mode is FlightMode.OFFBOARD and not self.offboard_stream_ok():
            self._trigger_failsafe("Offboard lost", int(self.params["COM_OBL_ACT"]), {0: "land", 1: "hold", 2: "rtl"})
        if self.rc_lost and t_s - self._rc_lost_since_s >= self.params["COM_RC_LOSS_T"]:
            excepted = self.mode is FlightMode.OFFBOARD and int(self.params["COM_RCL_EXCEPT"]) & 4
            exposed = self.mode in (FlightMode.POSCTL, FlightMode.OFFBOARD, FlightMode.AUTO_LOITER)
            action = int(self.params["NAV_RCL_ACT"])
            if exposed and not excepted and action > 0 and self.failsafe != "RC lost":
                self._trigger_failsafe("RC lost", action, {1: "hold", 2: "rtl", 3: "land"})

    def _trigger_failsafe(self, reason: str, action: int, actions: dict[int, str]) -> None:
        name = actions.get(action, "land")
        mode = {"land": FlightMode.AUTO_LAND, "hold": FlightMode.AUTO_LOITER, "rtl": FlightMode.AUTO_RTL}[name]
        if self.landed_state is LandedState.ON_GROUND and mode is not FlightMode.AUTO_LOITER:
            mode = FlightMode.AUTO_LOITER
        self.failsafe = reason
        self.failsafe_since_s = self._now_s
        self._event(f"Failsafe: {reason}, {name}")
        self.set_mode(mode, ControlSource.FAILSAFE)

    def _mode_setpoint(self, state: VehicleState) -> Setpoint:
        nan3 = np.full(3, math.nan)
        if self.mode is FlightMode.OFFBOARD and self.offboard is not None:
            sp = self.offboard
            return Setpoint(sp.position_ned_m.copy(), sp.velocity_ned_mps.copy(), sp.yaw_rad)
        if self.mode is FlightMode.AUTO_TAKEOFF:
            target = self._hold_ned_m.copy()
            target[2] = self.home_ned_m[2] - self.params["MIS_TAKEOFF_ALT"]
            if state.position_ned_m[2] - target[2] < 0.3:
                self.set_mode(FlightMode.AUTO_LOITER, ControlSource.AUTOPILOT)
                return Setpoint.hold(target, self._hold_yaw_rad)
            climb = np.array([math.nan, math.nan, -self.params["MPC_TKO_SPEED"]])
            pos = np.array([target[0], target[1], math.nan])
            return Setpoint(pos, climb, self._hold_yaw_rad)
        if self.mode is FlightMode.AUTO_LAND:
            pos = np.array([self._hold_ned_m[0], self._hold_ned_m[1], math.nan])
            return Setpoint(pos, np.array([math.nan, math.nan, self.params["MPC_LAND_SPEED"]]), self._hold_yaw_rad)
        if self.mode is FlightMode.AUTO_RTL:
            return self._rtl_setpoint(state)
        if self.mode is FlightMode.POSCTL and np.any(self.pilot_sticks != 0) and not self.rc_lost:
            self._capture_hold()
            vel = self.pilot_sticks * np.array(
                [self.params["MPC_XY_VEL_MAX"], self.params["MPC_XY_VEL_MAX"], self.params["MPC_Z_VEL_MAX_DN"]]
            )
            return Setpoint(nan3.copy(), vel, self._hold_yaw_rad)
        if self._braking:  # as PX4: brake to a stop first, then hold where the vehicle stopped
            if math.hypot(state.velocity_ned_mps[0], state.velocity_ned_mps[1]) > 0.3:
                pos = np.array([math.nan, math.nan, self._hold_ned_m[2]])
                return Setpoint(pos, np.array([0.0, 0.0, math.nan]), self._hold_yaw_rad)
            self._braking = False
            self._hold_ned_m[:2] = state.position_ned_m[:2]
        return Setpoint.hold(self._hold_ned_m, self._hold_yaw_rad)

    def _rtl_setpoint(self, state: VehicleState) -> Setpoint:
        return_down = self.home_ned_m[2] - self.params["RTL_RETURN_ALT"]
        pos = state.position_ned_m
        if self._rtl_phase == 0:  # climb to the return altitude where we are
            target_down = min(return_down, pos[2])
            if abs(pos[2] - target_down) < 0.5:
                self._rtl_phase = 1
            return Setpoint.hold(np.array([self._hold_ned_m[0], self._hold_ned_m[1], target_down]), self._hold_yaw_rad)
        if self._rtl_phase == 1:  # fly home at that altitude
            target = np.array([self.home_ned_m[0], self.home_ned_m[1], min(return_down, self._hold_ned_m[2])])
            if math.hypot(pos[0] - target[0], pos[1] - target[1]) < 1.0:
                self._rtl_phase = 2
            return Setpoint.hold(target, self._hold_yaw_rad)
        land = np.array([self.home_ned_m[0], self.home_ned_m[1], math.nan])
        return Setpoint(land, np.array([math.nan, math.nan, self.params["MPC_LAND_SPEED"]]), self._hold_yaw_rad)
