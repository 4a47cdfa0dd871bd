"""The autopilot's own log (a PX4 ULog: a real drone's SD card, or the SITL's ``flight.ulg``) lined up with the
companion's flight log, for ``slz report FLIGHT --ulog FILE``: what the autopilot did beside what the companion
decided, on one clock.

PX4 stamps its ULog in microseconds since boot, the clock MAVLink's ``time_boot_ms`` counts; the companion's flight
log keeps its ``t_s`` in that clock (seconds), so the two line up without an offset. A ULog of another flight or
another boot does not overlap the flight log's time span, and is refused. Read with pyulog (the ``report`` extra).
Topics read: ``vehicle_status`` (``nav_state``, ``arming_state``, ``failsafe``), ``vehicle_local_position`` (``z``,
NED), ``vehicle_command_ack`` and the logged strings; each is optional but the status.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from companion.errors import SlzError
from companion.geometry import F64Array

if TYPE_CHECKING:
    from companion.flightlog.flight_log import FlightLog

# PX4's vehicle_status.nav_state values and the names the companion's log uses for the flight modes.
NAV_STATE_NAMES = {
    0: "MANUAL",
    1: "ALTCTL",
    2: "POSCTL",
    3: "AUTO.MISSION",
    4: "AUTO.LOITER",
    5: "AUTO.RTL",
    6: "POSITION_SLOW",
    10: "ACRO",
    12: "DESCEND",
    13: "TERMINATION",
    14: "OFFBOARD",
    15: "STABILIZED",
    17: "AUTO.TAKEOFF",
    18: "AUTO.LAND",
    19: "AUTO.FOLLOW_TARGET",
    20: "AUTO.PRECLAND",
    21: "ORBIT",
    22: "AUTO.VTOL_TAKEOFF",
}
COMMAND_NAMES = {
    16: "waypoint",
    20: "return",
    21: "land",
    22: "takeoff",
    176: "set mode",
    178: "change speed",
    187: "actuator",
    192: "reposition",
    400: "arm/disarm",
    511: "message interval",
    512: "request message",
}
ACK_RESULTS = {0: "accepted", 1: "temporarily rejected", 2: "denied", 3: "unsupported", 4: "failed", 5: "in progress"}
LEVELS = {0: "emergency", 1: "alert", 2: "critical", 3: "error", 4: "warning", 5: "notice", 6: "info", 7: "debug"}


class AutopilotLogError(SlzError):
    """The autopilot's log could not be read or does not belong with the flight: the file and why."""

    def __init__(self, path: Path, why: str) -> None:
        self.path = path
        self.why = why
        super().__init__(f"{path}: {why}")


@dataclass
class AutopilotLog:
    """What the report draws of a ULog: the mode changes, the failsafe flag's, the altitude, commands and messages.

    Times are seconds of the vehicle's boot clock (the flight log's ``t_s``).
    """

    path: Path
    software: str
    modes: list[tuple[float, str]] = field(default_factory=list)
    """Each change of ``nav_state`` (and the first): (t_s, mode name)."""
    failsafes: list[tuple[float, bool]] = field(default_factory=list)
    """Each change of the failsafe flag: (t_s, on)."""
    armed: list[tuple[float, bool]] = field(default_factory=list)
    """Each change of arming: (t_s, armed)."""
    altitude_t_s: F64Array = field(default_factory=lambda: np.zeros(0))
    altitude_m: F64Array = field(default_factory=lambda: np.zeros(0))
    """Height above the local origin (-z of ``vehicle_local_position``), m."""
    commands: list[tuple[float, str, str]] = field(default_factory=list)
    """(t_s, command, result) for each acknowledged command."""
    messages: list[tuple[float, str, str]] = field(default_factory=list)
    """(t_s, level, text) of each logged string."""

    @property
    def span_s(self) -> tuple[float, float]:
        """The first and last instant the status covers."""
        return self.modes[0][0], self.last_s

    last_s: float = 0.0


