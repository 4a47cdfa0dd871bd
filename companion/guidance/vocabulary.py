"""What a landing decision did and why, as data: the words campaign metrics, hold explanations and reports read.

Every :class:`~companion.guidance.landing.Decision` carries its :class:`DecisionEvent` (what it did), the
:class:`RefusalCause` of a landing point or zone it gave up (or waited on), and the :class:`ZoneChange` events of the
zone commitment in that frame. Its ``reason`` text is for people and may be reworded freely; nothing that counts reads
it (a test rewords every reason and checks that no metric moves). Flight logs written before these fields existed are
read through :func:`companion.flightlog.legacy_decisions.vocabulary_of`, the one place that still matches texts.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class DecisionEvent(str, enum.Enum):
    """What one decision did."""

    MISSION_START = "mission_start"
    """The mission started: search from where the vehicle is."""
    HOLD_NO_TARGET = "hold_no_target"
    """Searching, no target yet: hold position (before the search pattern's timeout)."""
    SEARCH_PATTERN = "search_pattern"
    """Searching, no target for the search timeout: fly the expanding square."""
    CLIMB_BACK = "climb_back"
    """After an aborted descent, climbing back before choosing again."""
    APPROACH = "approach"
    """Flying towards the committed zone."""
    DESCEND = "descend"
    """Descending over the locked landing point."""
    WAIT_AT_GATE = "wait_at_gate"
    """Held at the walker gate: watching, waiting out a walker or a person in the footprint."""
    LAND = "land"
    """The landing command."""
    ABORT = "abort"
    """A descent refused its landing point: climb back and re-select (``cause`` says why)."""
    RESELECTIONS_USED_UP = "reselections_used_up"
    """A descent refused its point with no re-selection left: the last resort (``cause``: the last refusal's)."""
    TIME_LIMIT = "time_limit"
    """The mission time limit came without a landing: the last resort."""
    ENERGY_LOW = "energy_low"
    """The energy budget no longer covers getting home and down: its action (return or hold)."""
    LIMIT = "limit"
    """A limit of the program (its wall limit, a stop) ended the mission: the last resort."""
    PERCEPTION_HOLD = "perception_hold"
    """No processed frame for T1: hold."""
    PERCEPTION_FAILSAFE = "perception_failsafe"
    """No processed frame for T2: the failsafe action."""
    LANDED = "landed"
    """The autopilot reported the vehicle on the ground."""
    PILOT_TOOK_OVER = "pilot_took_over"
    """The flight mode left offboard without the companion: yield."""
    FRAME_IGNORED = "frame_ignored"
    """A frame in a phase that takes none."""
    TRANSIT = "transit"
    """Flying to the search area before the mission starts."""
    FALLBACK_SITE = "fallback_site"
    """The search's budget ended (or the site before was given up): fly to a fallback site and check it there."""
    OPERATOR_GO_AROUND = "operator_go_around"
    """The ground station's go-around: climb back and search again."""
    OPERATOR_REJECT = "operator_reject"
    """The ground station rejected the zone flown to (``cause``: operator): choose another."""
    OPERATOR_LAND = "operator_land"
    """The ground station's land-now: the landing command at once."""


class DecisionSource(str, enum.Enum):
    """What made the landing logic decide: the stimulus a ``decision`` record names (``source``) and replay hands back
    to the same entry point."""

    START = "start"
    """The mission started (the start sequence's last step)."""
    FRAME = "frame"
    """A perceived camera frame (its ``seq`` in the inputs)."""
    SILENCE = "silence"
    """No perceived frame for a while (``silent_s``)."""
    LANDED = "landed"
    """The vehicle reported itself on the ground in the landing phase."""
    TIME = "time"
    """The mission's time limit."""
    ENERGY = "energy"
    """The battery no longer covers the way home and down (``reason``, ``reach_m``)."""
    TAKEOVER = "takeover"
    """The pilot took the vehicle (``mode``)."""
    LIMIT = "limit"
    """The wall limit of ``slz fly --timeout`` (``reason``)."""
    STOP = "stop"
    """A stop asked of the program: SIGINT, SIGTERM (``reason``)."""
    OPERATOR = "operator"
    """An accepted ground-station command (``command``, ``person_seen``, ``force``)."""


class OperatorCommand(str, enum.Enum):
    """A landing command from the ground station (its MAVLink numbers: :mod:`companion.ground.operator_commands`)."""

    GO_AROUND = "go_around"
    """Climb back and search again."""
    REJECT_ZONE = "reject_zone"
    """Refuse the zone flown to; choose another."""
    LAND_NOW = "land_now"
    """Land on the current target now."""
    NEXT_FALLBACK = "next_fallback"
    """Go to the next fallback site."""


class RefusalCause(str, enum.Enum):
    """Why a landing point or a committed zone was given up (or, at the walker gate, waited on)."""

    PERSON_IN_FOOTPRINT = "person_in_footprint"
    """A person seen inside the footprint around it."""
    PERSON_AT_GATE = "person_at_gate"
    """A person seen inside the footprint for the walker gate's whole wait limit."""
    WALKER_KEPT_COMING = "walker_kept_coming"
    """Someone kept walking towards the footprint for the walker gate's wait limit."""
    ZONE_SHRANK = "zone_shrank"
    """The zone became narrower than the smallest a landing needs."""
    NO_FREE_MAP = "no_free_map"
    """No recent map saw the whole footprint free when the landing was due."""
    ZONE_LOST = "zone_lost"
    """The committed zone was not seen for the commitment's lost time."""
    LEFT_GEOFENCE = "left_geofence"
    """The committed zone's footprint left the geofence."""
    SITE_TIMED_OUT = "site_timed_out"
    """A fallback site not landed on within its time."""
    OPERATOR = "operator"
    """The ground station rejected it (or sent a go-around)."""


class ZoneChange(str, enum.Enum):
    """A change of the zone commitment (:mod:`companion.guidance.commitment`)."""

    COMMIT = "commit"
    """Committed to a zone (nothing was committed)."""
    SWITCH = "switch"
    """Switched to a rival that stayed clearly better."""
    RELEASE = "release"
    """Released the committed zone (its ``cause`` says why)."""
    REACQUIRE = "reacquire"
    """The committed zone, lost by the tracker, seen again under another track."""


@dataclass(frozen=True)
class CommitmentEvent:
    """One change of the zone commitment in a frame: what changed, why (a release's cause), and the words."""

    change: ZoneChange
    cause: RefusalCause | None
    text: str


ZONE_CHOICES = (ZoneChange.COMMIT, ZoneChange.SWITCH)
"""The changes that choose a landing zone (a campaign's ``zones_chosen`` counts them)."""
