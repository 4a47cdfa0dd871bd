"""The landing report an operator files: one JSON document per flight, beside its flight log.

``slz fly`` writes ``landing_report.json`` when a flight ends, and ``slz report`` summarises it (and writes it for a
log that has none): how the flight ended, where it landed or was to land (the land decision's point and the touchdown
the autopilot reported), when, the zone (its id, and its free radius when the descent began and at the land decision),
the nearest ground the map called occupied around the landing point in the last map that decided (taken at or above
``guidance.perception_min_altitude_m``; a person, or a false positive, with the map's safety dilation: a lower bound of
the distance to a body), the fallback site it landed at when it was one (issue 53: by name), the ground station's
commands and their answers, and the decisions on the way (phase changes, switches of target, failsafes, with their
reasons). Everything comes from the flight log: a report of an older log simply lacks
what that log did not record (``null``).
"""

from __future__ import annotations

import enum
import json
import logging
import os
from pathlib import Path
from typing import Any

from companion.app.mission import OperatingMode
from companion.flightlog.flight_log import FlightLog, FlightLogError, RecordKind
from companion.flightlog.timeline import flight_events
from companion.guidance.landing import ENDING_KINDS, CommandKind, LandingPhase
from companion.guidance.vocabulary import DecisionEvent, DecisionSource
from companion.json_value import JsonObject

logger = logging.getLogger(__name__)

REPORT_NAME = "landing_report.json"
VERSION = 3  # 2: fallback_site, ground_commands; 3: outcome, outcome_says, warning_device


class FlightEnding(str, enum.Enum):
    """How a flight ended, named (the landing report's ``outcome``, ``slz fly``'s last line)."""

    LANDED = "landed"
    """On the ground after the companion's own landing."""
    LANDED_BY_FAILSAFE = "landed_by_failsafe"
    """On the ground after a failsafe or last resort the companion commanded (perception silent, its time up)."""
    RETURNED = "returned"
    """A return home was commanded (the last resort, an energy budget): the autopilot flies it."""
    HELD = "held"
    """A hold was commanded (a failsafe, the last resort): the vehicle hovers for the pilot."""
    LINK_LOST = "link_lost"
    """The vehicle's telemetry stopped: the companion stopped commanding and the autopilot's own failsafe acts."""
    STOPPED = "stopped"
    """The program was stopped (Ctrl-C, the service stopped): the last resort went out first where it flew."""
    PILOT_TOOK_OVER = "pilot_took_over"
    """The pilot switched the flight mode: the companion yielded at once."""
    CRASHED = "crashed"
    """The program ended without its end record (an error, a kill): the log says how far it got."""
    DRY_RUN = "dry_run"
    """A dry run: the pilot flew; the companion watched and decided."""
    NOTHING_FLOWN = "nothing_flown"
    """The run ended before the mission started (no vehicle, no camera, a wait for the pilot's handover)."""


ENDING_WORDS = {
    FlightEnding.LANDED: "landed",
    FlightEnding.LANDED_BY_FAILSAFE: "landed by a failsafe",
    FlightEnding.RETURNED: "returning home (the autopilot's)",
    FlightEnding.HELD: "held for the pilot",
    FlightEnding.LINK_LOST: "link lost (the autopilot's failsafe acts)",
    FlightEnding.STOPPED: "stopped",
    FlightEnding.PILOT_TOOK_OVER: "the pilot took over",
    FlightEnding.CRASHED: "crashed (no end record)",
    FlightEnding.DRY_RUN: "dry run over",
    FlightEnding.NOTHING_FLOWN: "nothing flown",
}


def flight_ending(log: FlightLog) -> FlightEnding:
    """How the flight of ``log`` ended, from its records (the end record's outcome, the decisions and their
    sources, the supervision records), in this order: no end record, a lost link, a dry run, the pilot, a stop, a
    touchdown, the last command."""
    end = log.last(RecordKind.END)
    if end is None:
        return FlightEnding.CRASHED
    outcome = end["outcome"]
    if outcome.get("link_lost"):
        return FlightEnding.LINK_LOST
    header = log.header
    if header is not None and header.mode == OperatingMode.DRY_RUN:
        return FlightEnding.DRY_RUN
    decisions = log.decisions()
    supervision = [str(r.get("event")) for r in log.of(RecordKind.SUPERVISION)]
    if (
        outcome.get("phase") == LandingPhase.YIELDED
        or "pilot_has_it" in supervision
        or any(d.event is DecisionEvent.PILOT_TOOK_OVER for d in decisions)
    ):
        return FlightEnding.PILOT_TOOK_OVER
    if any(d.source is DecisionSource.STOP for d in decisions) or "stopped" in supervision:
        return FlightEnding.STOPPED
    active = [d for d in decisions if d.kind in ENDING_KINDS]
    last = active[-1] if active else None
    if outcome.get("touchdown_ne_m"):
        if (
            outcome.get("phase") == LandingPhase.DONE
            and last is not None
            and last.kind is CommandKind.LAND
            and last.phase is LandingPhase.LAND
        ):
            return FlightEnding.LANDED
        return (
            FlightEnding.RETURNED
            if last is not None and last.kind is CommandKind.RETURN
            else FlightEnding.LANDED_BY_FAILSAFE
        )
    if last is None:
        return FlightEnding.NOTHING_FLOWN
    if last.kind is CommandKind.RETURN:
        return FlightEnding.RETURNED
    if last.kind is CommandKind.LAND:  # commanded, not seen down: the failsafe's or the companion's landing
        return FlightEnding.LANDED_BY_FAILSAFE if last.phase is LandingPhase.FAILSAFE else FlightEnding.LANDED
    return FlightEnding.HELD


