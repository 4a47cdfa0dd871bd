"""The SITL vehicle process: dynamics, controller and commander under one simulated clock, on the MAVLink wire.

Rates: physics, attitude and rate control at ``physics_rate_hz``; position control, the commander, telemetry
scheduling and the trajectory log at 100 Hz of simulated time; heartbeats at 1 Hz of wall time (and at once on a
mode or arming change), so MAVSDK stays connected at any simulation speed.
"""

from __future__ import annotations

import functools
import logging
import select
import signal
import time
from types import FrameType
from typing import TYPE_CHECKING, Any

import numpy as np

from companion.errors import SlzError
from companion.vehicle.sim_control import Tick
from sitl.autopilot.actuators import ActuatorOutputs
from sitl.autopilot.battery import Battery, BatteryMonitor
from sitl.autopilot.broadcast import HEARTBEAT_PERIOD_S, Broadcaster
from sitl.autopilot.commander import Commander
from sitl.autopilot.controller import CascadedController, ControllerLimits, Setpoint
from sitl.autopilot.flight_ulog import FlightULog
from sitl.autopilot.mavlink_link import MavlinkLink
from sitl.autopilot.mavlink_server import MavlinkServer
from sitl.autopilot.params import ParameterStore
from sitl.autopilot.status import LandedState, Severity
from sitl.autopilot.telemetry import Origin, TelemetryBuilder
from sitl.config import FaultKind, LinkName, SitlConfig
from sitl.dynamics.base import DynamicsError
from sitl.dynamics.factory import make_dynamics
from sitl.timing.clock import SimClock
from sitl.timing.lockstep_gate import LockstepGate
from sitl.vehicle.control_channel import ControlChannel
from sitl.vehicle.control_requests import ControlRequests
from sitl.vehicle.fault_schedule import FaultSchedule
from sitl.vehicle.inputs import Inputs
from sitl.vehicle.live_truth import LiveTruthError
from sitl.vehicle.records import VehicleRecords
from sitl.vehicle.run_end import RunEnd

if TYPE_CHECKING:  # the camera module needs the renderer, which a SITL without a camera never loads
    from sitl.vehicle.sim_camera import SimCamera

logger = logging.getLogger(__name__)

OUTER_RATE_HZ = 100.0
IDLE_COMMAND = 0.1  # armed on the ground: props spin at idle


class SitlError(SlzError):
    """The SITL vehicle cannot start or had to stop (what failed, and where)."""

    def __init__(self, where: str, what: str) -> None:
        super().__init__(f"{where}: {what}")
        self.where = where
        self.what = what


def describe(c: SitlConfig) -> str:
    """One line with a SITL's endpoints."""
    return (
        f"SITL instance {c.instance} ready: sysid {c.system_id}, api udp {c.bind_address}:{c.api_port_local} -> "
        f"{c.api_port_remote}, gcs {c.gcs_port_local} -> {c.gcs_port_remote}, control {c.control_port}, "
        f"dynamics {c.dynamics.value}, speed {c.speed_factor or 'max'}{', lockstep' if c.lockstep else ''}"
    )


def open_links(config: SitlConfig, links: list[MavlinkLink]) -> None:
    """The companion's (``api``) and the ground station's (``gcs``) MAVLink links, each signed when the config says,
    appended to ``links`` as each opens (so that a failure closes the ones already open)."""
    sysid, bind, signing = config.system_id, config.bind_address, config.signing
    keys = {name: signing.key if signing is not None and name in signing.links else None for name in LinkName}
    api, gcs = LinkName.API, LinkName.GCS
    links.append(MavlinkLink("api", bind, config.api_port_local, config.api_port_remote, sysid, signing_key=keys[api]))
    links.append(MavlinkLink("gcs", bind, config.gcs_port_local, config.gcs_port_remote, sysid, signing_key=keys[gcs]))


