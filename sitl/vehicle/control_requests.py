"""The SITL's control-channel requests, answered against one vehicle: the simulated pilot, faults, wind, lockstep
subscription and acknowledgement, ground truth and shutdown. The vocabulary and the checks of every field are
``companion.vehicle.sim_control``; the socket is ``sitl.vehicle.control_channel``; this is what each request does.
"""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from companion.vehicle.sim_control import Command, Event, RequestError, flag, frames_wanted, lockstep_ack, number
from sitl.autopilot.actuators import ActuatorOutputs
from sitl.autopilot.commander import Commander
from sitl.autopilot.mavlink_link import MavlinkLink
from sitl.autopilot.mavlink_server import MAX_SENDERS_REPORTED, MavlinkServer
from sitl.autopilot.modes import FlightMode
from sitl.autopilot.status import ControlSource
from sitl.config import MAX_WIND_MPS, SitlConfig
from sitl.dynamics.base import Dynamics
from sitl.timing.clock import SimClock
from sitl.timing.lockstep_gate import LockstepGate
from sitl.vehicle.control_channel import ControlChannel
from sitl.world.crowd import CrowdError

if TYPE_CHECKING:  # the camera module needs the renderer, which a SITL without a camera never loads
    from sitl.vehicle.sim_camera import SimCamera


MAX_PLACE_M = 1000.0
"""How far from the origin ``place_person`` may put someone (m, per axis)."""


class ControlledVehicle(Protocol):
    """What the control channel's requests read and act on (:class:`sitl.vehicle.process.SitlVehicle` is one)."""

    config: SitlConfig
    clock: SimClock
    commander: Commander
    dynamics: Dynamics
    lockstep: LockstepGate
    links: list[MavlinkLink]
    mavlink: MavlinkServer
    control: ControlChannel | None
    camera: SimCamera | None
    """The simulated camera, or None without one."""
    camera_failed: bool
    actuators: ActuatorOutputs
    """The autopilot's actuator outputs and the warning device on one."""

    @property
    def handler_errors(self) -> int:
        """Messages and requests whose handling raised."""
        ...

    def fail_camera(self, failed: bool) -> None:
        """The camera delivers nothing from now on (or again)."""
        ...

    def request_stop(self, *_: object) -> None:
        """Stop at the next loop turn."""
        ...


