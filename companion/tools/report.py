"""``slz report``: a flight log turned into plots, a camera video and a readable page, without the SITL.

Works on any log ``slz fly`` writes: a real flight, a field dry run or a SITL mission. Only the log is used (no
ground truth, no re-run of the model), so what is drawn is what the companion knew and decided at the time:

- ``top_view.png``: north-up, the vehicle's path (from the decision states), the geofence and the landing area (if
  one is set), the targets acted on (approached, descended over, landed on), the zones tracked when the final
  descent began (or at the land command, or the last frame), the setpoints sent (or, in a dry run, the ones it would
  have sent) and the land point;
- ``timeline.png``: altitude over time with the phases, the failsafes, and the tracked zones and the target radius;
- ``camera.mp4`` and ``camera_sheet.jpg``: the saved camera frames with the tracked zones (cyan, with ids) and the
  target (yellow) projected back into the view, captioned with the time, the altitude and the decision in force;
- ``report.md`` and ``summary.json``: the outcome, the counters, the latency and the decision timeline.

Plots need matplotlib (the ``report`` extra, also in ``sitl`` and ``dev``); the drone never needs it.
"""

from __future__ import annotations

import collections
import json
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from companion.app.mission import MissionConfig
from companion.errors import SlzError
from companion.flightlog.flight_log import DecisionRecord, FlightLog, FlightLogError, RecordKind
from companion.flightlog.timeline import flight_events
from companion.geometry import Pose
from companion.guidance.landing import CommandKind, LandingPhase
from companion.perception.pipeline import camera_from_config
from companion.perception.projection import HeadPlaneProjector
from companion.perception.selection import Target
from companion.perception.visualize import draw_circles_overlay
from companion.tools.landing_report import landing_report
from companion.tools.replay import VideoWriter, flight_config

logger = logging.getLogger(__name__)

PHASE_COLOURS = {
    "idle": "#dddddd",
    "search": "#9ecae1",
    "approach": "#fdd0a2",
    "descent": "#fdae6b",
    "land": "#74c476",
    "hold": "#fcbba1",
    "done": "#c7e9c0",
    "failsafe": "#fb6a4a",
    "yielded": "#bcbddc",
}
SHEET_FRAMES = 6


class ReportError(SlzError):
    """The flight log cannot be reported on (which file, what is missing)."""


@dataclass
class FlightReport:
    """What ``slz report`` wrote and the figures it found."""

    out_dir: Path
    files: list[Path] = field(default_factory=list)
    summary: dict[str, Any] = field(default_factory=dict)


def _phase_spans(log: FlightLog, end_s: float) -> list[tuple[float, float, str]]:
    spans: list[tuple[float, float, str]] = []
    for r in log.of(RecordKind.PHASE):
        if r["t_s"] is not None:
            if spans:
                spans[-1] = (spans[-1][0], r["t_s"], spans[-1][2])
            spans.append((r["t_s"], end_s, r["phase"]))
    return spans


