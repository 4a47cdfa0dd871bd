"""A recorded flight as an MCAP file Foxglove opens as it is (``slz export FLIGHT --mcap``): the camera frames, the
vehicle's pose as transforms, the zones and the target in the world, the decisions and phases as log messages, the
commands sent; and, for a SITL run, the truth (where every person really was).

Every message is JSON with one of Foxglove's well-known schemas (``jsonschema`` encoding, schema named
``foxglove.X``), so its panels (Image, 3D, Log, Raw Messages) read them without a plugin. Log time is the vehicle's
boot clock (the flight log's ``t_s``) in nanoseconds. Frames: ``world`` (east, north, up, as Foxglove's 3D panel
expects up), ``world_ned`` (the flight log's: north, east, down; a fixed rotation under ``world``), ``body``
(``T_world_body`` of each processed frame). Topics and what each carries:

=====================  ==========================  ================================================================
topic                  schema                      from
=====================  ==========================  ================================================================
``/camera/image``      foxglove.CompressedImage    each saved frame (``frames/``: PNG or JPEG, as saved)
``/tf``                foxglove.FrameTransform     ``world`` to ``world_ned`` once; ``world_ned`` to ``body`` per
                                                   processed frame
``/slz/zones``         foxglove.SceneUpdate        each processed frame's tracked zones (grey) and target (green)
``/slz/decisions``     foxglove.Log                each decision: its phase, event and reason
``/slz/phase``         foxglove.Log                each phase change
``/slz/commands``      foxglove.Log                each command sent but the per-tick setpoints
``/slz/setpoint``      foxglove.PoseInFrame        each setpoint sent (``world_ned``)
``/truth/people``      foxglove.SceneUpdate        the SITL's truth: every person (red) at each truth record
=====================  ==========================  ================================================================
"""

from __future__ import annotations

import base64
import json
import math
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

from companion.app.flight_log import FlightLog, RecordKind
from companion.errors import SlzError

