"""A flight's timeline from its log: the events a person reads (phase changes, switches of target, failsafes, errors,
waits, the start and the supervision after a failsafe), each with its vehicle time and reason. ``slz report`` lists
them, and the landing report files them."""

from __future__ import annotations

from companion.flightlog.flight_log import FlightLog, RecordKind
from companion.guidance.landing import LandingPhase
from companion.json_value import JsonObject


def flight_events(log: FlightLog) -> list[JsonObject]:
    """The timeline of ``log``: ``{"t_s", "event", "reason"}`` in log order. A switch of target is a decision whose
    target zone differs from the last one decided on (a return to the search without one starts afresh)."""
    events: list[JsonObject] = []
    starting = (RecordKind.HANDOVER, RecordKind.TAKEOFF, RecordKind.WAITING_FOR_HANDOVER)
    kinds = (RecordKind.PHASE, RecordKind.FAILSAFE, RecordKind.ERROR, RecordKind.DECISION, RecordKind.SUPERVISION)
    target_id: object = None  # the zone decided on last: a change of it is a switch, with the decision's reason
    for kind, r in log.tagged(*kinds, RecordKind.WAITING, *starting):
        if kind is RecordKind.PHASE:
            events.append({"t_s": r["t_s"], "event": f"phase {r['previous']} -> {r['phase']}", "reason": r["reason"]})
        elif kind is RecordKind.FAILSAFE:
            # A lost link's record names no command of ours (logs before its action field): the autopilot acts.
            action = r.get("action", "autopilot")
            events.append({"t_s": r["t_s"], "event": f"failsafe ({action})", "reason": r["reason"]})
        elif kind is RecordKind.ERROR:
            events.append({"t_s": r["t_s"], "event": f"error in {r['where']}", "reason": r["error"]})
        elif kind is RecordKind.DECISION:
            target = r["decision"].get("target")
            if target is not None and target.get("track_id") != target_id:
                was = "none" if target_id is None else f"zone {target_id}"
                event = f"target {was} -> zone {target.get('track_id')} (r = {float(target['radius_m']):.2f} m)"
                events.append({"t_s": r["t_s"], "event": event, "reason": r["decision"].get("reason", "")})
                target_id = target.get("track_id")
            elif r["decision"]["phase"] == LandingPhase.SEARCH and target is None and target_id is not None:
                target_id = None  # back to searching: the next zone is a new choice, not a switch
        elif kind is RecordKind.SUPERVISION:
            events.append({"t_s": r["t_s"], "event": f"supervision: {r['event']}", "reason": r["reason"]})
        elif kind is RecordKind.WAITING:
            events.append({"t_s": r["t_s"], "event": "waiting", "reason": f"for {r['waiting_for']}"})
        else:
            events.append({"t_s": r["t_s"], "event": kind.value.replace("_", " "), "reason": ""})
    return events
