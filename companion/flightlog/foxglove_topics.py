"""The topics and schemas of a flight as Foxglove shows it, shared by the live view (``slz fly --live-view``) and the
MCAP export (``slz export --mcap``): the same topic carries the same schema in both.

Every message is JSON with one of Foxglove's well-known schemas (``jsonschema`` encoding, schema named
``foxglove.X``), so its panels (Image, 3D, Log, Raw Messages) read them without a plugin. Times are the vehicle's boot
clock (the flight log's ``t_s``). Frames: ``world`` (east, north, up, as Foxglove's 3D panel expects up),
``world_ned`` (the flight log's: north, east, down; a fixed rotation under ``world``), ``body`` (``T_world_body`` of
each processed frame), ``camera`` (the image's). Topics and what each carries:

=====================  ==========================  ================================================================
topic                  schema                      from
=====================  ==========================  ================================================================
``/camera/image``      foxglove.CompressedImage    the camera frames (saved ones in an export; live at a stated rate)
``/tf``                foxglove.FrameTransform     ``world`` to ``world_ned`` once; ``world_ned`` to ``body`` per
                                                   processed frame
``/slz/map``           foxglove.Grid               the occupancy on the head plane (live only: 0 unknown, 1
                                                   occupied, 2 free), in ``world_ned``
``/slz/zones``         foxglove.SceneUpdate        each processed frame's tracked zones (grey) and target (green)
``/slz/decisions``     foxglove.Log                each decision: its phase, what it did and why
``/slz/phase``         foxglove.Log                each phase change
``/slz/commands``      foxglove.Log                each command sent but the per-tick setpoints
``/slz/setpoint``      foxglove.PoseInFrame        each setpoint sent (``world_ned``)
``/slz/events``        foxglove.Log                failsafes, the warning device, ground-station commands, errors
``/truth/people``      foxglove.SceneUpdate        the SITL's truth: every person (red)
=====================  ==========================  ================================================================
"""

from __future__ import annotations

import base64
import math
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from companion.flightlog.flight_log import RecordKind
from companion.json_value import JsonObject, JsonValue
from companion.perception.projection import HeadPlaneOccupancy

SCHEMAS: dict[str, JsonObject] = {}
_TIME: JsonObject = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
_VEC3: JsonObject = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_QUAT: JsonObject = {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}}
_POSE: JsonObject = {"type": "object", "properties": {"position": _VEC3, "orientation": _QUAT}}
_COLOR: JsonObject = {"type": "object", "properties": {k: {"type": "number"} for k in "rgba"}}
SCHEMAS["foxglove.CompressedImage"] = {
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"},
        "format": {"type": "string"},
    },
}
SCHEMAS["foxglove.FrameTransform"] = {
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"},
        "translation": _VEC3,
        "rotation": _QUAT,
    },
}
SCHEMAS["foxglove.Log"] = {
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "level": {"type": "integer", "description": "0 unknown, 1 debug, 2 info, 3 warning, 4 error, 5 fatal"},
        "message": {"type": "string"},
        "name": {"type": "string"},
        "file": {"type": "string"},
        "line": {"type": "integer"},
    },
}
SCHEMAS["foxglove.PoseInFrame"] = {
    "type": "object",
    "properties": {"timestamp": _TIME, "frame_id": {"type": "string"}, "pose": _POSE},
}
_CYLINDER: JsonObject = {
    "type": "object",
    "properties": {
        "pose": _POSE,
        "size": _VEC3,
        "bottom_scale": {"type": "number"},
        "top_scale": {"type": "number"},
        "color": _COLOR,
    },
}
SCHEMAS["foxglove.SceneUpdate"] = {
    "type": "object",
    "properties": {
        "deletions": {"type": "array"},
        "entities": {
            "type": "array",
            "items": {
                "type": "object",
                "properties": {
                    "timestamp": _TIME,
                    "frame_id": {"type": "string"},
                    "id": {"type": "string"},
                    "lifetime": _TIME,
                    "frame_locked": {"type": "boolean"},
                    "cylinders": {"type": "array", "items": _CYLINDER},
                },
            },
        },
    },
}
SCHEMAS["foxglove.Grid"] = {
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "pose": _POSE,
        "column_count": {"type": "integer"},
        "cell_size": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}}},
        "row_stride": {"type": "integer"},
        "cell_stride": {"type": "integer"},
        "fields": {"type": "array"},
        "data": {"type": "string", "contentEncoding": "base64"},
    },
}
TOPICS = {
    "/camera/image": "foxglove.CompressedImage",
    "/tf": "foxglove.FrameTransform",
    "/slz/zones": "foxglove.SceneUpdate",
    "/slz/decisions": "foxglove.Log",
    "/slz/phase": "foxglove.Log",
    "/slz/commands": "foxglove.Log",
    "/slz/setpoint": "foxglove.PoseInFrame",
    "/slz/map": "foxglove.Grid",
    "/slz/events": "foxglove.Log",
    "/truth/people": "foxglove.SceneUpdate",
}
NED_IN_ENU: JsonObject = {"x": math.sqrt(0.5), "y": math.sqrt(0.5), "z": 0.0, "w": 0.0}
"""The rotation taking NED vectors to ENU: north to y, east to x, down to -z."""