SCHEMAS: dict[str, dict[str, Any]] = {}
_TIME = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
_VEC3 = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_QUAT = {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}}
_POSE = {"type": "object", "properties": {"position": _VEC3, "orientation": _QUAT}}
_COLOR = {"type": "object", "properties": {k: {"type": "number"} for k in "rgba"}}
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
_CYLINDER = {
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
TOPICS = {
    "/camera/image": "foxglove.CompressedImage",
    "/tf": "foxglove.FrameTransform",
    "/slz/zones": "foxglove.SceneUpdate",
    "/slz/decisions": "foxglove.Log",
    "/slz/phase": "foxglove.Log",
    "/slz/commands": "foxglove.Log",
    "/slz/setpoint": "foxglove.PoseInFrame",
    "/truth/people": "foxglove.SceneUpdate",
}
NED_IN_ENU = {"x": math.sqrt(0.5), "y": math.sqrt(0.5), "z": 0.0, "w": 0.0}
"""The rotation taking NED vectors to ENU: north to y, east to x, down to -z."""


class ExportError(SlzError):
    """A flight could not be exported: what and where."""


def _stamp(t_s: float) -> dict[str, int]:
    ns = max(0, round(t_s * 1e9))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _quaternion(rotation: list[list[float]]) -> dict[str, float]:
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


def _discs(t_s: float, prefix: str, discs: list[tuple[float, float, float]], rgba: tuple[float, ...]) -> dict[str, Any]:
    """A scene update of flat cylinders (north, east, radius) on the ground of ``world_ned``."""
    r, g, b, a = rgba
    entities = [
        {
            "timestamp": _stamp(t_s),
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
    return {"deletions": [{"timestamp": _stamp(t_s), "type": 1, "id": ""}], "entities": entities}


def _image_message(image: Path, t_s: float) -> Callable[[], dict[str, Any]]:
    def build() -> dict[str, Any]:
        fmt = "png" if image.suffix.lower() == ".png" else "jpeg"
        data = base64.b64encode(image.read_bytes()).decode()
        return {"timestamp": _stamp(t_s), "frame_id": "camera", "data": data, "format": fmt}

    return build


def _log(t_s: float, level: int, name: str, message: str) -> dict[str, Any]:
    return {"timestamp": _stamp(t_s), "level": level, "message": message, "name": name, "file": "", "line": 0}


class _Out:
    """The MCAP writer with a channel per topic, counting what it wrote."""

    def __init__(self, path: Path) -> None:
        try:
            from mcap.writer import Writer
        except ImportError:
            raise ExportError("writing MCAP needs the mcap package: pip install 'slz-lander[report]'") from None
        self._stream = path.open("wb")
        self.writer = Writer(self._stream)
        self.writer.start(profile="", library="slz-lander")
        schema_ids = {
            name: self.writer.register_schema(name, "jsonschema", json.dumps(schema).encode())
            for name, schema in SCHEMAS.items()
        }
        self.channels = {
            topic: self.writer.register_channel(topic, "json", schema_ids[schema]) for topic, schema in TOPICS.items()
        }
        self.counts: Counter[str] = Counter()

        self._pending: list[tuple[float, int, str, dict[str, Any] | Callable[[], dict[str, Any]]]] = []

    def add(self, topic: str, t_s: float, message: dict[str, Any] | Callable[[], dict[str, Any]]) -> None:
        """Queue one message (or a function that builds it, for the frames: built when written, one at a time)."""
        self._pending.append((t_s, len(self._pending), topic, message))

    def close(self) -> None:
        """Write the queued messages in log-time order (MCAP readers replay in that order) and finish the file."""
        try:
            for t_s, _, topic, message in sorted(self._pending, key=lambda m: (m[0], m[1])):
                ns = max(0, round(t_s * 1e9))
                body = message() if callable(message) else message
                data = json.dumps(body, separators=(",", ":")).encode()
                self.writer.add_message(self.channels[topic], log_time=ns, data=data, publish_time=ns)
                self.counts[topic] += 1
            self.writer.finish()  # type: ignore[no-untyped-call]
        finally:
            self._stream.close()


def _truth(path: Path, out: _Out) -> None:
    """The SITL's truth: every person (red, 0.3 m) at the header and at each record that moves them."""
    lines = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
    if not lines or lines[0].get("kind") != "header":
        raise ExportError(f"{path}: no ground-truth header")
    header = lines[0]
    radii = header.get("radii_m") or [0.3] * len(header["positions_ne_m"])
    red = (0.9, 0.1, 0.1, 0.8)

    def people(t_s: float, positions: list[list[float]]) -> None:
        discs = [(float(n), float(e), float(r)) for (n, e), r in zip(positions, radii, strict=False)]
        out.add("/truth/people", t_s, _discs(t_s, "person", discs, red))

    people(float(header.get("t_s", 0.0)), header["positions_ne_m"])
    for line in lines[1:]:
        if line.get("kind", "truth") == "truth" and line.get("positions_ne_m") is not None:
            people(float(line["t_s"]), line["positions_ne_m"])


def export_mcap(flight_dir: Path, out_path: Path, truth: Path | None = None) -> Counter[str]:
    """Write the flight in ``flight_dir`` (``flight.jsonl``, ``frames/``) as MCAP at ``out_path``; with ``truth``
    (a SITL run's ``truth.jsonl``) the people too. Returns the messages written per topic.

    Raises
    ------
    ExportError
        No readable flight log, or the mcap package is missing.
    """
    try:
        flight = FlightLog.read(flight_dir)
    except SlzError as exc:
        raise ExportError(f"{flight_dir}: {exc}") from None
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out = _Out(out_path)
    try:
        first = next((float(r["t_s"]) for r in flight.records if r.get("t_s") is not None), 0.0)
        out.add(
            "/tf",
            first,
            {
                "timestamp": _stamp(first),
                "parent_frame_id": "world",
                "child_frame_id": "world_ned",
                "translation": {"x": 0.0, "y": 0.0, "z": 0.0},
                "rotation": NED_IN_ENU,
            },
        )
        folder = Path(flight.path).parent
        for r in flight.records:
            kind, t = r.get("kind"), r.get("t_s")
            if t is None:
                continue
            t_s = float(t)
            if kind == RecordKind.FRAME.value and r.get("path"):
                image = folder / str(r["path"])
                if image.is_file():
                    out.add("/camera/image", t_s, _image_message(image, t_s))
            elif kind == RecordKind.FRAME_RESULT.value:
                T = r["T_world_body"]
                out.add(
                    "/tf",
                    t_s,
                    {
                        "timestamp": _stamp(t_s),
                        "parent_frame_id": "world_ned",
                        "child_frame_id": "body",
                        "translation": {"x": T[0][3], "y": T[1][3], "z": T[2][3]},
                        "rotation": _quaternion([row[:3] for row in T[:3]]),
                    },
                )
                zones = [(float(z["north_m"]), float(z["east_m"]), float(z["radius_m"])) for z in r["tracks"] or []]
                update = _discs(t_s, "zone", zones, (0.6, 0.6, 0.6, 0.5))
                target = r.get("target")
                if target:
                    disc = (float(target["north_m"]), float(target["east_m"]), float(target["radius_m"]))
                    update["entities"] += _discs(t_s, "target", [disc], (0.1, 0.8, 0.2, 0.8))["entities"]
                out.add("/slz/zones", t_s, update)
            elif kind == RecordKind.DECISION.value:
                d = r["decision"]
                words = f"{d.get('phase')}: {d.get('kind')}" + (f" ({d['reason']})" if d.get("reason") else "")
                out.add("/slz/decisions", t_s, _log(t_s, 2, "decision", words))
            elif kind == RecordKind.PHASE.value:
                words = f"{r.get('previous')} -> {r['phase']}: {r.get('reason', '')}"
                out.add("/slz/phase", t_s, _log(t_s, 2, "phase", words))
            elif kind == RecordKind.COMMAND.value:
                setpoint = r.get("setpoint")
                if r["command"] == "setpoint" and setpoint:
                    yaw = math.radians(float(setpoint.get("yaw_deg") or 0.0))
                    pose = {
                        "position": {"x": setpoint["north_m"], "y": setpoint["east_m"], "z": setpoint["down_m"]},
                        "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)},
                    }
                    out.add("/slz/setpoint", t_s, {"timestamp": _stamp(t_s), "frame_id": "world_ned", "pose": pose})
                else:
                    out.add("/slz/commands", t_s, _log(t_s, 3, "command", f"sent {r['command']}"))
        if truth is not None:
            _truth(truth, out)
    finally:
        out.close()
    return out.counts