def _changes(t_s: np.ndarray, values: np.ndarray) -> list[tuple[float, Any]]:
    out: list[tuple[float, Any]] = []
    for t, v in zip(t_s.tolist(), values.tolist(), strict=True):
        if not out or out[-1][1] != v:
            out.append((float(t), v))
    return out


def read_autopilot_log(path: Path) -> AutopilotLog:
    """Read the parts of a PX4 ULog the report draws.

    Raises
    ------
    AutopilotLogError
        pyulog is not installed, the file is not a ULog, or it has no ``vehicle_status``.
    """
    try:
        from pyulog import ULog
    except ImportError:
        raise AutopilotLogError(path, "reading a ULog needs pyulog: pip install 'slz-lander[report]'") from None
    if not path.is_file():
        raise AutopilotLogError(path, "no such file")
    try:
        ulog = ULog(str(path))
    except Exception as exc:  # pyulog raises plain exceptions of several kinds on a damaged file
        raise AutopilotLogError(path, f"not a readable ULog ({type(exc).__name__}: {exc})") from None
    datasets = {d.name: d.data for d in ulog.data_list if d.multi_id == 0}
    status = datasets.get("vehicle_status")
    if status is None or len(status["timestamp"]) == 0:
        raise AutopilotLogError(path, "no vehicle_status topic: not a flight log of a PX4 autopilot")
    t_s = status["timestamp"].astype(np.float64) / 1e6
    software = str(ulog.msg_info_dict.get("ver_sw_release", "?"))
    log = AutopilotLog(path, software)
    log.modes = [(t, NAV_STATE_NAMES.get(int(v), f"nav_state {v}")) for t, v in _changes(t_s, status["nav_state"])]
    if "failsafe" in status:
        log.failsafes = [(t, bool(v)) for t, v in _changes(t_s, status["failsafe"])]
    if "arming_state" in status:
        log.armed = [(t, int(v) == 2) for t, v in _changes(t_s, status["arming_state"])]
    log.last_s = float(t_s[-1])
    position = datasets.get("vehicle_local_position")
    if position is not None:
        log.altitude_t_s = position["timestamp"].astype(np.float64) / 1e6
        log.altitude_m = -position["z"].astype(np.float64)
    acks = datasets.get("vehicle_command_ack")
    if acks is not None:
        for t, command, result in zip(acks["timestamp"], acks["command"], acks["result"], strict=True):
            name = COMMAND_NAMES.get(int(command), f"command {int(command)}")
            log.commands.append((float(t) / 1e6, name, ACK_RESULTS.get(int(result), f"result {int(result)}")))
    for m in ulog.logged_messages:
        raw = int(m.log_level)  # an ASCII digit in the file ('0' emergency ... '7' debug), as PX4 writes it
        level = LEVELS.get(raw - ord("0"), LEVELS.get(raw, str(raw)))
        log.messages.append((float(m.timestamp) / 1e6, level, str(m.message)))
    return log


def check_same_flight(log: AutopilotLog, flight_t0_s: float, flight_t1_s: float) -> None:
    """Refuse a ULog whose time span does not overlap the flight log's (another flight, another boot)."""
    a0, a1 = log.span_s
    if a1 < flight_t0_s or a0 > flight_t1_s:
        raise AutopilotLogError(
            log.path,
            f"its time ({a0:.1f}-{a1:.1f} s since boot) does not overlap the flight log's ({flight_t0_s:.1f}-"
            f"{flight_t1_s:.1f} s): the log of another flight or another boot",
        )


