"""What the pilot sees of the companion at the ground station, over the vehicle's own MAVLink link.

The autopilot forwards the companion's messages to its ground-station link (PX4's MAVLink forwarding), so
QGroundControl, MAVProxy or any MAVLink ground station shows them without a new link or a new dependency on the drone:

- **STATUSTEXT** at each phase change and failsafe, at PX4-like severities (:data:`PHASE_SEVERITY`): a failsafe is
  CRITICAL (QGroundControl pops it up and speaks it), an abort to hold or a yield to the pilot a WARNING, the landing
  itself a NOTICE, the search and approach INFO. Texts longer than 50 characters go out in MAVLink 2 chunks.
- **LANDING_TARGET** for the chosen target: local NED (``MAV_FRAME_LOCAL_NED``), the target's centre on the ground,
  its slant distance and angular size from the vehicle.
- **NAMED_VALUE_FLOAT** ``SLZ_ZONES`` (tracked free zones), ``SLZ_R_M`` (the target's free radius, m; 0 when there is
  none) and ``SLZ_DRY`` (1 in a dry run), the values a ground station can plot.

In a dry run (``--dry-run``) everything is sent too, marked: texts start with ``[dry run]``, ``SLZ_DRY`` is 1, and
LANDING_TARGET goes out with ``position_valid = 0``, so an autopilot set up for precision landing never acts on a
target the companion was not allowed to fly to (a ground station shows the values all the same).

Decision-time values (targets, zone counts) are sent at most :data:`REPORT_RATE_HZ` per second of vehicle time; every
send is best effort: a refusal is counted and logged, never raised into the flight logic.
"""

from __future__ import annotations

import logging
import math

from companion.guidance.landing import LandingPhase
from companion.guidance.vehicle_state import VehicleState
from companion.perception.selection import Target
from companion.vehicle.ground_messages import GroundMessage, LandingTarget, NamedValueFloat
from companion.vehicle.link import Ground
from companion.vehicle.statustext import statustext_chunks

logger = logging.getLogger(__name__)

REPORT_RATE_HZ = 2.0
DRY_RUN_PREFIX = "[dry run] "
MAV_FRAME_LOCAL_NED = 1
LANDING_TARGET_TYPE_VISION_OTHER = 3
MAV_SEVERITY = {"critical": 2, "warning": 4, "notice": 5, "info": 6}
PHASE_SEVERITY = {
    LandingPhase.FAILSAFE: MAV_SEVERITY["critical"],
    LandingPhase.HOLD: MAV_SEVERITY["warning"],
    LandingPhase.YIELDED: MAV_SEVERITY["warning"],
    LandingPhase.LAND: MAV_SEVERITY["notice"],
    LandingPhase.DONE: MAV_SEVERITY["notice"],
}


def landing_target(t_s: float, target: Target, state: VehicleState, dry_run: bool) -> LandingTarget:
    """LANDING_TARGET for ``target`` seen from ``state`` (local NED; the head plane is taken as the ground, z = 0)."""
    dn, de = target.north_m - state.north_m, target.east_m - state.east_m
    height = max(state.altitude_m, 0.01)
    distance = math.sqrt(dn * dn + de * de + height * height)
    size = 2.0 * math.atan2(target.radius_m, distance)
    return LandingTarget(
        time_usec=round(t_s * 1e6),
        target_num=0,
        frame=MAV_FRAME_LOCAL_NED,
        angle_x=math.atan2(de, height),
        angle_y=math.atan2(dn, height),
        distance=distance,
        size_x=size,
        size_y=size,
        x=target.north_m,
        y=target.east_m,
        z=0.0,
        q=(1.0, 0.0, 0.0, 0.0),
        type=LANDING_TARGET_TYPE_VISION_OTHER,
        position_valid=0 if dry_run else 1,
    )


class GroundReport:
    """Sends the companion's decisions to the ground station (see the module docstring).

    Parameters
    ----------
    ground : Ground
        The vehicle link's ground part, which carries the messages.
    dry_run : bool
        Mark everything as a dry run's.
    """

    def __init__(self, ground: Ground, dry_run: bool) -> None:
        self.ground = ground
        self.dry_run = dry_run
        self.sent = 0
        self.failed = 0
        self._text_id = 0
        self._last_values_t_s = -math.inf

    async def _send(self, message: GroundMessage) -> None:
        try:
            await self.ground.send(message)
            self.sent += 1
        except Exception as exc:  # the ground station's view is informative; flying goes on without it
            self.failed += 1
            if self.failed in (1, 10, 100) or self.failed % 1000 == 0:
                logger.warning("ground report %s not sent (%d so far): %s", message.message_name, self.failed, exc)

    async def text(self, text: str, severity: int) -> None:
        """One status text (chunked when long), marked in a dry run."""
        if self.dry_run:
            text = DRY_RUN_PREFIX + text
        self._text_id = self._text_id % 65535 + 1
        for chunk in statustext_chunks(text, severity, self._text_id):
            await self._send(chunk)

    async def phase(self, phase: LandingPhase, reason: str) -> None:
        """A phase change, at its severity."""
        await self.text(f"SLZ {phase.value}: {reason}", PHASE_SEVERITY.get(phase, MAV_SEVERITY["info"]))

    async def decision_values(self, t_s: float, zones: int, target: Target | None, state: VehicleState | None) -> None:
        """The zone count, the target's radius and the target itself, at most :data:`REPORT_RATE_HZ` (vehicle time)."""
        if t_s - self._last_values_t_s < 1.0 / REPORT_RATE_HZ - 1e-9:
            return
        self._last_values_t_s = t_s
        boot_ms = round(t_s * 1000.0) & 0xFFFFFFFF
        radius = target.radius_m if target is not None else 0.0
        for name, value in (("SLZ_ZONES", float(zones)), ("SLZ_R_M", radius), ("SLZ_DRY", float(self.dry_run))):
            await self._send(NamedValueFloat(time_boot_ms=boot_ms, name=name, value=value))
        if target is not None and state is not None:
            await self._send(landing_target(t_s, target, state, self.dry_run))
