"""The MAVLink mission protocol, as PX4's ``mavlink_mission.cpp`` serves it: missions, geofences and rally points.

Download: MISSION_REQUEST_LIST gives MISSION_COUNT, each MISSION_REQUEST_INT (MISSION_REQUEST) gives MISSION_ITEM_INT
(MISSION_ITEM), the ground station ends with MISSION_ACK. Upload: MISSION_COUNT starts it, the vehicle asks for each
item in turn and re-asks after :data:`RETRY_S` of silence (the request or the item was lost), up to
:data:`MAX_RETRIES` times; the last item is answered with MISSION_ACK, and only then does the new list replace the
old one (a failed or abandoned upload changes nothing). MISSION_CLEAR_ALL empties a list, MISSION_SET_CURRENT picks
the next item. Every item is checked before it is stored: a command this autopilot does not fly, a frame it does not
know, a coordinate that is not a finite point within :data:`MAX_DISTANCE_M` of the origin is refused with the
MAV_MISSION_RESULT that names it and a CRITICAL status text.

The vehicle asks for items with MISSION_REQUEST (QGroundControl answers it and MISSION_REQUEST_INT alike; MAVProxy
1.8 answers only MISSION_REQUEST) and takes either MISSION_ITEM or MISSION_ITEM_INT in reply. Retry timing is wall
time: it is about lost datagrams, not about the simulated flight.
"""

from __future__ import annotations

import enum
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from companion.errors import SlzError
from sitl.autopilot.geofence import Fence
from sitl.autopilot.mavlink_link import MavlinkLink, for_autopilot
from sitl.autopilot.navigator import NavCommand, Navigator, NavItem
from sitl.autopilot.status import MavResult, Severity
from sitl.autopilot.telemetry import Origin
from sitl.geodesy import geodetic_to_ned

logger = logging.getLogger(__name__)

RETRY_S = 0.25  # wall seconds without the requested item before asking again (PX4: 250 ms)
MAX_RETRIES = 20  # then the upload is abandoned (5 s of silence)
MAX_DISTANCE_M = 10_000.0  # the flat-earth conversion's scale
MAX_ITEMS = {0: 500, 1: 64, 2: 16}  # per list: mission, fence vertices and circles, rally points


class MissionType(enum.IntEnum):
    """MAV_MISSION_TYPE."""

    MISSION = 0
    FENCE = 1
    RALLY = 2
    ALL = 255


class MissionResult(enum.IntEnum):
    """MAV_MISSION_RESULT values used here."""

    ACCEPTED = 0
    ERROR = 1
    UNSUPPORTED_FRAME = 2
    UNSUPPORTED = 3
    NO_SPACE = 4
    INVALID = 5
    INVALID_PARAM1 = 6
    INVALID_PARAM2 = 7
    INVALID_PARAM4 = 9
    INVALID_PARAM5_X = 10
    INVALID_PARAM6_Y = 11
    INVALID_PARAM7 = 12
    INVALID_SEQUENCE = 13
    DENIED = 14
    OPERATION_CANCELLED = 15