def _zone(target: dict[str, Any] | None) -> JsonObject | None:
    if target is None:
        return None
    return {
        "track_id": target.get("track_id"),
        "north_m": target["north_m"],
        "east_m": target["east_m"],
        "radius_m": target["radius_m"],
    }


def _fallback_site(log: FlightLog, config: dict[str, Any], target: dict[str, Any] | None) -> str | None:
    """The name of the fallback site ``target`` is (a site's target has track id ``-1 - index`` among the flight's
    sites: its ``fallback_sites`` record, else its config's), None for a zone."""
    track_id = None if target is None else target.get("track_id")
    if not isinstance(track_id, int) or track_id >= 0:
        return None
    record = log.first(RecordKind.FALLBACK_SITES)
    sites = record["sites"] if record else config.get("guidance", {}).get("fallback", {}).get("sites") or []
    index = -1 - track_id
    return str(sites[index]["name"]) if index < len(sites) else None


def landing_report(log: FlightLog) -> dict[str, Any]:
    """The flight's landing report (see the module docstring), a JSON-able mapping."""
    header = log.header
    end = log.first(RecordKind.END)
    outcome = end["outcome"] if end else {}
    records = log.of(RecordKind.DECISION)
    land_index = next(
        (i for i in range(len(records) - 1, -1, -1) if records[i]["decision"]["kind"] == CommandKind.LAND), None
    )
    land = records[land_index] if land_index is not None else None
    descent = None  # the decision that began the last descent before the landing (or before the end)
    last = land_index if land_index is not None else len(records) - 1
    for i in range(last, -1, -1):
        if records[i]["decision"]["phase"] == LandingPhase.DESCENT and (
            i == 0 or records[i - 1]["decision"]["phase"] != LandingPhase.DESCENT
        ):
            descent = records[i]
            break
    observed = None  # the nearest occupied ground seen around the landing point, by the last frame that decided
    for record in records[: (land_index + 1) if land_index is not None else len(records)]:
        if record.get("observed") and record["source"] == DecisionSource.FRAME:
            observed = record["observed"]
    config = header.config if header is not None else {}
    mode = header.mode if header is not None else None
    ending = flight_ending(log)
    return {
        "version": VERSION,
        "outcome": ending.value,
        "outcome_says": ENDING_WORDS[ending],
        "mode": mode,
        "software": header.version if header is not None else None,
        "model": header.model if header is not None else None,
        "model_sha256": header.model_sha256 if header is not None else None,
        "ended_in": outcome.get("phase"),
        "reason": outcome.get("reason"),
        "failsafes": outcome.get("failsafes", []),
        "land_decided": None
        if land is None
        else {
            "t_s": land["t_s"],
            "north_m": land["state"]["north_m"] if land.get("state") else None,
            "east_m": land["state"]["east_m"] if land.get("state") else None,
            "sent": mode != OperatingMode.DRY_RUN,
        },
        "touchdown": None
        if not outcome.get("touchdown_ne_m")
        else {
            "t_s": outcome.get("touchdown_t_s"),
            "north_m": outcome["touchdown_ne_m"][0],
            "east_m": outcome["touchdown_ne_m"][1],
            "by": "the autopilot's landing detection",
        },
        "zone": _zone(land["decision"].get("target") if land else None),
        "fallback_site": _fallback_site(log, config, land["decision"].get("target") if land else None),
        "zone_when_descent_began": None
        if descent is None
        else {
            "t_s": descent["t_s"],
            **(_zone(descent["decision"].get("target")) or {}),
            "seen_from_altitude_m": -descent["state"]["down_m"] if descent.get("state") else None,
        },
        "nearest_occupied_m": None if observed is None else observed.get("nearest_occupied_m"),
        "warning_device": [
            {k: r.get(k) for k in ("t_s", "on", "sent", "event", "actuator")} for r in log.of(RecordKind.WARNING)
        ],
        "ground_commands": [
            {k: r.get(k) for k in ("t_s", "command", "result", "reason", "force", "signed")}
            for r in log.of(RecordKind.GROUND_COMMAND)
        ],
        "decisions": flight_events(log),
    }


def write_landing_report(flight_dir: Path) -> Path | None:
    """Write ``landing_report.json`` beside the flight log in ``flight_dir`` (flushed and fsync'd); None, logged, when
    the log cannot be read (the flight itself is not affected)."""
    try:
        report = landing_report(FlightLog.read(flight_dir))
    except (FlightLogError, KeyError, TypeError, ValueError) as exc:
        logger.error("no landing report for %s: %s", flight_dir, exc)
        return None
    path = flight_dir / REPORT_NAME
    with path.open("w", encoding="utf-8") as f:
        json.dump(report, f, indent=2)
        f.write("\n")
        f.flush()
        os.fsync(f.fileno())
    return path