def stamp(t_s: float) -> JsonObject:
    ns = max(0, round(t_s * 1e9))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def quaternion(rotation: list[list[float]]) -> JsonObject:
    """(x, y, z, w) of a 3x3 rotation matrix (rows)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation
    trace = r00 + r11 + r22
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        return {"w": s / 4, "x": (r21 - r12) / s, "y": (r02 - r20) / s, "z": (r10 - r01) / s}
    if r00 > r11 and r00 > r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        return {"w": (r21 - r12) / s, "x": s / 4, "y": (r01 + r10) / s, "z": (r02 + r20) / s}
    if r11 > r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        return {"w": (r02 - r20) / s, "x": (r01 + r10) / s, "y": s / 4, "z": (r12 + r21) / s}
    s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
    return {"w": (r10 - r01) / s, "x": (r02 + r20) / s, "y": (r12 + r21) / s, "z": s / 4}


def discs(t_s: float, prefix: str, discs: list[tuple[float, float, float]], rgba: tuple[float, ...]) -> JsonObject:
    """A scene update of flat cylinders (north, east, radius) on the ground of ``world_ned``."""
    return scene_update(t_s, disc_entities(t_s, prefix, discs, rgba))


def scene_update(t_s: float, entities: list[JsonValue]) -> JsonObject:
    """A foxglove.SceneUpdate that replaces every entity by ``entities``."""
    return {"deletions": [{"timestamp": stamp(t_s), "type": 1, "id": ""}], "entities": entities}


def disc_entities(
    t_s: float, prefix: str, discs: list[tuple[float, float, float]], rgba: tuple[float, ...]
) -> list[JsonValue]:
    """Flat cylinders (north, east, radius) on the ground of ``world_ned``, one scene entity each."""
    r, g, b, a = rgba
    return [
        {
            "timestamp": stamp(t_s),
            "frame_id": "world_ned",
            "id": f"{prefix}{k}",
            "lifetime": {"sec": 0, "nsec": 0},
            "frame_locked": False,
            "cylinders": [
                {
                    "pose": {"position": {"x": n, "y": e, "z": 0.0}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}},
                    "size": {"x": 2 * radius, "y": 2 * radius, "z": 0.05},
                    "bottom_scale": 1.0,
                    "top_scale": 1.0,
                    "color": {"r": r, "g": g, "b": b, "a": a},
                }
            ],
        }
        for k, (n, e, radius) in enumerate(discs)
    ]


def image_file_message(image: Path, t_s: float) -> Callable[[], JsonObject]:
    def build() -> JsonObject:
        fmt = "png" if image.suffix.lower() == ".png" else "jpeg"
        data = base64.b64encode(image.read_bytes()).decode()
        return {"timestamp": stamp(t_s), "frame_id": "camera", "data": data, "format": fmt}

    return build


def log_message(t_s: float, level: int, name: str, message: str) -> JsonObject:
    return {"timestamp": stamp(t_s), "level": level, "message": message, "name": name, "file": "", "line": 0}


def world_ned_transform(t_s: float) -> JsonObject:
    """``world`` (ENU) to ``world_ned``: the fixed rotation."""
    return {
        "timestamp": stamp(t_s),
        "parent_frame_id": "world",
        "child_frame_id": "world_ned",
        "translation": {"x": 0.0, "y": 0.0, "z": 0.0},
        "rotation": NED_IN_ENU,
    }


def grid_message(t_s: float, head_plane: HeadPlaneOccupancy) -> JsonObject:
    """The head-plane occupancy as a foxglove.Grid in ``world_ned``: columns along north (its x), rows along east."""
    grid = head_plane.grid
    cells = np.where(head_plane.known, np.where(head_plane.free, 2, 1), 0).astype(np.uint8)
    data = np.ascontiguousarray(cells.T)  # (east, north): a row of the message runs along north, x of world_ned
    origin: JsonObject = {"x": grid.north_min_m, "y": grid.east_min_m, "z": 0.0}
    return {
        "timestamp": stamp(t_s),
        "frame_id": "world_ned",
        "pose": {"position": origin, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
        "column_count": int(grid.rows),
        "cell_size": {"x": grid.resolution_m, "y": grid.resolution_m},
        "row_stride": int(grid.rows),
        "cell_stride": 1,
        "fields": [{"name": "occupancy", "offset": 0, "type": 1}],
        "data": base64.b64encode(data.tobytes()).decode(),
    }


def image_message(t_s: float, data: bytes, fmt: str) -> JsonObject:
    """A compressed camera image (``fmt``: jpeg or png)."""
    return {"timestamp": stamp(t_s), "frame_id": "camera", "data": base64.b64encode(data).decode(), "format": fmt}


EVENT_KINDS = {
    RecordKind.FAILSAFE.value: 4,
    RecordKind.ERROR.value: 4,
    "warning": 3,
    "ground_command": 2,
    RecordKind.SUPERVISION.value: 3,
}


def messages_of(record: dict[str, Any], folder: Path | None) -> Iterator[tuple[str, float, Any]]:
    """The messages one flight-log record makes: (topic, t_s, message or a function building it). A ``frame``
    record's saved image (under ``folder``) becomes an image message when ``folder`` is given."""
    kind, t = record.get("kind"), record.get("t_s")
    if t is None:
        return
    t_s = float(t)
    if kind == RecordKind.FRAME.value and record.get("path") and folder is not None:
        image = folder / str(record["path"])
        if image.is_file():
            yield "/camera/image", t_s, image_file_message(image, t_s)
    elif kind == RecordKind.FRAME_RESULT.value:
        T = record["T_world_body"]
        yield (
            "/tf",
            t_s,
            {
                "timestamp": stamp(t_s),
                "parent_frame_id": "world_ned",
                "child_frame_id": "body",
                "translation": {"x": T[0][3], "y": T[1][3], "z": T[2][3]},
                "rotation": quaternion([row[:3] for row in T[:3]]),
            },
        )
        zones = [(float(z["north_m"]), float(z["east_m"]), float(z["radius_m"])) for z in record["tracks"] or []]
        entities = disc_entities(t_s, "zone", zones, (0.6, 0.6, 0.6, 0.5))
        target = record.get("target")
        if target:
            disc = (float(target["north_m"]), float(target["east_m"]), float(target["radius_m"]))
            entities += disc_entities(t_s, "target", [disc], (0.1, 0.8, 0.2, 0.8))
        yield "/slz/zones", t_s, scene_update(t_s, entities)
    elif kind == RecordKind.DECISION.value:
        d = record["decision"]
        words = f"{d.get('phase')}: {d.get('kind')}" + (f" ({d['reason']})" if d.get("reason") else "")
        yield "/slz/decisions", t_s, log_message(t_s, 2, "decision", words)
    elif kind == RecordKind.PHASE.value:
        words = f"{record.get('previous')} -> {record['phase']}: {record.get('reason', '')}"
        yield "/slz/phase", t_s, log_message(t_s, 2, "phase", words)
    elif kind == RecordKind.COMMAND.value:
        setpoint = record.get("setpoint")
        if record["command"] == "setpoint" and setpoint:
            yaw = math.radians(float(setpoint.get("yaw_deg") or 0.0))
            pose = {
                "position": {"x": setpoint["north_m"], "y": setpoint["east_m"], "z": setpoint["down_m"]},
                "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)},
            }
            yield "/slz/setpoint", t_s, {"timestamp": stamp(t_s), "frame_id": "world_ned", "pose": pose}
        else:
            yield "/slz/commands", t_s, log_message(t_s, 3, "command", f"sent {record['command']}")
    elif kind in EVENT_KINDS:
        words = ", ".join(f"{k} {v}" for k, v in record.items() if k not in ("kind", "t_s"))
        yield "/slz/events", t_s, log_message(t_s, EVENT_KINDS[str(kind)], str(kind), words[:2000])


def truth_messages(path: Path) -> Iterator[tuple[str, float, Any]]:
    """The SITL's truth (``truth.jsonl``): every person (red) at the header and at each record that moves them."""
    import json

    lines = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
    if not lines or lines[0].get("kind") != "header":
        raise ValueError(f"{path}: no ground-truth header")
    header = lines[0]
    radii = header.get("radii_m") or [0.3] * len(header["positions_ne_m"])
    red = (0.9, 0.1, 0.1, 0.8)

    def people(t_s: float, positions: list[list[float]]) -> tuple[str, float, Any]:
        found = [(float(n), float(e), float(r)) for (n, e), r in zip(positions, radii, strict=False)]
        return "/truth/people", t_s, discs(t_s, "person", found, red)

    yield people(float(header.get("t_s", 0.0)), header["positions_ne_m"])
    for line in lines[1:]:
        if line.get("kind", "truth") == "truth" and line.get("positions_ne_m") is not None:
            yield people(float(line["t_s"]), line["positions_ne_m"])
