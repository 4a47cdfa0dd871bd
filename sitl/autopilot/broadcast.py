"""What the autopilot says on its links without being asked: heartbeats (1 Hz of wall time, and at once on a mode or
arming change), the telemetry streams each link's schedule has due, the commander's events as STATUSTEXT, mission
progress, and the pose at a lockstep tick."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from sitl.autopilot.battery import Battery
from sitl.autopilot.commander import Commander
from sitl.autopilot.mavlink_link import MavlinkLink
from sitl.autopilot.status import Severity
from sitl.autopilot.telemetry import (
    API_RATES_HZ,
    GCS_RATES_HZ,
    StreamSchedule,
    TelemetryBuilder,
    statustext_messages,
)
from sitl.dynamics.base import VehicleState

HEARTBEAT_PERIOD_S = 1.0
WAITING_HEARTBEAT_PERIOD_S = 0.1
"""Heartbeats while a lockstep SITL waits for its first client (simulated time stands still at 0): a client finds
the autopilot by its heartbeat, so at PX4's 1 Hz a campaign mission's companion waited up to a wall second for one."""


class Broadcaster:
    """The autopilot's unsolicited messages on its links.

    Parameters
    ----------
    api, gcs : MavlinkLink
        The companion's link (its streams at ``API_RATES_HZ``, the tick's pose) and the ground station's
        (``GCS_RATES_HZ``).
    telemetry : TelemetryBuilder
        Builds each message.
    commander : Commander
        Mode, arming, events and the navigator's mission progress.
    battery : Battery
        The battery the streams report.
    """

    def __init__(
        self,
        api: MavlinkLink,
        gcs: MavlinkLink,
        telemetry: TelemetryBuilder,
        commander: Commander,
        battery: Battery,
    ) -> None:
        self.links = [api, gcs]
        self.telemetry = telemetry
        self.commander = commander
        self.battery = battery
        self.schedules = {id(api): StreamSchedule(API_RATES_HZ), id(gcs): StreamSchedule(GCS_RATES_HZ)}
        """Each link's telemetry schedule, by the link's ``id()`` (SET_MESSAGE_INTERVAL changes it)."""
        self._last_heartbeat_wall = -math.inf
        self._statustext_id = 0
        self.sink: Callable[[Severity, str], None] | None = None
        """Also given every STATUSTEXT sent (the flight's ULog)."""

    def statustext(self, text: str, severity: Severity = Severity.INFO) -> None:
        """A STATUSTEXT on every link, at PX4's severity (refusals and failsafes CRITICAL), in chunks of 50
        characters when longer (MAVLink 2's ``id`` and ``chunk_seq``)."""
        if self.sink is not None:
            self.sink(severity, text)
        self._statustext_id = (self._statustext_id + 1) % 65536 or 1
        for link in self.links:
            for message in statustext_messages(link.mav, text, int(severity), self._statustext_id):
                link.send(message)

    def heartbeat_now(self) -> None:
        """A heartbeat on every link at once (a mode or arming change must be seen without waiting)."""
        self._last_heartbeat_wall = -math.inf
        self.heartbeat_if_due(waiting=False)

    def heartbeat_if_due(self, waiting: bool) -> None:
        """A heartbeat on every link when its period has passed (wall time; shorter while ``waiting`` for a lockstep
        client)."""
        now = time.monotonic()
        if now - self._last_heartbeat_wall >= (WAITING_HEARTBEAT_PERIOD_S if waiting else HEARTBEAT_PERIOD_S):
            self._last_heartbeat_wall = now
            for link in self.links:
                link.send(self.telemetry.heartbeat(link.mav, self.commander))

    def streams(self, t_s: float, state: VehicleState) -> None:
        """The streams due at ``t_s``, each link's in as few datagrams as fit (:meth:`MavlinkLink.send_all`)."""
        for link in self.links:
            due = self.schedules[id(link)].due(t_s)
            if due:
                link.send_all(
                    [self.telemetry.build(n, link.mav, t_s, state, self.commander, self.battery) for n in due]
                )

    def tick_pose(self, t_s: float, state: VehicleState) -> None:
        """The pose at a lockstep tick's instant on the companion's link, before the tick, so the client can pair the
        tick's frame with a pose stamped at its capture time (the scheduled streams need not fall on tick instants)."""
        api = self.links[0]
        api.send_all(
            [
                self.telemetry.build(name, api.mav, t_s, state, self.commander, self.battery)
                for name in ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION")
            ]
        )

    def announce(self, t_s: float, state: VehicleState) -> bool:
        """The commander's new events as STATUSTEXT, a heartbeat at once on a mode or arming change, and the mission's
        progress; whether mode or arming changed."""
        cmd = self.commander
        changed = cmd.changed
        if changed:
            cmd.changed = False
            self._last_heartbeat_wall = -math.inf
        while cmd.events:
            severity, text = cmd.events.popleft()
            self.statustext(text, severity)
        nav = cmd.navigator
        if nav.mission_changed:
            nav.mission_changed = False
            for link in self.links:
                link.send(self.telemetry.build("MISSION_CURRENT", link.mav, t_s, state, cmd, self.battery))
        while nav.mission_reached:
            seq = nav.mission_reached.popleft()
            for link in self.links:
                link.send(link.mav.mission_item_reached_encode(seq))
        return changed
