"""The SITL vehicle's trajectory log: CSV rows of its state at ``log_rate_hz`` of simulated time (``log_path``)."""

from __future__ import annotations

from pathlib import Path

from sitl.dynamics.base import VehicleState

HEADER = "t_s,north_m,east_m,down_m,vn_mps,ve_mps,vd_mps,qw,qx,qy,qz,armed,mode,landed_state\n"


class TrajectoryLog:
    """Rows at most ``rate_hz`` apart in simulated time, and at once when forced (a phase change, the end), which
    also flushes them to the disk.

    Parameters
    ----------
    path : Path
        The CSV file (its folder is created).
    rate_hz : float
        Rows per simulated second.
    """

    def __init__(self, path: Path, rate_hz: float) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(path, "w", encoding="utf-8")  # noqa: SIM115 - closed in close()
        self._file.write(HEADER)
        self.rate_hz = rate_hz
        self._next_s = 0.0

    def due(self, t_s: float) -> bool:
        """Whether a row is due at simulated ``t_s`` (s)."""
        return t_s >= self._next_s - 1e-9

    def write(self, t_s: float, state: VehicleState, armed: bool, mode: str, landed_state: str, force: bool) -> None:
        """One row: time (s), position (NED, m), velocity (NED, m/s), attitude quaternion (w, x, y, z), armed, the
        PX4 mode and the landed state."""
        self._next_s = t_s + 1.0 / self.rate_hz
        values = [t_s, *state.position_ned_m, *state.velocity_ned_mps, *state.quaternion_wxyz]
        self._file.write(",".join(f"{v:.17g}" for v in values) + f",{int(armed)},{mode},{landed_state}\n")
        if force:
            self._file.flush()

    def close(self) -> None:
        """Close the file."""
        self._file.close()
