"""The main job: one seeded landing mission in the SITL, flown by the companion in lockstep, and what to look at.

``slz demo`` starts the SITL with a seeded random scene (a park with 80-120 people in the 30 m region of interest) and
the companion with ``mission_configs/sitl.yaml``, flies one mission in lockstep (:mod:`sitl.harness.mission`), and
writes ``runs/<id>/``: the flight log (``flight/flight.jsonl``, with every frame saved losslessly, so ``slz replay``
re-runs it), the SITL's ground truth, ``top_view.png`` (people, the zones tracked when the landing was decided, the
path, the touchdown), ``camera.mp4`` (the camera view with occupancy, zones and target, from a replay of the log) and
``summary.json`` and ``demo.png`` (the camera view as the descent began beside the top view: the README's picture)."""

from __future__ import annotations

import datetime
import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from companion.flightlog.flight_log import FlightLog
from companion.tools.landing_report import landing_report
from companion.tools.replay import flight_config, replay
from companion.tools.report import camera_views, tracks_at_landing
from sitl.harness.mission import DEFAULT_MISSION_CONFIG, MissionResult, MissionSpec, fly
from sitl.vehicle.truth import people_at, read_truth, touchdown

logger = logging.getLogger(__name__)

PERSON_BGR = (160, 40, 200)
PATH_BGR = (40, 40, 40)
ZONE_BGR = (200, 160, 0)
TARGET_BGR = (0, 200, 230)
TOUCHDOWN_BGR = (0, 140, 0)
FENCE_BGR = (0, 0, 200)


@dataclass(frozen=True)
class DemoOutcome:
    """The mission's result plus the demo's files."""

    result: MissionResult
    replay_identical: bool
    top_view_path: Path
    video_path: Path
    descent_zone: tuple[int | None, float, float] | None = None
    """The zone the last descent began over: its track id, free radius (m) and the altitude it was seen from (m)."""


def run(
    out_root: Path,
    seed: int = 1,
    mission_config: Path = DEFAULT_MISSION_CONFIG,
    instance: int = 0,
    timeout_s: float = 600.0,
) -> DemoOutcome:
    """Fly the demo mission into ``out_root/<id>/`` and draw it (see the module docstring)."""
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    run_dir = out_root / f"{stamp}-seed{seed}"
    spec = MissionSpec(
        seed=seed,
        run_dir=run_dir,
        instance=instance,
        mission_config=mission_config,
        record_frames=True,
        timeout_s=timeout_s,
    )
    result = fly(spec)
    video_path = run_dir / "camera.mp4"
    report = replay(run_dir / "flight", video_path=video_path)
    top_view_path = run_dir / "top_view.png"
    cv2.imwrite(str(top_view_path), draw_mission_top_view(run_dir))
    log = FlightLog.read(run_dir / "flight")
    began = landing_report(log)["zone_when_descent_began"]  # the operator's figures, the demo's too
    zone = None
    if began is not None and began.get("radius_m") is not None and began["seen_from_altitude_m"] is not None:
        track_id = began["track_id"]
        zone = (None if track_id is None else int(track_id)), float(began["radius_m"]), began["seen_from_altitude_m"]
    figure = None if began is None else descent_figure(run_dir, log, top_view_path, float(began["t_s"]))
    if figure is not None:
        cv2.imwrite(str(run_dir / "demo.png"), figure)
    summary = {**result.to_json(), "replay_identical": report.identical, "video": str(video_path)}
    if zone is not None:
        summary["descent_zone"] = {"track_id": zone[0], "radius_m": zone[1], "seen_from_altitude_m": zone[2]}
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return DemoOutcome(result, report.identical, top_view_path, video_path, zone)


