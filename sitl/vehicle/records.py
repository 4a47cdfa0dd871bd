"""What the SITL vehicle writes about itself while it runs: the trajectory CSV, the ULog, the ground truth a campaign
scores a mission by, and the live truth a Foxglove client watches. Each is optional (its config path or port), each
at its own rate of simulated time, and forced rows (a phase change, the end) reach the disk at once.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from sitl.autopilot.battery import Battery
from sitl.autopilot.commander import Commander
from sitl.autopilot.controller import Setpoint
from sitl.autopilot.flight_ulog import FlightULog
from sitl.autopilot.params import ParameterStore
from sitl.config import SitlConfig
from sitl.dynamics.base import VehicleState
from sitl.vehicle.live_truth import LiveTruth
from sitl.vehicle.trajectory_log import TrajectoryLog
from sitl.vehicle.truth import TruthRecord, TruthWriter


class VehicleRecords:
    """The vehicle's records, none open until :meth:`open` (so :meth:`close` works from any failure before)."""

    def __init__(self) -> None:
        self.trajectory: TrajectoryLog | None = None
        self.truth: TruthWriter | None = None
        self.ulog: FlightULog | None = None
        self.live: LiveTruth | None = None

    def open(self, config: SitlConfig, params: ParameterStore, truth: bool) -> None:
        """Open what ``config`` asks for (ground truth only with ``truth``: a camera draws people); raises
        :class:`~sitl.vehicle.live_truth.LiveTruthError` when the live view's port cannot be had."""
        if config.truth_path is not None and truth:
            self.truth = TruthWriter(Path(config.truth_path), config.seed)
        if config.log_path is not None:
            self.trajectory = TrajectoryLog(Path(config.log_path), config.log_rate_hz)
        if config.ulog_path is not None:
            self.ulog = FlightULog(Path(config.ulog_path), config.log_rate_hz, params, config.system_id)
        if config.live_view_port is not None:
            self.live = LiveTruth(config.live_view_port, config.bind_address)

    def row(
        self,
        t_s: float,
        state: Callable[[], VehicleState],
        cmd: Commander,
        setpoint: Setpoint | None,
        battery: tuple[Battery, int],
        people: Callable[[], dict[str, Any]] | None,
        force: bool = False,
    ) -> None:
        """The rows due at ``t_s`` (all of them when ``force``): the ULog's (the battery and its monitor's level), the
        live view's (``people``: the crowd as it stands, never advanced here) and the trajectory's."""
        if self.ulog is not None and (force or self.ulog.due(t_s)):
            self.ulog.sample(t_s, state(), cmd, setpoint, *battery)
        if self.live is not None and self.live.due(t_s):
            self.live.sample(t_s, None if people is None else people(), state())
        if self.trajectory is None or not (force or self.trajectory.due(t_s)):
            return
        self.trajectory.write(t_s, state(), cmd.armed, cmd.mode.px4_name, cmd.landed_state.name, force)

    def truth_at(
        self, t_s: float, state: VehicleState, cmd: Commander, warning_on: bool, people_at: Callable[[float], Any]
    ) -> None:
        """One ground-truth record at ``t_s`` (people positions only when some walk)."""
        if self.truth is None:
            return
        n, e, d = (float(v) for v in state.position_ned_m)
        flags = (cmd.armed, cmd.mode.px4_name, cmd.landed_state.name, bool(state.on_ground))
        self.truth.write(t_s, people_at(t_s), TruthRecord(t_s, (n, e, d), *flags, warning=warning_on))

    def close(self) -> None:
        """Close every record (the trajectory first, the truth last, as they were opened around them)."""
        for log in (self.trajectory, self.ulog, self.live, self.truth):
            if log is not None:
                log.close()
        self.trajectory = self.ulog = self.live = None
        self.truth = None
