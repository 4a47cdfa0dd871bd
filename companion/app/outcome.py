"""How a flight ended: :class:`FlightOutcome`, filled in by the flight and its parts as it goes, recorded at its end."""

from __future__ import annotations

from dataclasses import dataclass, field

from companion.guidance.landing import LandingPhase


@dataclass
class FlightOutcome:
    """How a flight ended."""

    phase: str = LandingPhase.IDLE.value
    reason: str = ""
    touchdown_ne_m: tuple[float, float] | None = None
    touchdown_t_s: float | None = None
    ticks: int = 0
    lockstep: bool = False
    frames_processed: int = 0
    frames_before_start: int = 0
    frames_dropped_old: int = 0
    frames_dropped_no_pose: int = 0
    frames_missing: int = 0
    frames_failed: int = 0
    takeoff_refusals: int = 0
    commands_sent: int = 0
    camera_lost: bool = False
    camera_fault: str | None = None
    """Why the camera stopped (a :class:`~companion.camera.frames.CameraFault` value), when it did."""
    link_lost: bool = False
    failsafes: list[str] = field(default_factory=list)
    ground_channel: dict[str, int] | None = None
    """The ground station's command channel: commands taken, refused and dropped, by why (None without one)."""
    wall_s: float = 0.0
    cpu_s: float = 0.0
    """Process CPU time (all threads) over the flight: ``cpu_s / wall_s`` is the companion's CPU share."""