def descent_figure(run_dir: Path, log: FlightLog, top_view_path: Path, descent_t_s: float) -> np.ndarray | None:
    """The demo's picture (the README's): the camera view when the last descent began (at vehicle time
    ``descent_t_s``; ``log``: the flight's log), with the zones tracked then (cyan, with their ids) and the target
    (yellow), beside the top view; None without a saved frame."""
    flight_dir = run_dir / "flight"
    header = log.header
    top = cv2.imread(str(top_view_path), cv2.IMREAD_COLOR)
    if header is None or top is None:
        return None
    views = [v for v in camera_views(flight_dir, log, flight_config(log, header)) if v[0] <= descent_t_s]
    if not views:
        return None
    _, image, caption = views[-1]
    height = top.shape[0]
    camera = cv2.resize(image, (round(image.shape[1] * height / image.shape[0]), height), interpolation=cv2.INTER_AREA)
    cv2.rectangle(camera, (0, 0), (camera.shape[1], 24), (0, 0, 0), -1)
    cv2.putText(camera, caption[:80], (6, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return np.hstack([camera, np.full((height, 8, 3), 255, np.uint8), top])


def draw_mission_top_view(run_dir: Path, size_px: int = 800, half_extent_m: float = 27.0) -> np.ndarray:
    """North-up top view of a flown mission: ground-truth people (magenta, at touchdown or at the end), the zones
    tracked when the final descent began (cyan), the target (yellow), the true path (grey), the touchdown (green cross)
    and the geofence (red)."""
    header, records = read_truth(run_dir / "truth.jsonl")
    flight = FlightLog.read(run_dir / "flight")
    config = flight.config
    down = touchdown(records)
    at = down if down is not None else (records[-1] if records else None)
    positions, radii = people_at(header, at)
    px_per_m = size_px / (2.0 * half_extent_m)
    view = np.full((size_px, size_px, 3), 245, np.uint8)

    def to_px(north_m: float, east_m: float) -> tuple[int, int]:
        return round((east_m + half_extent_m) * px_per_m), round((half_extent_m - north_m) * px_per_m)

    for step in range(-25, 26, 5):  # a 5 m grid
        a, b = to_px(step, -half_extent_m), to_px(step, half_extent_m)
        cv2.line(view, a, b, (225, 225, 225), 1)
        a, b = to_px(-half_extent_m, step), to_px(half_extent_m, step)
        cv2.line(view, a, b, (225, 225, 225), 1)
    fence = [to_px(n, e) for n, e in config["geofence"]["polygon_ne_m"]]
    cv2.polylines(view, [np.array(fence, np.int32)], True, FENCE_BGR, 1, cv2.LINE_AA)
    for (n, e), r in zip(positions, radii, strict=True):
        cv2.circle(view, to_px(n, e), max(2, round(r * px_per_m)), PERSON_BGR, -1, cv2.LINE_AA)
    path = [to_px(r.position_ned_m[0], r.position_ned_m[1]) for r in records]
    if len(path) > 1:
        cv2.polylines(view, [np.array(path, np.int32)], False, PATH_BGR, 2, cv2.LINE_AA)
    tracks, target = tracks_at_landing(flight)
    for track in tracks:
        centre = to_px(track["north_m"], track["east_m"])
        cv2.circle(view, centre, round(track["radius_m"] * px_per_m), ZONE_BGR, 1, cv2.LINE_AA)
    if target is not None:
        centre = to_px(target.north_m, target.east_m)
        cv2.circle(view, centre, round(target.radius_m * px_per_m), TARGET_BGR, 2, cv2.LINE_AA)
    if down is not None:
        n, e, _ = down.position_ned_m
        cv2.drawMarker(view, to_px(n, e), TOUCHDOWN_BGR, cv2.MARKER_CROSS, 22, 3)
    caption = f"seed {header.seed}  t {0.0 if at is None else at.t_s:.1f} s  " + (
        "touchdown (green)" if down is not None else "no touchdown"
    )
    cv2.putText(view, caption, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(
        view,
        "people (magenta), zones (cyan), target (yellow), path (grey), geofence (red)",
        (8, size_px - 10),
        cv2.FONT_HERSHEY_SIMPLEX,
        0.45,
        (60, 60, 60),
        1,
        cv2.LINE_AA,
    )
    return view


def describe(outcome: DemoOutcome) -> str:
    """The demo's outcome for a terminal."""
    r = outcome.result
    lines = [f"seed {r.seed}: the companion ended in '{r.phase}' ({r.reason})"]
    if r.landed and r.touchdown_ne_m is not None:
        lines.append(
            f"touchdown (ground truth: first contact) at north {r.touchdown_ne_m[0]:.2f} m, east "
            f"{r.touchdown_ne_m[1]:.2f} m, t = {r.touchdown_t_s:.1f} s simulated ({r.wall_s:.0f} s wall); the "
            "flight log's touchdown is the autopilot's landing detection, up to a second or two later"
        )
        lines.append(f"ground truth: the nearest person's body is {r.nearest_person_m:.2f} m from the touchdown point")
    else:
        lines.append("no touchdown")
    zone = outcome.descent_zone
    if zone is not None:
        lines.append(f"zone {zone[0]}: free radius {zone[1]:.2f} m as seen from {zone[2]:.1f} m when the descent began")
    if r.target_radius_m is not None:
        lines.append(
            f"its free radius at the land decision: {r.target_radius_m:.2f} m (from the walker gate, about 5 m up, "
            "the camera sees a few metres around the footprint: a lower bound, not the zone's size)"
        )
    lines.append(f"replay of the log: {'identical' if outcome.replay_identical else 'DIFFERENT'}")
    names = [outcome.top_view_path.name, outcome.video_path.name, "demo.png", "summary.json"]
    names = [name for name in names if (Path(r.run_dir) / name).exists()]
    lines.append(f"wrote {r.run_dir}: flight/, truth.jsonl, {', '.join(names)}")
    lines.append(f"look again: slz report {r.run_dir}, slz replay {r.run_dir}")
    return "\n".join(lines)


def safe(result: MissionResult, clearance_m: float = 1.5) -> bool:
    """Touched down with no person's body within ``clearance_m``."""
    return result.landed and math.isfinite(result.nearest_person_m) and result.nearest_person_m >= clearance_m
