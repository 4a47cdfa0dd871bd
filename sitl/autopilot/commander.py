"""The autopilot's commander: arming, modes, takeoff and landing, failsafes, and the setpoint each mode flies.

Times are simulated seconds. Results follow MAVLink's MAV_RESULT: ACCEPTED, TEMPORARILY_REJECTED (try again
later: e.g. OFFBOARD without a setpoint stream, takeoff while disarmed), DENIED (pre-arm checks failed, disarming
in the air without force), UNSUPPORTED (a mode this autopilot does not fly).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from sitl.autopilot.arming_checks import prearm_problem
from sitl.autopilot.battery import BatteryLevel, failsafe_action
from sitl.autopilot.controller import Setpoint
from sitl.autopilot.flight_tasks import mode_setpoint
from sitl.autopilot.geofence import Fence, GeofenceWatch
from sitl.autopilot.land_detector import LOW_THRUST_SHARE, TOUCHING_BELOW_MPS, LandDetector, LandEvent
from sitl.autopilot.modes import FlightMode
from sitl.autopilot.navigator import Navigator
from sitl.autopilot.params import ParameterStore
from sitl.autopilot.status import ControlSource, LandedState, MavResult, Severity
from sitl.dynamics.base import F64Array, VehicleState
from sitl.dynamics.rigid_body import quaternion_to_matrix

logger = logging.getLogger(__name__)


# What each failsafe parameter's values do (anything else: land).
OBL_RC_ACTIONS = {3: "rtl", 4: "land", 5: "hold", 6: "land", 7: "land"}  # COM_OBL_RC_ACT beyond the manual modes
OBL_RC_MANUAL = {0: "position", 1: "altitude", 2: "manual"}  # COM_OBL_RC_ACT: modes flown on the pilot's sticks
FAILSAFE_MODES = {
    "land": FlightMode.AUTO_LAND,
    "hold": FlightMode.AUTO_LOITER,
    "rtl": FlightMode.AUTO_RTL,
    "position": FlightMode.POSCTL,
}


def setpoint_refusal(position_ned_m: F64Array, velocity_ned_mps: F64Array, yaw_rad: float) -> str | None:
    """Why an offboard setpoint (NaN = not controlled) is refused; None when it is taken."""
    used = np.concatenate([position_ned_m[~np.isnan(position_ned_m)], velocity_ned_mps[~np.isnan(velocity_ned_mps)]])
    if used.size == 0:
        return "no position or velocity"
    if not np.all(np.isfinite(used)):
        return "non-finite value"
    if np.any(np.abs(position_ned_m[~np.isnan(position_ned_m)]) > 10_000.0):
        return "position beyond 10 km"
    if np.any(np.abs(velocity_ned_mps[~np.isnan(velocity_ned_mps)]) > 50.0):
        return "velocity beyond 50 m/s"
    if math.isinf(yaw_rad):
        return "infinite yaw"
    return None


def offboard_loss_action(value: int, rc_lost: bool) -> tuple[str, str | None]:
    """What PX4 v1.15 flies when the offboard stream stops, by ``COM_OBL_RC_ACT`` ``value``, and what it says.

    0-2 (position, altitude, manual: the default is 0) hand the vehicle to the pilot's sticks, flown here as position
    mode (this autopilot has no altitude or stabilized mode); without RC those modes cannot run and PX4 falls back
    to hold, as here. 6 (terminate) and 7 (disarm) are flown as land: nothing here cuts the motors.
    """
    manual = OBL_RC_MANUAL.get(value)
    if manual is not None:
        if rc_lost:
            return "hold", f"Offboard loss: {manual} mode needs RC: hold"
        return "position", None if manual == "position" else f"Offboard loss: {manual} mode flown as position mode"
    if value in (6, 7):
        return "land", f"Offboard loss: {'terminate' if value == 6 else 'disarm'} flown as land"
    return OBL_RC_ACTIONS.get(value, "land"), None


RCL_ACTIONS = {1: "hold", 2: "rtl", 3: "land"}  # NAV_RCL_ACT (0: none, never triggered)


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
        self.land_detector = LandDetector()
        self.events: deque[tuple[Severity, str]] = deque(maxlen=32)
        self.offboard: OffboardSetpoint | None = None
        self.rc_lost = False
        self._rc_lost_since_s = math.nan
        self.pilot_sticks = np.zeros(3)  # north, east, down velocity fractions in POSCTL
        self.failsafe: str | None = None
        self.failsafe_since_s = math.nan
        self._armed_at_s = math.nan
        self.hold_ned_m = self.home_ned_m.copy()
        self.hold_yaw_rad = math.nan
        self.braking = False
        self.now_s = 0.0
        self._state: VehicleState | None = None
        self.takeoff_altitude_m = float(params["MIS_TAKEOFF_ALT"])
        self.changed = False  # set on every arm/mode change, cleared by whoever announces it
        self.geofence = GeofenceWatch(params)
        self.battery_level = BatteryLevel.OK
        self.navigator = Navigator(self)  # mission, orbit, go-to, return home

    @property
    def landed_state(self) -> LandedState:
        """The land detector's state."""
        return self.land_detector.state

    # -- helpers ---------------------------------------------------------------------------------------------
    def event(self, text: str, severity: Severity = Severity.INFO) -> None:
        logger.info(text)
        self.events.append((severity, text))
        self.changed = True

    def position(self) -> F64Array:
        source = self._state.position_ned_m if self._state is not None else self.home_ned_m
        return np.array(source, dtype=np.float64)

    def _yaw(self) -> float:
        if self._state is None:
            return 0.0
        R = quaternion_to_matrix(self._state.quaternion_wxyz)
        return math.atan2(R[1, 0], R[0, 0])

    def capture_hold(self) -> None:
        """Hold where the vehicle is, at its heading."""
        self.hold_ned_m = self.position()
        self.hold_yaw_rad = self._yaw()

    def offboard_stream_ok(self) -> bool:
        """A valid setpoint arrived within COM_OF_LOSS_T."""
        return self.offboard is not None and self.now_s - self.offboard.received_s <= self.params["COM_OF_LOSS_T"]

    # -- requests --------------------------------------------------------------------------------------------
    def arm(self, force: bool = False) -> MavResult:
        """Arm after pre-arm checks (force skips them)."""
        if self.armed:
            return MavResult.ACCEPTED
        if not force:
            problem = self.prearm_problem()
            if problem:
                self.event(f"Arming denied: {problem}", Severity.CRITICAL)
                return MavResult.DENIED
        self.armed = True
        self._armed_at_s = self.now_s
        self.land_detector.reset_landed_time()
        self.capture_hold()
        self.event("Armed")
        return MavResult.ACCEPTED

    def prearm_problem(self) -> str | None:
        """Why arming would be denied now, or None (:mod:`sitl.autopilot.arming_checks`)."""
        return prearm_problem(self)

    def disarm(self, force: bool = False, reason: str = "Disarmed") -> MavResult:
        """Disarm; refused in the air unless forced (it would drop the vehicle)."""
        if not self.armed:
            return MavResult.ACCEPTED
        if self.landed_state is not LandedState.ON_GROUND and not force:
            self.event("Disarming denied: in the air", Severity.CRITICAL)
            return MavResult.DENIED
        self.armed = False
        self.navigator.disarmed()
        self.event(reason)
        return MavResult.ACCEPTED

    def set_mode(self, mode: FlightMode, source: ControlSource = ControlSource.MAVLINK) -> MavResult:
        """Switch mode; OFFBOARD needs a live setpoint stream; the pilot's switch always wins."""
        if mode is FlightMode.OFFBOARD and not self.offboard_stream_ok() and source is not ControlSource.FAILSAFE:
            self.event("Offboard rejected: no setpoint stream", Severity.CRITICAL)
            return MavResult.TEMPORARILY_REJECTED
        if mode is FlightMode.AUTO_MISSION and not self.navigator.mission:
            self.event("Mission rejected: no mission uploaded", Severity.CRITICAL)
            return MavResult.DENIED
        if mode is FlightMode.ORBIT and (self.navigator.orbit is None or not self.armed):
            self.event("Orbit rejected: use the orbit command in the air", Severity.CRITICAL)
            return MavResult.TEMPORARILY_REJECTED
        if mode is FlightMode.AUTO_TAKEOFF and not self.armed:
            return MavResult.TEMPORARILY_REJECTED
        if mode is self.mode:
            return MavResult.ACCEPTED
        if source is ControlSource.PILOT:
            self.failsafe = None
        self.mode = mode
        self.capture_hold()
        self.braking = mode in (FlightMode.POSCTL, FlightMode.AUTO_LOITER)
        if mode is FlightMode.AUTO_TAKEOFF:
            self.hold_ned_m = self.position()
            self.takeoff_altitude_m = self.params["MIS_TAKEOFF_ALT"]  # unless NAV_TAKEOFF names another
        self.navigator.mode_entered(mode)
        self.event(f"Mode {mode.px4_name} ({source.value})")
        return MavResult.ACCEPTED

    def takeoff(self, altitude_m: float) -> MavResult:
        """NAV_TAKEOFF: climb to ``altitude_m`` above home (NaN: MIS_TAKEOFF_ALT), then hold."""
        if not self.armed:
            return MavResult.TEMPORARILY_REJECTED
        result = self.set_mode(FlightMode.AUTO_TAKEOFF)
        if result is MavResult.ACCEPTED and math.isfinite(altitude_m) and altitude_m > 0:
            self.takeoff_altitude_m = min(altitude_m, 100.0)  # this takeoff's: PX4 leaves MIS_TAKEOFF_ALT as it is
        return result

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
        refused = setpoint_refusal(position_ned_m, velocity_ned_mps, yaw_rad)
        if refused is not None:
            return False, refused
        self.offboard = OffboardSetpoint(position_ned_m.copy(), velocity_ned_mps.copy(), yaw_rad, self.now_s)
        return True, ""

    def set_rc_lost(self, lost: bool) -> None:
        """The simulated pilot's RC link goes away or comes back."""
        if lost and not self.rc_lost:
            self._rc_lost_since_s = self.now_s
            self.event("RC lost", Severity.WARNING)
        elif not lost and self.rc_lost:
            self.event("RC regained")
        self.rc_lost = lost

    def set_pilot_sticks(self, north: float, east: float, down: float) -> None:
        """The pilot's sticks as velocity fractions in world NED, each in [-1, 1] (flown in POSCTL)."""
        self.pilot_sticks = np.array([north, east, down])

    # -- the periodic update ---------------------------------------------------------------------------------
    def update(self, t_s: float, state: VehicleState, collective: float) -> Setpoint | None:
        """Advance the state machine to ``t_s``; returns the setpoint to fly, or None for motors off/idle."""
        self.now_s = t_s
        self._state = state
        self._detect_landing(t_s, state, collective)
        self._failsafes(t_s)
        if not self.armed:
            return None
        if (
            not math.isnan(self._armed_at_s)
            and self.landed_state is LandedState.ON_GROUND
            and self.params["COM_DISARM_PRFLT"] > 0
            and t_s - self._armed_at_s > self.params["COM_DISARM_PRFLT"]
            and math.isnan(self.land_detector.landed_since_s)
        ):
            self.disarm(reason="Disarmed: no takeoff after arming")
            return None
        setpoint = mode_setpoint(self, state)
        if self.landed_state is LandedState.ON_GROUND and not self._wants_to_climb(setpoint, state):
            return None  # armed on the ground: motors idle until something asks to climb
        if self.landed_state is LandedState.ON_GROUND:
            self.land_detector.take_off()
            self._armed_at_s = math.nan
            self.event("Takeoff")
        return setpoint

    @staticmethod
    def _wants_to_climb(setpoint: Setpoint, state: VehicleState) -> bool:
        pos_down = setpoint.position_ned_m[2]
        vel_down = setpoint.velocity_ned_mps[2]
        return (not math.isnan(pos_down) and pos_down < state.position_ned_m[2] - 0.3) or (
            not math.isnan(vel_down) and vel_down < -0.2
        )

    def _detect_landing(self, t_s: float, state: VehicleState, collective: float) -> None:
        """The land detector's update (:mod:`sitl.autopilot.land_detector`), acted on: the landing announced (a
        mission's land item reached), the disarm after landing."""
        mission_lands = self.mode is FlightMode.AUTO_MISSION and self.navigator.item_landing
        event = self.land_detector.update(
            t_s,
            altitude_m=float(self.home_ned_m[2] - state.position_ned_m[2]),
            touching=bool(state.on_ground) and float(np.linalg.norm(state.velocity_ned_mps)) < TOUCHING_BELOW_MPS,
            low_thrust=collective < LOW_THRUST_SHARE * self.params["MPC_THR_HOVER"],
            armed=self.armed,
            landing=self.mode is FlightMode.AUTO_LAND or mission_lands,
            disarm_delay_s=self.params["COM_DISARM_LAND"],
        )
        if event is LandEvent.LANDED:
            self.event("Landing detected")
            if mission_lands:
                self.navigator.item_reached()  # the land item ends the mission
        elif event is LandEvent.DISARM_DUE:
            self.disarm(reason="Disarmed after landing")

    def outside_fence(self) -> bool:
        """Outside the fence in force (:meth:`GeofenceWatch.outside`)."""
        return self.geofence.outside(self.position(), self.home_ned_m)

    @property
    def fence_limited(self) -> bool:
        """A fence is in force (PX4's geofence module)."""
        return self.geofence.limited

    @property
    def fence_breached(self) -> bool:
        """The vehicle is outside the fence in force, in the air (SYS_STATUS reports the fence unhealthy)."""
        return self.geofence.breached

    def set_fence(self, fence: Fence) -> None:
        """A new geofence (an upload or a clear)."""
        self.geofence.set(fence)

    def _geofence(self) -> None:
        """GF_ACTION once, when the vehicle leaves the fence in the air (as PX4: a breach, not every step outside)."""
        on_ground = self.landed_state is LandedState.ON_GROUND
        action = self.geofence.breach(self.position(), self.home_ned_m, on_ground)
        if action == "warn":
            self.event("Geofence breached", Severity.CRITICAL)
        elif action is not None:
            self._trigger_failsafe("Geofence breached", action)

    def _failsafes(self, t_s: float) -> None:
        if not self.armed:
            return
        self._geofence()
        if self.mode is FlightMode.OFFBOARD and not self.offboard_stream_ok():
            self._trigger_failsafe("Offboard lost", self._offboard_loss_action())
        if self.rc_lost and t_s - self._rc_lost_since_s >= self.params["COM_RC_LOSS_T"]:
            excepted = self.mode is FlightMode.OFFBOARD and int(self.params["COM_RCL_EXCEPT"]) & 4
            exposed = self.mode in (FlightMode.POSCTL, FlightMode.OFFBOARD, FlightMode.AUTO_LOITER)
            action = int(self.params["NAV_RCL_ACT"])
            if exposed and not excepted and action > 0 and self.failsafe != "RC lost":
                self._trigger_failsafe("RC lost", RCL_ACTIONS.get(action, "land"))

    def _offboard_loss_action(self) -> str:
        """What PX4 v1.15 flies when the offboard stream stops (:func:`offboard_loss_action`)."""
        action, note = offboard_loss_action(int(self.params["COM_OBL_RC_ACT"]), self.rc_lost)
        if note is not None:
            self.event(note, Severity.WARNING)
        return action

    def battery_failsafe(self, level: BatteryLevel) -> None:
        """PX4's battery failsafe at a new, worse level: a warning, then the action ``COM_LOW_BAT_ACT`` asks."""
        self.battery_level = level
        action = failsafe_action(level, int(self.params["COM_LOW_BAT_ACT"]))
        self.event(f"Battery {level.name.lower()}", Severity.CRITICAL if level > BatteryLevel.LOW else Severity.WARNING)
        if action is not None and self.armed and self.landed_state is not LandedState.ON_GROUND:
            self._trigger_failsafe(f"battery {level.name.lower()}", action)

    def _trigger_failsafe(self, reason: str, name: str) -> None:
        """Fly the failsafe action ``name`` (land, hold, rtl or position; hold on the ground) for ``reason``."""
        mode = FAILSAFE_MODES[name]
        if self.landed_state is LandedState.ON_GROUND and mode is not FlightMode.AUTO_LOITER:
            mode = FlightMode.AUTO_LOITER
        self.failsafe = reason
        self.failsafe_since_s = self.now_s
        self.event(f"Failsafe: {reason}, {name}", Severity.CRITICAL)
        if mode is self.mode is FlightMode.AUTO_LOITER:  # holding already, towards a go-to point: stop here
            self.capture_hold()
            self.braking = True
        self.set_mode(mode, ControlSource.FAILSAFE)