def _percentile(values: Sequence[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def summarize(log: FlightLog) -> dict[str, Any]:
    """The outcome, counters, latency and the decision timeline (phase changes, failsafes, commands) of a log."""
    header = log.header
    start = log.first(RecordKind.START) or {}
    end = log.first(RecordKind.END)
    decisions = log.decisions()
    latencies = [float(r["frame_to_command_ms"]) for r in log.of(RecordKind.LATENCY)]
    land = next((d for d in decisions if d.kind is CommandKind.LAND and d.state), None)
    events = flight_events(log)
    outcome = end["outcome"] if end else None
    return {
        "version": header.version if header else None,
        "model": header.model if header else None,
        "model_sha256": header.model_sha256 if header else None,
        "mode": start.get("mode"),
        "vehicle": start.get("vehicle"),
        "camera": start.get("camera"),
        "complete": end is not None,
        "outcome": outcome,
        "frames_processed": log.count(RecordKind.FRAME_RESULT),
        "frame_errors": log.count(RecordKind.FRAME_ERROR),
        "frame_errors_by_why": dict(
            collections.Counter(str(r.get("error", "")) for r in log.of(RecordKind.FRAME_ERROR)).most_common()
        ),
        "decisions": len(decisions),
        "commands_sent": log.count(RecordKind.COMMAND),
        "land_command": None
        if land is None or land.state is None
        else {"t_s": land.t_s, "north_m": land.state.north_m, "east_m": land.state.east_m},
        "latency_ms": {
            "count": len(latencies),
            "median": _percentile(latencies, 50),
            "p95": _percentile(latencies, 95),
            "max": max(latencies) if latencies else None,
        },
        "events": events,
    }


def tracks_at_landing(log: FlightLog) -> tuple[list[dict[str, Any]], Target | None]:
    """The tracked zones when the final descent began (the last entry into descent before the land command, else
    the tracks at the land command or the last frame) and the target landed on (or the last one)."""
    tracks: list[dict[str, Any]] = []
    at_descent: list[dict[str, Any]] | None = None
    target = None
    previous_phase = ""
    for kind, record in log.tagged(RecordKind.FRAME_RESULT, RecordKind.DECISION):
        if kind is RecordKind.FRAME_RESULT:
            tracks = record["tracks"] or []
        else:
            decision = DecisionRecord.from_record(record)
            if decision.target is not None:
                target = decision.target
            if decision.phase is LandingPhase.DESCENT and previous_phase is not LandingPhase.DESCENT:
                at_descent = tracks
            previous_phase = decision.phase
            if decision.kind is CommandKind.LAND:
                break
    return (at_descent if at_descent is not None else tracks), target


def _plot_top_view(log: FlightLog, config: MissionConfig, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    decisions = log.decisions()
    fig, ax = plt.subplots(figsize=(9.5, 7.0), dpi=100)
    fence = np.asarray(config.geofence.polygon_ne_m, dtype=float)
    ax.add_patch(Polygon(fence[:, ::-1], closed=True, fill=False, edgecolor="red", lw=1.2, label="geofence"))
    if config.perception.zones.landing_area_ne_m is not None:
        area = np.asarray(config.perception.zones.landing_area_ne_m, dtype=float)
        ax.add_patch(
            Polygon(area[:, ::-1], closed=True, fill=False, edgecolor="green", lw=1.2, ls="--", label="landing area")
        )
    poses = log.of(RecordKind.POSE)  # the whole flight once a second; older logs: the states decisions saw
    states = [(r["north_m"], r["east_m"]) for r in poses] or [
        (d.state.north_m, d.state.east_m) for d in decisions if d.state
    ]
    if states:
        ne = np.array(states, dtype=float)
        ax.plot(ne[:, 1], ne[:, 0], color="0.45", lw=1.5, label="path" if poses else "path (vehicle states)")
        ax.plot(ne[0, 1], ne[0, 0], "o", color="0.2", label="start")
    setpoints = np.array([[d.setpoint.north_m, d.setpoint.east_m] for d in decisions if d.setpoint is not None])
    if len(setpoints):
        label = "setpoints " + ("sent" if log.count(RecordKind.COMMAND) else "decided (not sent)")
        ax.plot(setpoints[:, 1], setpoints[:, 0], ".", color="tab:blue", ms=3, alpha=0.5, label=label)
    for i, track in enumerate(tracks_at_landing(log)[0]):
        ax.add_patch(
            Circle(
                (track["east_m"], track["north_m"]),
                track["radius_m"],
                fill=False,
                edgecolor="tab:cyan",
                lw=1.2,
                label="zones at final descent" if i == 0 else None,
            )
        )
    targets: dict[object, Target] = {}  # each target zone where it was last chosen
    for d in decisions:  # the targets acted on: approached, descended over or landed on
        if (t := d.target) is not None and d.phase in (LandingPhase.APPROACH, LandingPhase.DESCENT, LandingPhase.LAND):
            targets[t.track_id if t.track_id is not None else (t.north_m, t.east_m)] = t
    for i, t in enumerate(targets.values()):
        ax.add_patch(
            Circle((t.east_m, t.north_m), max(t.radius_m, 0.3), fill=False, edgecolor="gold", lw=1.5,
                   label="targets acted on (last estimate)" if i == 0 else None)
        )  # fmt: skip
    land = next((d.state for d in decisions if d.kind is CommandKind.LAND and d.state), None)
    if land is not None:
        ax.plot(land.east_m, land.north_m, "x", color="green", ms=14, mew=3, label="land")
    extent = float(np.abs(fence).max()) + 3.0
    ax.set_xlim(-extent, extent)
    ax.set_ylim(-extent, extent)
    ax.set_aspect("equal")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title("Top view (north up, local NED around the EKF origin)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _plot_timeline(log: FlightLog, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    decisions = [d for d in log.decisions() if d.state]
    frames = log.of(RecordKind.FRAME_RESULT)
    times = [d.t_s for d in decisions] + [r["t_s"] for r in frames]
    if not times:
        raise ReportError("the log holds no decision and no processed frame: nothing to plot")
    t0, t1 = min(times), max(times)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9.0, 5.5), dpi=110, sharex=True, height_ratios=[2, 1])
    for a, b, phase in _phase_spans(log, t1):
        top.axvspan(a, b, color=PHASE_COLOURS.get(phase, "#eeeeee"), alpha=0.6, lw=0)
        top.text((a + b) / 2, 0.98, phase, transform=top.get_xaxis_transform(), ha="center", va="top", fontsize=8)
    top.plot([d.t_s for d in decisions], [-d.state.down_m for d in decisions if d.state], color="k", lw=1.2)
    for r in log.of(RecordKind.FAILSAFE):
        if r["t_s"] is not None:
            top.axvline(r["t_s"], color="red", ls="--", lw=1)
    top.set_ylabel("altitude (m)")
    top.set_title("Altitude and phases (failsafes dashed red)")
    top.grid(alpha=0.3)
    bottom.step([r["t_s"] for r in frames], [len(r["tracks"] or []) for r in frames], where="post", label="tracks")
    radius = [r["target"]["radius_m"] if r["target"] else math.nan for r in frames]
    bottom.plot([r["t_s"] for r in frames], radius, color="goldenrod", label="target radius (m)")
    bottom.set_xlabel("vehicle time (s)")
    bottom.set_xlim(t0, t1)
    bottom.grid(alpha=0.3)
    bottom.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def camera_views(flight_dir: Path, log: FlightLog, config: MissionConfig) -> list[tuple[float, np.ndarray, str]]:
    """Every saved frame with the logged zones and target drawn on it, and its caption."""
    camera, T_body_camera = camera_from_config(config.perception.camera)
    projector = HeadPlaneProjector(camera, T_body_camera, config.perception.projection)
    paths = {int(r["seq"]): flight_dir / str(r["path"]) for r in log.of(RecordKind.FRAME)}
    views = []
    decision = "idle"
    for kind, r in log.tagged(RecordKind.DECISION, RecordKind.FRAME_RESULT):
        if kind is RecordKind.DECISION:
            decision = f"{r['decision']['phase']}: {r['decision']['reason']}"[:60]
            continue
        if int(r["seq"]) not in paths:
            continue
        raw = cv2.imread(str(paths[int(r["seq"])]), cv2.IMREAD_COLOR)
        if raw is None:
            logger.warning("cannot read %s: skipped", paths[int(r["seq"])])
            continue
        pose = Pose(np.asarray(r["T_world_body"], dtype=np.float64))
        zones = [(t["north_m"], t["east_m"], t["radius_m"], t["track_id"]) for t in r["tracks"] or []]
        target = r["target"]
        aim = None if target is None else (target["north_m"], target["east_m"], target["radius_m"])
        image = draw_circles_overlay(np.asarray(raw, np.uint8), pose, projector, zones, aim)
        altitude = -float(pose.position_ned_m[2])
        views.append((float(r["t_s"]), image, f"t {r['t_s']:6.1f} s  alt {altitude:5.1f} m  {decision}"))
    return views


def _contact_sheet(views: list[tuple[float, np.ndarray, str]], path: Path) -> None:
    picks = np.unique(np.linspace(0, len(views) - 1, min(SHEET_FRAMES, len(views))).round().astype(int))
    tiles = []
    for i in picks:
        _, image, caption = views[i]
        tile = cv2.resize(image, (400, round(400 * image.shape[0] / image.shape[1])), interpolation=cv2.INTER_AREA)
        cv2.rectangle(tile, (0, 0), (tile.shape[1], 18), (0, 0, 0), -1)
        cv2.putText(tile, caption[:58], (4, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(tile)
    while len(tiles) % 3:
        tiles.append(np.zeros_like(tiles[0]))
    rows = [np.hstack(tiles[k : k + 3]) for k in range(0, len(tiles), 3)]
    cv2.imwrite(str(path), np.vstack(rows), [cv2.IMWRITE_JPEG_QUALITY, 85])


def _landing_lines(landing: dict[str, Any]) -> list[str]:
    """The landing report's zone (or fallback site), the ground station's commands and the nearest occupied ground,
    for the page."""
    lines = []
    zone, first = landing.get("zone"), landing.get("zone_when_descent_began") or {}
    if zone is not None:
        seen = ""
        if first.get("radius_m") is not None and first.get("seen_from_altitude_m") is not None:
            seen = (
                f"{first['radius_m']:.2f} m as seen from {first['seen_from_altitude_m']:.1f} m when the descent began, "
            )
        site = landing.get("fallback_site")
        where = f"fallback site {site}" if site is not None else f"landing zone {zone['track_id']}"
        lines.append(f"- {where}: free radius {seen}{zone['radius_m']:.2f} m at the land decision")
    for command in landing.get("ground_commands") or []:
        forced = " (forced)" if command.get("force") else ""
        when = "the end" if command.get("t_s") is None else f"{command['t_s']:.1f} s"
        why = f" ({command['reason']})" if command.get("result") in ("denied", "unsupported", "not_for_us") else ""
        lines.append(f"- ground station at {when}: {command['command']}{forced}, {command['result']}{why}")
    if landing.get("nearest_occupied_m") is not None:
        lines.append(
            f"- nearest ground the map called occupied, from the landing point: {landing['nearest_occupied_m']:.2f} m "
            "(with the map's safety dilation: a lower bound of the distance to a person)"
        )
    return lines


def _markdown(flight_dir: Path, summary: dict[str, Any], files: list[Path], out_dir: Path) -> str:
    outcome = summary["outcome"] or {}
    lat = summary["latency_ms"]
    dry = summary["mode"] == "dry_run"
    lines = [
        f"# Flight report: {flight_dir.name}",
        "",
        f"- mode: **{summary['mode']}**" + (" (decided, never commanded)" if dry else ""),
        f"- vehicle `{summary['vehicle']}`, camera `{summary['camera']}`",
        f"- slz-lander {summary['version']}, model `{summary['model']}` (sha256 {str(summary['model_sha256'])[:12]})",
        f"- ended in **{outcome.get('phase', '?')}** ({outcome.get('reason', 'no end record: the app stopped')})",
        f"- frames processed {summary['frames_processed']}, frame errors {summary['frame_errors']}, decisions "
        f"{summary['decisions']}, commands sent {summary['commands_sent']}",
    ]
    for why, count in (summary.get("frame_errors_by_why") or {}).items():
        lines.append(f"  - {count} frame error{'s' * (count != 1)}: {why}")
    if outcome.get("touchdown_ne_m"):
        n, e = outcome["touchdown_ne_m"]
        t_s = outcome["touchdown_t_s"]
        lines.append(
            f"- touchdown (the autopilot's landing detection) at north {n:.2f} m, east {e:.2f} m, t = {t_s:.1f} s"
        )
    if summary["land_command"]:
        land = summary["land_command"]
        verb = "decided" if dry else "sent"
        lines.append(
            f"- land {verb} at t = {land['t_s']:.1f} s over north {land['north_m']:.2f} m, east {land['east_m']:.2f} m"
        )
    if lat["count"]:
        lines.append(
            f"- frame to command: median {lat['median']:.1f} ms, p95 {lat['p95']:.1f} ms, max {lat['max']:.1f} ms "
            f"over {lat['count']} commands"
        )
    if outcome.get("failsafes"):
        lines.append(f"- failsafes: {', '.join(outcome['failsafes'])}")
    lines += _landing_lines(summary.get("landing_report") or {})
    lines += [""]
    for f in files:
        if f.suffix in (".png", ".jpg"):
            lines += [f"![{f.stem}]({f.relative_to(out_dir)})", ""]
        elif f.suffix == ".mp4":
            lines += [f"Camera view with zones and target: [{f.name}]({f.relative_to(out_dir)})", ""]
    lines += ["## Events", "", "| t (s) | event | reason |", "| --- | --- | --- |"]
    for ev in summary["events"]:
        t = "" if ev["t_s"] is None else f"{ev['t_s']:.1f}"
        lines.append(f"| {t} | {ev['event']} | {str(ev['reason']).replace('|', '/')} |")
    return "\n".join(lines) + "\n"


def _autopilot_section(flight: FlightLog, ulog: Path, out: Path) -> tuple[list[str], Path]:
    """The autopilot's ULog beside the flight: its picture and the merged timeline's lines (markdown)."""
    from companion.tools.autopilot_log import (
        AutopilotLogError,
        check_same_flight,
        merged_timeline,
        plot_side_by_side,
        read_autopilot_log,
    )

    try:
        log = read_autopilot_log(ulog)
        times = [r["t_s"] for r in flight.records if r.get("t_s") is not None]
        if not times:
            raise ReportError(f"{flight.path}: no timed record to line the ULog up with")
        check_same_flight(log, float(min(times)), float(max(times)))
    except AutopilotLogError as exc:
        raise ReportError(str(exc)) from None
    picture = out / "autopilot.png"
    plot_side_by_side(flight, log, picture)
    lines = [
        "## The autopilot beside the companion",
        "",
        f"`{ulog.name}` ({log.software}), on the vehicle's boot clock, the flight log's:",
        "",
        f"![autopilot]({picture.relative_to(out)})",
        "",
        "| t (s) | who | what |",
        "| --- | --- | --- |",
    ]
    t0, t1 = float(min(times)), float(max(times))
    for t, who, what in merged_timeline(flight, log):
        if t0 - 5.0 <= t <= t1 + 5.0:
            lines.append(f"| {t:.2f} | {who} | {what.replace('|', '/')} |")
    return lines, picture


def build_flight_report(
    flight_dir: Path, out_dir: Path | None = None, video: bool = True, ulog: Path | None = None
) -> FlightReport:
    """Write the report of the flight in ``flight_dir`` (its ``flight.jsonl``, and ``frames/`` when saved).

    Parameters
    ----------
    flight_dir : Path
        A folder ``slz fly`` wrote.
    out_dir : Path, optional
        Where to write (default ``flight_dir / "report"``).
    video : bool
        Also write ``camera.mp4`` (the contact sheet is written whenever frames were saved).
    ulog : Path, optional
        The autopilot's PX4 ULog of the same flight: ``autopilot.png`` and a merged timeline beside the companion's
        (:mod:`companion.tools.autopilot_log`).

    Raises
    ------
    ReportError
        No flight log, no header, or nothing to plot.
    """
    log = flight_dir / "flight.jsonl"
    if not log.is_file():
        raise ReportError(f"no flight log at {log}")
    try:
        flight = FlightLog.read(log)
    except FlightLogError as exc:
        raise ReportError(str(exc)) from None
    header = flight.header
    if header is None:
        raise ReportError(f"{log}: no header record (the config the flight ran with)")
    config = flight_config(flight, header)
    out = out_dir or flight_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    report = FlightReport(out)
    report.summary = summarize(flight)
    report.summary["landing_report"] = landing_report(flight)
    _plot_top_view(flight, config, out / "top_view.png")
    _plot_timeline(flight, out / "timeline.png")
    report.files += [out / "top_view.png", out / "timeline.png"]
    views = camera_views(flight_dir, flight, config)
    if views:
        _contact_sheet(views, out / "camera_sheet.jpg")
        report.files.append(out / "camera_sheet.jpg")
        if video:
            gaps = np.diff([t for t, _, _ in views])
            rate_hz = 1.0 / float(np.median(gaps)) if len(gaps) and np.median(gaps) > 0 else 10.0
            writer = VideoWriter(out / "camera.mp4", rate_hz)
            try:
                for _, image, caption in views:
                    writer.add(image, caption)
            finally:
                writer.close()
            report.files.append(out / "camera.mp4")
    report.summary["camera_frames"] = len(views)
    autopilot_lines: list[str] = []
    if ulog is not None:
        autopilot_lines, picture = _autopilot_section(flight, ulog, out)
        report.files.append(picture)
        report.summary["ulog"] = str(ulog)
    (out / "summary.json").write_text(json.dumps(report.summary, indent=1) + "\n")
    page = _markdown(flight_dir, report.summary, [f for f in report.files if f.name != "autopilot.png"], out)
    (out / "report.md").write_text(page + ("\n" + "\n".join(autopilot_lines) + "\n" if autopilot_lines else ""))
    report.files += [out / "summary.json", out / "report.md"]
    return report
