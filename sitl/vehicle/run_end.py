"""When a SITL run ends by itself after its lockstep client let go (``end_after_touchdown_s``): in simulated time,
so the ground truth ends at the same instant at any speed."""

from __future__ import annotations


class RunEnd:
    """Once a lockstep client has let go: the run ends when the vehicle is disarmed, or has been on the ground (first
    seen there after the release) for ``end_after_touchdown_s``.

    Parameters
    ----------
    end_after_touchdown_s : float or None
        Simulated seconds on the ground before the run ends; None: it never ends by itself.
    """

    def __init__(self, end_after_touchdown_s: float | None) -> None:
        self.end_after_touchdown_s = end_after_touchdown_s
        self.grounded_s: float | None = None
        """Simulated time the vehicle was first seen on the ground after the release (None: not yet)."""

    def reached(self, t_s: float, released: bool, armed: bool, on_ground: bool) -> str | None:
        """Why the run ends at simulated ``t_s`` (s), in words; None while it goes on. ``released``: the lockstep
        client has let go; ``armed`` and ``on_ground``: the vehicle now."""
        end_s = self.end_after_touchdown_s
        if end_s is None or not released:
            return None
        if not armed:
            return f"disarmed after the lockstep client let go, at {t_s:.3f} s simulated: the run ends"
        if self.grounded_s is None:
            if on_ground:
                self.grounded_s = t_s
            return None
        if t_s >= self.grounded_s + end_s - 1e-9:
            return (
                f"on the ground since {self.grounded_s:.3f} s simulated, {end_s:.1f} s after the lockstep client let "
                "go: the run ends"
            )
        return None