def merged_timeline(flight: FlightLog, log: AutopilotLog) -> list[tuple[float, str, str]]:
    """The companion's decisions, failsafes and commands and the autopilot's mode changes, failsafe flag,
    acknowledged commands and its warnings (and worse), in time order: (t_s, who, what)."""
    from companion.flightlog.flight_log import RecordKind
    from companion.guidance.landing import ENDING_KINDS

    rows: list[tuple[float, str, str]] = []
    previous = None
    for d in flight.decisions():  # each change of what the decisions do (a setpoint every tick is not news)
        what = d.event.value if d.event is not None else d.phase.value
        if what != previous or d.kind in ENDING_KINDS:
            rows.append((d.t_s, "companion", f"{what}: {d.reason}" if d.reason else what))
        previous = what
    for r in flight.of(RecordKind.COMMAND):
        if r["command"] != "setpoint":  # one every tick: the decisions above say what they did
            rows.append((float(r["t_s"]), "companion", f"sent {r['command']}"))
    for r in flight.of(RecordKind.FAILSAFE):
        if r.get("t_s") is not None:
            rows.append((float(r["t_s"]), "companion", f"failsafe: {r.get('reason', '')}"))
    for t, mode in log.modes:
        rows.append((t, "autopilot", f"mode {mode}"))
    for t, on in log.failsafes[1:] if log.failsafes and not log.failsafes[0][1] else log.failsafes:
        rows.append((t, "autopilot", "failsafe on" if on else "failsafe off"))
    for t, name, result in log.commands:
        if name not in ("message interval", "request message"):
            rows.append((t, "autopilot", f"{name}: {result}"))
    for t, level, text in log.messages:
        if level in ("emergency", "alert", "critical", "error", "warning"):
            rows.append((t, "autopilot", f"{level}: {text}"))
    rows.sort(key=lambda row: (row[0], row[1]))
    return rows


def plot_side_by_side(flight: FlightLog, log: AutopilotLog, path: Path) -> None:
    """Altitude from both logs over the autopilot's modes, and each side's events below, on the boot clock."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    decisions = [d for d in flight.decisions() if d.state]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10.0, 7.0), dpi=110, sharex=True, height_ratios=[3, 2])
    ends = [t for t, _ in log.modes[1:]] + [log.last_s]
    palette = plt.get_cmap("tab20")
    names = sorted({m for _, m in log.modes})
    for (start, mode), end in zip(log.modes, ends, strict=True):
        top.axvspan(start, end, color=palette(names.index(mode) % 20), alpha=0.25, lw=0)
        top.text((start + end) / 2, 0.98, mode, transform=top.get_xaxis_transform(), ha="center", va="top", fontsize=7)
    if len(log.altitude_t_s):
        top.plot(log.altitude_t_s, log.altitude_m, color="k", lw=1.0, label="autopilot (ULog)")
    top.plot(
        [d.t_s for d in decisions],
        [-d.state.down_m for d in decisions if d.state],
        ".",
        color="tab:orange",
        ms=3,
        label="companion (its decisions)",
    )
    for t, on in log.failsafes:
        if on:
            top.axvline(t, color="red", ls="--", lw=1)
    top.set_ylabel("altitude (m)")
    top.set_title(f"The autopilot ({log.software}) beside the companion: modes, altitude (failsafes dashed red)")
    top.grid(alpha=0.3)
    top.legend(loc="lower left", fontsize=8)
    rows = merged_timeline(flight, log)
    for k, (t, who, what) in enumerate(rows):
        y = 1.0 if who == "companion" else 0.0
        colour = "tab:orange" if who == "companion" else "k"
        bottom.plot([t], [y], "|", color=colour, ms=12)
        if len(rows) <= 60:  # labelled while they can be read
            bottom.text(
                t,
                y + (0.12 if k % 2 else -0.12),
                what.split(":")[0][:24],
                rotation=90,
                fontsize=6,
                color=colour,
                ha="center",
                va="bottom" if k % 2 else "top",
            )
    bottom.set_yticks([0.0, 1.0], ["autopilot", "companion"])
    bottom.set_ylim(-1.5, 2.5)
    bottom.set_xlabel("vehicle time since boot (s)")
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
