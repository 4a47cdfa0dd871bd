"""The one reader of decision *texts*: what a decision did and why, for flight logs written before decisions carried
it as data (:mod:`companion.guidance.vocabulary`).

A log written since records ``event``, ``cause`` and ``zone_changes`` with every decision, and nothing reads its
``reason`` to count. Older logs (campaign results kept for comparison, recorded flights replayed) have only the
words; :func:`vocabulary_of` maps the words every version of the state machine wrote to the same data, so their
metrics are what they were. It is frozen with those texts: a reworded reason is never read here, since a new log
carries its data.
"""

from __future__ import annotations

from companion.guidance.vocabulary import CommitmentEvent, DecisionEvent, RefusalCause, ZoneChange

CLIMBING_BACK = "climbing back to"
WAITING_AT_GATE = "wait at"
ABORTED = ": climb back and re-select"
USED_UP = " re-selections used up"


def refusal_cause(text: str) -> RefusalCause | None:
    """The cause in the words of an aborted descent or of a release (None: not one these words name)."""
    if "at the gate for" in text:
        return RefusalCause.PERSON_AT_GATE
    if "kept walking towards the footprint" in text:
        return RefusalCause.WALKER_KEPT_COMING
    if "person seen inside" in text:
        return RefusalCause.PERSON_IN_FOOTPRINT
    if "shrank" in text:
        return RefusalCause.ZONE_SHRANK
    if "no map saw the footprint free" in text:
        return RefusalCause.NO_FREE_MAP
    if "not seen for" in text:
        return RefusalCause.ZONE_LOST
    if "left the geofence" in text:
        return RefusalCause.LEFT_GEOFENCE
    return None


def zone_changes_of(reason: str) -> tuple[CommitmentEvent, ...]:
    """The commitment's changes a reason reports (its parts between ``; ``, as the state machine joined them)."""
    changes = []
    for part in reason.split("; "):
        if part.startswith("committed to zone"):
            changes.append(CommitmentEvent(ZoneChange.COMMIT, None, part))
        elif part.startswith("switched from zone"):
            changes.append(CommitmentEvent(ZoneChange.SWITCH, None, part))
        elif part.startswith("released: "):
            changes.append(CommitmentEvent(ZoneChange.RELEASE, refusal_cause(part), part))
        elif " seen again as zone " in part:
            changes.append(CommitmentEvent(ZoneChange.REACQUIRE, None, part))
    return tuple(changes)


def vocabulary_of(
    reason: str, phase: str
) -> tuple[DecisionEvent | None, RefusalCause | None, tuple[CommitmentEvent, ...]]:
    """What a logged decision did (None: words no version wrote), the cause it names and the commitment's changes,
    from its ``reason`` and ``phase``."""
    cause: RefusalCause | None = None
    changes = zone_changes_of(reason)  # wherever the words report them, as every earlier reader counted them
    event: DecisionEvent | None = None
    if USED_UP in reason:
        event, cause = DecisionEvent.RESELECTIONS_USED_UP, refusal_cause(reason)
    elif ABORTED in reason:
        event, cause = DecisionEvent.ABORT, refusal_cause(reason)
    elif reason == "mission start":
        event = DecisionEvent.MISSION_START
    elif reason.startswith("no target yet: hold"):
        event = DecisionEvent.HOLD_NO_TARGET
    elif reason.startswith("no target: search pattern"):
        event = DecisionEvent.SEARCH_PATTERN
    elif reason.startswith(CLIMBING_BACK):
        event = DecisionEvent.CLIMB_BACK
    elif reason.startswith("approach target"):
        event = DecisionEvent.APPROACH
    elif reason.startswith(WAITING_AT_GATE):
        event = DecisionEvent.WAIT_AT_GATE
        if ": a person seen inside the footprint" in reason:
            cause = RefusalCause.PERSON_IN_FOOTPRINT
        elif ": the zone shrank" in reason:
            cause = RefusalCause.ZONE_SHRANK
    elif reason.startswith("descend over zone"):
        event = DecisionEvent.DESCEND
    elif reason.startswith("land on zone"):
        event = DecisionEvent.LAND
    elif reason.startswith("no landing within"):
        event = DecisionEvent.TIME_LIMIT
    elif reason.startswith("perception silent"):
        event = DecisionEvent.PERCEPTION_HOLD if phase == "hold" else DecisionEvent.PERCEPTION_FAILSAFE
    elif reason == "landed":
        event = DecisionEvent.LANDED
    elif reason.startswith("pilot took over"):
        event = DecisionEvent.PILOT_TOOK_OVER
    elif reason.startswith("frame ignored in"):
        event = DecisionEvent.FRAME_IGNORED
    elif reason == "transit":
        event = DecisionEvent.TRANSIT
    elif phase == "failsafe":
        event = DecisionEvent.LIMIT  # the program's limits: its wall limit, a stop
    return event, cause, changes