class SitlVehicle:
    """One simulated PX4 quadrotor. Build it, then :meth:`run` until shutdown; :meth:`close` frees the ports."""

    def __init__(self, config: SitlConfig) -> None:
        self.config = config
        self.records = VehicleRecords()  # first, so close() works from any failure below
        try:
            home_ned_m = np.array([*config.home_ne_m, 0.0])
            self.dynamics = make_dynamics(config.dynamics, config.physics_rate_hz, home_ned_m)
        except DynamicsError as exc:
            raise SitlError("dynamics", str(exc)) from None
        if config.physics_rate_hz < self.dynamics.min_rate_hz:
            raise SitlError(
                "config.physics_rate_hz",
                f"{config.physics_rate_hz} Hz is below the {config.dynamics.value} model's "
                f"{self.dynamics.min_rate_hz} Hz minimum",
            )
        airframe = self.dynamics.airframe
        self.params = ParameterStore({"MPC_THR_HOVER": round(airframe.hover_thrust, 4), **config.params})
        self.params.set("MAV_SYS_ID", config.system_id)
        self.speed_mps: float | None = None  # DO_CHANGE_SPEED's, while it holds
        self.dynamics.set_wind(np.array(config.wind_ned_mps))
        home = self.dynamics.state().position_ned_m.copy()
        home[2] = 0.0
        self.commander = Commander(self.params, home)
        self.controller = CascadedController(airframe, self.limits())
        self.clock = SimClock(1.0 / config.physics_rate_hz, config.speed_factor)
        self._outer_every = max(1, round(config.physics_rate_hz / OUTER_RATE_HZ))
        self._outer_dt_s = self._outer_every / config.physics_rate_hz
        self.telemetry = TelemetryBuilder(
            Origin(config.origin_lat_deg, config.origin_lon_deg, config.origin_alt_m),
            np.random.default_rng(config.seed),
            config.position_noise_m,
        )
        self.battery = Battery(config.battery.capacity_mah, config.battery.initial_fraction)
        self.battery_monitor = BatteryMonitor()
        self.actuators = ActuatorOutputs(config.scenario.reaction.warning_actuator)
        self.links: list[MavlinkLink] = []
        self.control: ControlChannel | None = None
        self.camera: SimCamera | None = None
        self._next_frame_s = 0.0
        try:
            open_links(config, self.links)
            self.control = ControlChannel(config.bind_address, config.control_port)
        except Exception as exc:
            self.close()
            raise SitlError("network", str(exc)) from None
        if config.camera.enabled:
            from sitl.render.camera import RenderError
            from sitl.vehicle.sim_camera import SimCamera

            try:
                self.camera = SimCamera(config)
                self.actuators.listeners.append(self.camera.crowd.warn)  # people below may hear it
            except (RenderError, OSError) as exc:
                self.close()
                raise SitlError("camera", str(exc)) from None
        self.broadcast = Broadcaster(self.links[0], self.links[1], self.telemetry, self.commander, self.battery)
        self.schedules = self.broadcast.schedules
        self._setpoint: Setpoint | None = None
        self._running = True
        self._exit_code = 0
        self.run_end = RunEnd(config.end_after_touchdown_s)
        self.lockstep = LockstepGate(config.lockstep, config.lockstep_period_s, config.lockstep_timeout_s)
        requests = ControlRequests(self)
        self.mavlink = MavlinkServer(self)
        self.inputs = Inputs(self.links, self.control, self.mavlink, requests)
        self.faults = FaultSchedule(config.faults)
        self.camera_failed = False  # injected: the camera delivers nothing (ticks go on without frames)
        try:  # ground truth, trajectory, ULog, live view
            self.records.open(config, self.params, truth=self.camera is not None)
        except LiveTruthError as exc:
            self.close()
            raise SitlError("live_view", str(exc)) from None
        if self.records.ulog is not None:
            self.broadcast.sink = functools.partial(self.records.ulog.statustext_at, self.clock)

    @property
    def handler_errors(self) -> int:
        """Messages and requests whose handling raised (dropped, logged, counted)."""
        return self.inputs.handler_errors

    @property
    def ulog(self) -> FlightULog | None:
        """The run's ULog (None: not asked for), where the autopilot logs commands and parameter changes."""
        return self.records.ulog

    # -- lifecycle ---------------------------------------------------------------------------------------------
    def limits(self) -> ControllerLimits:
        """The controller's limits from the live parameters (and a DO_CHANGE_SPEED within them)."""
        p = self.params
        xy_max = p["MPC_XY_VEL_MAX"] if self.speed_mps is None else min(self.speed_mps, p["MPC_XY_VEL_MAX"])
        return ControllerLimits(
            xy_vel_max_mps=xy_max,
            z_vel_max_up_mps=p["MPC_Z_VEL_MAX_UP"],
            z_vel_max_down_mps=p["MPC_Z_VEL_MAX_DN"],
            tilt_max_deg=p["MPC_TILTMAX_AIR"],
        )

    def change_speed(self, speed_mps: float | None) -> None:
        """DO_CHANGE_SPEED: fly at most this horizontal speed from now on (None: MPC_XY_VEL_MAX again)."""
        self.speed_mps = speed_mps
        self.refresh_limits()

    def refresh_limits(self) -> None:
        """The controller's limits again from the live parameters (after a change)."""
        self.controller.limits = self.limits()

    def fail_camera(self, failed: bool) -> None:
        """The camera delivers nothing from now on (or again), as injected (ticks go on without frames)."""
        self.camera_failed = failed

    def request_stop(self, *_: object) -> None:
        """Stop at the next loop turn (signal handler and control channel)."""
        self._running = False

    def close(self) -> None:
        """Release sockets and the log."""
        for link in self.links:
            link.close()
        if self.control is not None:
            self.control.close()
        if self.camera is not None:
            self.camera.close()
            self.camera = None
        self.records.close()

    def run(self) -> int:
        """Run until shutdown, ``duration_s`` or a lockstep timeout; returns the exit code."""
        logger.info(describe(self.config))
        assert self.control is not None
        sockets: list[Any] = [*self.links, self.control, *([self.camera] if self.camera is not None else [])]
        fast = self.config.speed_factor == 0 or self.config.speed_factor > 1
        try:
            while self._running:
                if not fast or self.clock.steps % self._outer_every == 0:
                    self.inputs.poll()
                self.broadcast.heartbeat_if_due(self.lockstep.enabled and self.lockstep.client is None)
                if self.config.duration_s is not None and self.clock.now_s >= self.config.duration_s - 1e-9:
                    logger.info("duration reached at %.3f s simulated", self.clock.now_s)
                    break
                if self._settled():
                    break
                free_running = self.lockstep.free_running
                if self.camera is not None and free_running:
                    if self.clock.now_s >= self._next_frame_s - 1e-9:  # free-running: frames go out, or are dropped
                        self._write_truth()
                        if not self.camera_failed:
                            self.camera.capture(self.clock.now_s, self.dynamics.state())
                        self._next_frame_s += self.camera.period_s
                    else:
                        self.camera.server.poll()
                if self.lockstep.at_tick(self.clock.now_s) and not self._lockstep_gate(sockets):
                    continue
                wait = self.clock.wall_time_until_next_step()
                if wait > 0:
                    select.select(sockets, [], [], min(wait, HEARTBEAT_PERIOD_S))
                    continue
                self._step()
        finally:
            self._write_log_row(force=True)
        return self._exit_code

    # -- lockstep ------------------------------------------------------------------------------------------------
    def _lockstep_gate(self, sockets: list[Any]) -> bool:
        """At a tick: send its frame, pose and event once, then True when it is acknowledged (time may pass it)."""
        gate = self.lockstep
        if gate.client is None:
            if self.camera is not None:
                # A companion connects its camera before it subscribes: accepted now, its connection would keep the
                # listening socket readable and this wait would spin (about a wall second of CPU per mission).
                self.camera.server.poll()
            select.select(sockets, [], [], 0.05)  # nobody to step with yet
            self.clock.resync()
            return False
        if not gate.tick_out:
            assert self.control is not None
            frame_seq: int | None = None
            if self.camera is not None and not self.camera_failed:
                # Every tick is a frame: it goes out whole before the tick, so the client has it to acknowledge.
                self.camera.server.poll()
                connected = self.camera.server.connected
                if gate.frame_client_gone_too_long(connected):
                    logger.error("lockstep: the frame client left at tick %d; stopping", gate.seq)
                    self._stop_with(3)
                if not connected:
                    select.select(sockets, [], [], 0.05)  # waiting for the frame client
                    self.clock.resync()
                    return False
                if not gate.frames_wanted:
                    self.camera.skip()  # the client does not look at frames yet (before its flight starts)
                else:
                    self.camera.capture(self.clock.now_s, self.dynamics.state())
                    frame_seq = self.camera.seq - 1
                    if not self.camera.server.flush(time.monotonic() + gate.timeout_s):
                        logger.error("lockstep: the frame client did not take frame %d; stopping", frame_seq)
                        self._stop_with(3)
                        return False
            self.broadcast.tick_pose(self.clock.now_s, self.dynamics.state())
            self._write_truth()
            self.control.send(Tick(gate.seq, self.clock.now_s, frame_seq).to_event(), gate.client)
            gate.sent()
        ack = gate.pending_ack()
        mavlink = self.mavlink
        if ack is not None and gate.ack_covers_mavlink(
            ack,
            mavlink.last_setpoint_ned,
            mavlink.commands_seen,
            lambda source: sum(link.stats.per_source.get(source, 0) for link in self.links),
        ):
            gate.passed(self.mavlink.last_setpoint_ned)
            self.clock.resync()
            return True
        if gate.ack_overdue():
            logger.error(
                "lockstep: no acknowledgement of tick %d (t = %.3f s) within %.1f s wall; stopping",
                gate.seq,
                self.clock.now_s,
                gate.timeout_s,
            )
            self._stop_with(3)
            return False
        select.select(sockets, [], [], 0.02)
        return False

    def _settled(self) -> bool:
        """Whether the run ends here by ``end_after_touchdown_s`` (:class:`~sitl.vehicle.run_end.RunEnd`), checked at
        the outer rate."""
        end = self.run_end
        if end.end_after_touchdown_s is None or not self.lockstep.released or self.clock.steps % self._outer_every:
            return False
        on_ground = end.grounded_s is None and self.commander.armed and bool(self.dynamics.state().on_ground)
        why = end.reached(self.clock.now_s, self.lockstep.released, self.commander.armed, on_ground)
        if why is not None:
            logger.info("%s", why)
        return why is not None

    def _stop_with(self, exit_code: int) -> None:
        self._exit_code = exit_code
        self._running = False

    def _write_truth(self) -> None:
        """One ground-truth record at this instant (:meth:`VehicleRecords.truth_at`)."""
        if self.camera is not None:
            state, warning = self.dynamics.state(), self.actuators.warning_on
            self.records.truth_at(self.clock.now_s, state, self.commander, warning, self.camera.people_at)

    # -- the physics step ----------------------------------------------------------------------------------------
    def _step(self) -> None:
        t_s = self.clock.now_s
        if self.faults:
            inject_faults(self, t_s)
        dt_s = self.clock.step_s
        state = self.dynamics.state()
        if self.clock.steps % self._outer_every == 0:
            cmd = self.commander
            self._setpoint = cmd.update(t_s, state, self.controller.collective)
            if self._setpoint is None:
                self.controller.reset()
            else:
                self.controller.update_position(
                    state, self._setpoint, self._outer_dt_s, integrate=cmd.landed_state is not LandedState.ON_GROUND
                )
            self.telemetry.setpoint = self._setpoint
            if self.broadcast.announce(t_s, state):
                self._write_log_row(force=True)  # phase changes reach the disk at once
            self.battery.update(self.controller.collective, self._outer_dt_s, cmd.armed)
            if (level := self.battery_monitor.update(self.battery.remaining, self.params)) is not None:
                cmd.battery_failsafe(level)  # PX4's battery failsafe: a warning, or COM_LOW_BAT_ACT's action
            self.broadcast.streams(t_s, state)
            self._write_log_row()
        if self._setpoint is not None:
            motors = self.controller.update_attitude(state, dt_s)
        else:
            motors = np.full(4, IDLE_COMMAND if self.commander.armed else 0.0)
        self.telemetry.motor_outputs = motors
        self.dynamics.set_motor_commands(motors)
        self.dynamics.step(dt_s)
        self.clock.advance()

    def statustext(self, text: str, severity: Severity = Severity.INFO) -> None:
        """A STATUSTEXT on every link (:meth:`Broadcaster.statustext`)."""
        self.broadcast.statustext(text, severity)

    def heartbeat_now(self) -> None:
        """A heartbeat on every link at once."""
        self.broadcast.heartbeat_now()

    def _write_log_row(self, force: bool = False) -> None:
        battery = (self.battery, int(self.battery_monitor.level))
        people = None if self.camera is None else self.camera.people
        t_s, state, cmd = self.clock.now_s, self.dynamics.state, self.commander
        self.records.row(t_s, state, cmd, self._setpoint, battery, people, force)


def inject_faults(vehicle: SitlVehicle, t_s: float) -> None:
    """The faults of ``vehicle``'s schedule due at simulated ``t_s``, injected."""
    for fault in vehicle.faults.due(t_s):
        logger.warning("fault injected at %.3f s: %s", t_s, fault.kind.value)
        if fault.kind is FaultKind.CAMERA_FAIL:
            vehicle.camera_failed = True
        elif fault.kind is FaultKind.CAMERA_DISCONNECT:
            vehicle.camera_failed = True
            if vehicle.camera is not None:
                vehicle.camera.server.disconnect()
        elif fault.kind is FaultKind.LINK_LOSS:
            vehicle.links[0].cut = True


def install_signal_handlers(vehicle: SitlVehicle) -> None:
    """SIGTERM and SIGINT stop the loop cleanly."""

    def handler(signum: int, frame: FrameType | None) -> None:
        vehicle.request_stop()

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)