ABSOLUTE_FRAMES = {mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT}
RELATIVE_FRAMES = {mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
FENCE_COMMANDS = {
    mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT,
    mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
    mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
    mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
    mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
}
RALLY_COMMANDS = {mavlink.MAV_CMD_NAV_RALLY_POINT}
POLYGON_COMMANDS = {
    mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
    mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
}


@dataclass(frozen=True)
class StoredItem:
    """One item as received (returned unchanged on download): latitude and longitude in 1e-7 degrees."""

    frame: int
    command: int
    autocontinue: int
    params: tuple[float, float, float, float]
    lat_e7: int
    lon_e7: int
    alt_m: float


@dataclass
class Upload:
    """An upload in progress on one link from one sender."""

    link: MavlinkLink
    peer: tuple[int, int]
    mission_type: MissionType
    count: int
    items: list[StoredItem]
    last_activity_wall_s: float
    retries: int = 0


class ItemRefusedError(SlzError):
    """An uploaded item cannot be stored (the MAV_MISSION_RESULT and why)."""

    def __init__(self, result: MissionResult, why: str) -> None:
        super().__init__(why)
        self.result = result


class MissionServer:
    """The mission, fence and rally lists of a vehicle and the protocol that reads and writes them.

    Parameters
    ----------
    navigator : Navigator
        Flies the mission (the list is handed to it once an upload completes).
    set_fence : callable
        ``set_fence(fence)`` hands the commander a completed fence upload.
    system_id : int
        This autopilot's MAVLink system id (messages for another system are not ours).
    origin : Origin
        The geodetic position of the local NED origin (items in latitude and longitude become north and east).
    statustext : callable
        ``statustext(text, severity)`` tells the ground stations why an upload or a request was refused.
    """

    def __init__(
        self,
        navigator: Navigator,
        set_fence: Callable[[Fence], None],
        system_id: int,
        origin: Origin,
        statustext: Callable[[str, Severity], None],
    ) -> None:
        self.navigator = navigator
        self.set_fence = set_fence
        self.system_id = system_id
        self.origin = origin
        self.statustext = statustext
        self.lists: dict[MissionType, list[StoredItem]] = {t: [] for t in MissionType if t is not MissionType.ALL}
        self.upload: Upload | None = None
        self.uploads_accepted = 0
        self.uploads_refused = 0

    # -- dispatch ----------------------------------------------------------------------------------------------
    def handle(self, link: MavlinkLink, msg: Any) -> bool:
        """Act on a mission-protocol message addressed to us; False when ``msg`` is not one."""
        kind = msg.get_type()
        if not kind.startswith("MISSION_") or kind in ("MISSION_CURRENT", "MISSION_ITEM_REACHED"):
            return False
        if not for_autopilot(msg, self.system_id):
            return True
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        try:
            mission_type = MissionType(int(getattr(msg, "mission_type", 0)))
        except ValueError:
            self._ack(link, peer, 0, MissionResult.UNSUPPORTED)
            return True
        if kind == "MISSION_REQUEST_LIST":
            self._send_count(link, peer, mission_type)
        elif kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            self._send_item(link, peer, mission_type, int(msg.seq), as_int=kind == "MISSION_REQUEST_INT")
        elif kind == "MISSION_COUNT":
            self._start_upload(link, peer, mission_type, int(msg.count))
        elif kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            self._receive_item(link, peer, msg, as_int=kind == "MISSION_ITEM_INT")
        elif kind == "MISSION_CLEAR_ALL":
            self._clear(link, peer, mission_type)
        elif kind == "MISSION_SET_CURRENT" and self.navigator.set_mission_current(int(msg.seq)) != MavResult.ACCEPTED:
            self.statustext(f"Mission: no item {int(msg.seq)}", Severity.CRITICAL)
        return True  # MISSION_ACK from a ground station after a download: nothing to do

    def _ack(self, link: MavlinkLink, peer: tuple[int, int], mission_type: int, result: MissionResult) -> None:
        link.send(link.mav.mission_ack_encode(peer[0], peer[1], int(result), mission_type))

    # -- download ----------------------------------------------------------------------------------------------
    def _send_count(self, link: MavlinkLink, peer: tuple[int, int], mission_type: MissionType) -> None:
        if mission_type is MissionType.ALL:
            self._ack(link, peer, int(mission_type), MissionResult.UNSUPPORTED)
            return
        link.send(link.mav.mission_count_encode(peer[0], peer[1], len(self.lists[mission_type]), int(mission_type)))

    def _send_item(
        self, link: MavlinkLink, peer: tuple[int, int], mission_type: MissionType, seq: int, as_int: bool
    ) -> None:
        items = self.lists.get(mission_type, [])
        if not 0 <= seq < len(items):
            self._ack(link, peer, int(mission_type), MissionResult.INVALID_SEQUENCE)
            return
        item = items[seq]
        current = int(mission_type is MissionType.MISSION and seq == self.navigator.mission_current)
        common = (peer[0], peer[1], seq)
        if as_int:
            frame = {
                mavlink.MAV_FRAME_GLOBAL: mavlink.MAV_FRAME_GLOBAL_INT,
                mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            }.get(item.frame, item.frame)
            message = link.mav.mission_item_int_encode(
                *common, frame, item.command, current, item.autocontinue, *item.params,
                item.lat_e7, item.lon_e7, item.alt_m, int(mission_type),
            )  # fmt: skip
        else:
            frame = {
                mavlink.MAV_FRAME_GLOBAL_INT: mavlink.MAV_FRAME_GLOBAL,
                mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
            }.get(item.frame, item.frame)
            message = link.mav.mission_item_encode(
                *common, frame, item.command, current, item.autocontinue, *item.params,
                item.lat_e7 / 1e7, item.lon_e7 / 1e7, item.alt_m, int(mission_type),
            )  # fmt: skip
        link.send(message)

    # -- upload ------------------------------------------------------------------------------------------------
    def _start_upload(self, link: MavlinkLink, peer: tuple[int, int], mission_type: MissionType, count: int) -> None:
        busy = self.upload
        if busy is not None and (busy.peer != peer or busy.link is not link):
            self._ack(link, peer, int(mission_type), MissionResult.DENIED)
            self.statustext("Mission upload refused: another upload in progress", Severity.CRITICAL)
            return
        if mission_type is MissionType.ALL:
            self._ack(link, peer, int(mission_type), MissionResult.UNSUPPORTED)
            return
        if count > MAX_ITEMS[int(mission_type)]:
            self._ack(link, peer, int(mission_type), MissionResult.NO_SPACE)
            self.statustext(
                f"{mission_type.name.lower()} upload refused: {count} items, at most {MAX_ITEMS[int(mission_type)]}",
                Severity.CRITICAL,
            )
            return
        if count == 0:
            self.upload = None
            self._replace(mission_type, [])
            self._ack(link, peer, int(mission_type), MissionResult.ACCEPTED)
            return
        self.upload = Upload(link, peer, mission_type, count, [], time.monotonic())
        self._request_next()

    def _request_next(self) -> None:
        up = self.upload
        assert up is not None
        link = up.link
        link.send(link.mav.mission_request_encode(up.peer[0], up.peer[1], len(up.items), int(up.mission_type)))

    def _receive_item(self, link: MavlinkLink, peer: tuple[int, int], msg: Any, as_int: bool) -> None:
        up = self.upload
        mission_type = int(getattr(msg, "mission_type", 0))
        if up is None or up.peer != peer or up.link is not link or int(up.mission_type) != mission_type:
            # PX4 answers an item outside an upload with an error, so a confused sender stops
            self._ack(link, peer, mission_type, MissionResult.ERROR if up is None else MissionResult.DENIED)
            return
        up.last_activity_wall_s = time.monotonic()
        up.retries = 0
        seq = int(msg.seq)
        if seq != len(up.items):
            self._request_next()  # a duplicate or an item ahead of its turn: ask again for the one wanted
            return
        try:
            item = self._stored_item(msg, as_int, up.mission_type)
        except ItemRefusedError as exc:
            self.upload = None
            self.uploads_refused += 1
            self._ack(link, peer, mission_type, exc.result)
            self.statustext(f"{up.mission_type.name.lower()} item {seq} refused: {exc}", Severity.CRITICAL)
            return
        up.items.append(item)
        if len(up.items) < up.count:
            self._request_next()
            return
        self.upload = None
        try:
            self._replace(up.mission_type, up.items)
        except ItemRefusedError as exc:
            self.uploads_refused += 1
            self._ack(link, peer, mission_type, exc.result)
            self.statustext(f"{up.mission_type.name.lower()} refused: {exc}", Severity.CRITICAL)
            return
        self.uploads_accepted += 1
        self._ack(link, peer, mission_type, MissionResult.ACCEPTED)
        logger.info("%s uploaded: %d items", up.mission_type.name.lower(), up.count)

    def tick(self) -> None:
        """Ask again for an item that did not come; abandon an upload after :data:`MAX_RETRIES` asks."""
        up = self.upload
        if up is None or time.monotonic() - up.last_activity_wall_s < RETRY_S:
            return
        if up.retries >= MAX_RETRIES:
            self.upload = None
            self._ack(up.link, up.peer, int(up.mission_type), MissionResult.OPERATION_CANCELLED)
            self.statustext(f"{up.mission_type.name.lower()} upload timed out", Severity.CRITICAL)
            return
        up.retries += 1
        up.last_activity_wall_s = time.monotonic()
        self._request_next()

    def _clear(self, link: MavlinkLink, peer: tuple[int, int], mission_type: MissionType) -> None:
        types = list(self.lists) if mission_type is MissionType.ALL else [mission_type]
        for t in types:
            self._replace(t, [])
        self._ack(link, peer, int(mission_type), MissionResult.ACCEPTED)

    def _replace(self, mission_type: MissionType, items: list[StoredItem]) -> None:
        """A whole list replaces the old one: missions are handed to the commander as flown items."""
        if mission_type is MissionType.FENCE:
            self.set_fence(self._fence(items))
        if mission_type is MissionType.MISSION:
            self.navigator.set_mission([self._nav_item(seq, item) for seq, item in enumerate(items)])
        self.lists[mission_type] = list(items)

    # -- checks and conversions --------------------------------------------------------------------------------
    def _stored_item(self, msg: Any, as_int: bool, mission_type: MissionType) -> StoredItem:
        command, frame = int(msg.command), int(msg.frame)
        params = (float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4))
        allowed = {
            MissionType.MISSION: {int(c) for c in NavCommand},
            MissionType.FENCE: FENCE_COMMANDS,
            MissionType.RALLY: RALLY_COMMANDS,
        }[mission_type]
        if command not in allowed:
            name = mavlink.enums["MAV_CMD"][command].name if command in mavlink.enums["MAV_CMD"] else str(command)
            raise ItemRefusedError(MissionResult.UNSUPPORTED, f"command {name} is not supported")
        positional = command != NavCommand.RETURN_TO_LAUNCH
        if positional and frame not in ABSOLUTE_FRAMES | RELATIVE_FRAMES:
            raise ItemRefusedError(MissionResult.UNSUPPORTED_FRAME, f"frame {frame} is not supported")
        if as_int:
            lat_e7, lon_e7 = int(msg.x), int(msg.y)
        else:
            if positional and not (math.isfinite(msg.x) and math.isfinite(msg.y)):
                raise ItemRefusedError(MissionResult.INVALID_PARAM5_X, "latitude or longitude is not a number")
            lat_e7, lon_e7 = (round(float(msg.x) * 1e7), round(float(msg.y) * 1e7)) if positional else (0, 0)
        alt = float(msg.z)
        if positional:
            if not -900_000_000 <= lat_e7 <= 900_000_000:
                raise ItemRefusedError(MissionResult.INVALID_PARAM5_X, f"latitude {lat_e7 / 1e7} outside [-90, 90]")
            if not -1_800_000_000 <= lon_e7 <= 1_800_000_000:
                raise ItemRefusedError(MissionResult.INVALID_PARAM6_Y, f"longitude {lon_e7 / 1e7} outside [-180, 180]")
            if not math.isfinite(alt) or abs(alt) > MAX_DISTANCE_M:
                raise ItemRefusedError(MissionResult.INVALID_PARAM7, f"altitude {alt} is not a usable number")
            if lat_e7 != 0 or lon_e7 != 0:
                north, east = self._ned(lat_e7, lon_e7)
                if math.hypot(north, east) > MAX_DISTANCE_M:
                    raise ItemRefusedError(MissionResult.INVALID_PARAM5_X, f"more than {MAX_DISTANCE_M:g} m from home")
        for i, value in enumerate(params):
            if math.isinf(value) or (i < 2 and math.isnan(value) and command in POLYGON_COMMANDS):
                raise ItemRefusedError(MissionResult(MissionResult.INVALID_PARAM1 + i), f"param{i + 1} is {value}")
        return StoredItem(frame, command, int(msg.autocontinue), params, lat_e7, lon_e7, alt)

    def _ned(self, lat_e7: int, lon_e7: int) -> tuple[float, float]:
        o = self.origin
        north, east, _ = geodetic_to_ned(lat_e7 / 1e7, lon_e7 / 1e7, 0.0, o.lat_deg, o.lon_deg, 0.0)
        return north, east

    def _nav_item(self, seq: int, item: StoredItem) -> NavItem:
        """The commander's view of a stored mission item: local NED, NaN where the item leaves it to the vehicle."""
        command = NavCommand(item.command)
        north = east = math.nan
        if item.lat_e7 != 0 or item.lon_e7 != 0:
            north, east = self._ned(item.lat_e7, item.lon_e7)
        down = above_home = math.nan
        if command is not NavCommand.RETURN_TO_LAUNCH and command is not NavCommand.LAND:
            if item.frame in RELATIVE_FRAMES:
                above_home = item.alt_m
            else:
                down = self.origin.alt_m - item.alt_m
        p1, p2, _p3, p4 = item.params
        hold_s = p1 if command in (NavCommand.WAYPOINT, NavCommand.LOITER_TIME) and math.isfinite(p1) else 0.0
        radius = p2 if command is NavCommand.WAYPOINT and math.isfinite(p2) and p2 > 0 else math.nan
        yaw = math.radians(p4) if math.isfinite(p4) and command is not NavCommand.LOITER_TIME else math.nan
        return NavItem(seq, command, north, east, down, above_home, max(hold_s, 0.0), radius, yaw)

    def _fence(self, items: list[StoredItem]) -> Fence:
        """The commander's fence (local NED) from fence items, checked as it is built: polygon vertices come in whole
        groups of the count their first vertex declares (at least 3), and a circle has a radius."""
        polygons: dict[int, list[Any]] = {command: [] for command in POLYGON_COMMANDS}
        circles: dict[int, list[tuple[float, float, float]]] = {
            mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION: [],
            mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION: [],
        }
        i = 0
        while i < len(items):
            item = items[i]
            if item.command in polygons:
                count = item.params[0]
                if not (math.isfinite(count) and count >= 3 and count == round(count)):
                    raise ItemRefusedError(MissionResult.INVALID_PARAM1, f"polygon at item {i} has {count} vertices")
                group = items[i : i + int(count)]
                if len(group) < count or any(v.command != item.command for v in group):
                    raise ItemRefusedError(MissionResult.INVALID, f"polygon at item {i} is incomplete")
                polygons[item.command].append(np.array([self._ned(v.lat_e7, v.lon_e7) for v in group]))
                i += len(group)
                continue
            if item.command != mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT and not item.params[0] > 0:
                raise ItemRefusedError(MissionResult.INVALID_PARAM1, f"circle at item {i} has no radius")
            if item.command in circles:
                circles[item.command].append((*self._ned(item.lat_e7, item.lon_e7), item.params[0]))
            i += 1
        return Fence(
            tuple(polygons[mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION]),
            tuple(polygons[mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION]),
            tuple(circles[mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION]),
            tuple(circles[mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION]),
        )