class ControlRequests:
    """The control channel's requests for ``vehicle``."""

    def __init__(self, vehicle: ControlledVehicle) -> None:
        self.vehicle = vehicle

    def handle(self, request: dict[str, Any], addr: tuple[str, int]) -> None:
        """Answer one checked request from ``addr`` (an error event naming the field when a field is bad)."""
        v = self.vehicle
        assert v.control is not None
        cmd = request["cmd"]
        reply: dict[str, Any] = {"event": Event.ACK.value, "cmd": cmd}
        try:
            if cmd == Command.PING:
                reply = {"event": Event.PONG.value, "t_s": v.clock.now_s, "pid": os.getpid()}
            elif cmd == Command.STATE:
                reply = self.state()
            elif cmd == Command.PILOT_MODE:
                mode = request.get("mode")
                if not isinstance(mode, str):
                    raise RequestError("mode: expected a mode name")
                reply["result"] = int(v.commander.set_mode(FlightMode.from_name(mode[:32]), ControlSource.PILOT))
            elif cmd == Command.PILOT_STICKS:
                v.commander.set_pilot_sticks(
                    *(number(request, k, -1.0, 1.0, default=0.0) for k in ("north", "east", "down"))
                )
            elif cmd == Command.RC_LOSS:
                v.commander.set_rc_lost(flag(request, "lost"))
            elif cmd == Command.WIND:
                wind = request.get("ned_mps")
                if not isinstance(wind, list) or len(wind) != 3:
                    raise RequestError("ned_mps: expected three numbers (north, east, down m/s)")
                components = {f"ned_mps[{i}]": v for i, v in enumerate(wind)}
                v.dynamics.set_wind(np.array([number(components, k, -MAX_WIND_MPS, MAX_WIND_MPS) for k in components]))
            elif cmd == Command.LOCKSTEP_SUBSCRIBE:
                v.lockstep.subscribe(addr, frames_wanted(request))  # the pending tick goes (again) to this client
                reply["tick_period_s"] = v.config.lockstep_period_s
            elif cmd == Command.LOCKSTEP_RELEASE:  # the client is leaving: run free from here on
                v.lockstep.release()
                v.clock.resync()
            elif cmd == Command.CAMERA_FAIL:
                if v.camera is None:
                    raise ValueError("this SITL has no camera")
                v.fail_camera(flag(request, "failed"))
            elif cmd == Command.LINK_LOSS:
                v.links[0].cut = flag(request, "lost")
            elif cmd == Command.LOCKSTEP_ACK:
                v.lockstep.acknowledge(addr, lockstep_ack(request))
                return
            elif cmd == Command.PEOPLE:
                if v.camera is None:
                    raise ValueError("this SITL has no world (camera disabled)")
                reply = {"event": Event.PEOPLE.value, **v.camera.people()}
            elif cmd == Command.PLACE_PERSON:
                if v.camera is None:
                    raise ValueError("this SITL has no world (camera disabled)")
                north, east = (number(request, k, -MAX_PLACE_M, MAX_PLACE_M) for k in ("north_m", "east_m"))
                v.camera.crowd.advance_to(v.clock.now_s)
                try:
                    reply["index"] = v.camera.crowd.place(north, east)
                except CrowdError as exc:
                    raise ValueError(str(exc)) from None
            elif cmd == Command.SHUTDOWN:
                v.request_stop()
            else:
                raise ValueError(f"unknown cmd {cmd!r}")
        except (KeyError, ValueError, TypeError) as exc:
            reply = {"event": Event.ERROR.value, "cmd": cmd, "error": str(exc)}
        request_id = request.get("id")
        if isinstance(request_id, (int, str)) and len(str(request_id)) <= 64:
            reply["id"] = request_id  # lets the requester match replies to requests
        v.control.send(reply, addr)

    def state(self) -> dict[str, Any]:
        """The ``state`` reply: ground truth, modes, faults and every counter (it always fits one datagram)."""
        v = self.vehicle
        s = v.dynamics.state()
        cmd = v.commander
        return {
            "event": Event.STATE.value,
            "t_s": v.clock.now_s,
            "position_ned_m": s.position_ned_m.tolist(),
            "velocity_ned_mps": s.velocity_ned_mps.tolist(),
            "quaternion_wxyz": s.quaternion_wxyz.tolist(),
            "on_ground": s.on_ground,
            "armed": cmd.armed,
            "mode": cmd.mode.px4_name,
            "landed_state": cmd.landed_state.name,
            "failsafe": cmd.failsafe,
            "failsafe_since_s": None if math.isnan(cmd.failsafe_since_s) else cmd.failsafe_since_s,
            "rc_lost": cmd.rc_lost,
            "camera_failed": v.camera_failed,
            "api_link_cut": v.links[0].cut,
            "lockstep_tick": v.lockstep.seq,
            "setpoints_rejected": v.mavlink.setpoints_rejected,
            "setpoints_between_ticks": v.lockstep.setpoints_between_ticks,
            "frames": None
            if v.camera is None
            else {
                "sent": v.camera.server.stats.sent,
                "dropped": v.camera.server.stats.dropped,
                "clients": v.camera.server.stats.clients,
                "refused": v.camera.server.stats.refused,
                "not_wanted": v.camera.server.stats.not_wanted,
            },
            "warning": {  # the vehicle's warning device, and the people who reacted to it (scenario.reaction)
                "on": v.actuators.warning_on,
                "times_on": v.actuators.warnings,
                "reactions": None if v.camera is None else v.camera.crowd.reaction.reactions,
            },
            "handler_errors": v.handler_errors,
            "control_malformed": v.control.malformed if v.control is not None else 0,
            "commands_by_sender": dict(v.mavlink.commands_by_sender),
            "setpoints_by_sender": dict(v.mavlink.setpoints_by_sender),
            "links": {
                link.name: {
                    "received": link.stats.received,
                    "sent": link.stats.sent,
                    "dropped_malformed": link.stats.dropped_malformed,
                    "dropped_unknown": link.stats.dropped_unknown,
                    "senders": sorted({f"{s_}/{c_}" for s_, c_ in link.stats.per_source})[:MAX_SENDERS_REPORTED],
                    "dropped_unsigned": link.stats.dropped_unsigned,
                    "stray_frames": link.stats.stray_frames,
                    "partner": f"{link.remote[0]}:{link.remote[1]}",
                }
                for link in v.links
            },
        }
