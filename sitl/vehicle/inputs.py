"""What comes in to the SITL vehicle: MAVLink on its links and requests on its control channel, each handed to its
server. A message or request whose handling raises is dropped, counted and logged (at most once a wall second),
never the vehicle's end.
"""

from __future__ import annotations

import logging
import math
import select
import time

from companion.config import quote
from companion.vehicle.sim_control import Event
from sitl.autopilot.mavlink_link import MavlinkLink
from sitl.autopilot.mavlink_server import MavlinkServer
from sitl.vehicle.control_channel import ControlChannel
from sitl.vehicle.control_requests import ControlRequests

logger = logging.getLogger(__name__)


class Inputs:
    """The vehicle's inputs, polled (see the module docstring).

    Parameters
    ----------
    links : list of MavlinkLink
        The MAVLink links (their messages to ``mavlink``).
    control : ControlChannel
        The control channel (its requests to ``requests``).
    mavlink, requests : MavlinkServer, ControlRequests
        What answers each.
    """

    def __init__(
        self, links: list[MavlinkLink], control: ControlChannel, mavlink: MavlinkServer, requests: ControlRequests
    ) -> None:
        self.links = links
        self.control = control
        self.mavlink = mavlink
        self.requests = requests
        self.handler_errors = 0  # messages and requests whose handling raised (dropped, logged, counted)
        self._last_handler_error_wall = -math.inf

    def poll(self) -> None:
        """Handle what came in on the links and the control channel. One select() asks which sockets have something,
        so an idle socket costs no receive call (a poll runs at every outer step, 100 times a simulated second)."""
        sockets: list[MavlinkLink | ControlChannel] = [*self.links, self.control]
        readable = select.select(sockets, [], [], 0)[0]
        for link in self.links:
            if link not in readable:
                continue
            for msg, from_peer in link.receive():
                try:
                    self.mavlink.handle(link, msg, from_peer)
                except Exception as exc:  # a message no check foresaw: drop and count it, never die of it
                    self._handler_failed(f"MAVLink {msg.get_type()} on {link.name}", exc)
        self.mavlink.missions.tick()
        self.mavlink.pump()
        if self.control not in readable:
            return
        for request, addr in self.control.receive():
            try:
                self.requests.handle(request, addr)
            except Exception as exc:
                self._handler_failed(f"control {quote(request.get('cmd'))}", exc)
                self.control.send({"event": Event.ERROR.value, "cmd": "?", "error": "request failed"}, addr)

    def _handler_failed(self, what: str, exc: Exception) -> None:
        """Count a request whose handling raised; log it at most once per wall second."""
        self.handler_errors += 1
        now = time.monotonic()
        if now - self._last_handler_error_wall >= 1.0:
            self._last_handler_error_wall = now
            name = type(exc).__name__
            logger.error("%s dropped: %s: %s (%d so far)", what, name, quote(str(exc)), self.handler_errors)
