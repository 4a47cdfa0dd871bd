"""Real-time factor of the headless SITL vehicle (no camera) for each dynamics backend.

Run: ``.venv/bin/python bench/sitl_speed.py [--sim-seconds 60]``. The whole vehicle runs in this process, as fast as
possible: physics and attitude control at 400 Hz, position control, commander, telemetry encoding and UDP sends at
100 Hz, trajectory log off. It takes off and flies to a point 22 m away and holds there. Prints and saves
``bench/results/sitl_speed.json`` with the machine's context.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO_ROOT))

from bench.machine import machine_context, save_report  # noqa: E402
from sitl.autopilot.modes import FlightMode  # noqa: E402
from sitl.config import SitlConfig  # noqa: E402
from sitl.dynamics.base import DynamicsBackend  # noqa: E402
from sitl.vehicle import SitlVehicle  # noqa: E402


def measure(backend: DynamicsBackend, sim_seconds: float, instance: int) -> dict[str, float]:
    config = SitlConfig(
        instance=instance,
        dynamics=backend,
        speed_factor=0.0,
        duration_s=sim_seconds,
        params={"COM_OF_LOSS_T": 60.0},
    )
    vehicle = SitlVehicle(config)
    try:
        cmd = vehicle.commander
        cmd.update(0.0, vehicle.dynamics.state(), 0.0)
        cmd.offboard_setpoint(np.array([20.0, 10.0, -10.0]), np.full(3, np.nan), 0.0)
        cmd.set_mode(FlightMode.OFFBOARD)
        cmd.arm()
        start = time.perf_counter()
        code = vehicle.run()
        wall_s = time.perf_counter() - start
        final = vehicle.dynamics.state().position_ned_m
    finally:
        vehicle.close()
    if code != 0 or np.linalg.norm(final - [20.0, 10.0, -10.0]) > 0.5:
        raise RuntimeError(f"{backend.value}: the benchmark flight failed (exit {code}, final {final})")
    return {"sim_s": sim_seconds, "wall_s": wall_s, "real_time_factor": sim_seconds / wall_s}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sim-seconds", type=float, default=60.0)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench" / "results" / "sitl_speed.json")
    args = parser.parse_args()
    results: dict[str, dict[str, float] | str] = {}
    for i, backend in enumerate(DynamicsBackend):
        try:
            results[backend.value] = measure(backend, args.sim_seconds, instance=30 + i)
        except Exception as exc:  # a missing optional backend is reported, not fatal
            results[backend.value] = f"not measured: {exc}"
    report = {"benchmark": "sitl_speed", "machine": machine_context(), "backends": results}
    sys.stdout.write(f"SITL vehicle, headless, one process, {report['machine']}\n")
    for name, row in results.items():
        if isinstance(row, dict):
            sys.stdout.write(
                f"{name:<14} {row['sim_s']:.0f} s simulated in {row['wall_s']:.2f} s wall: "
                f"real-time factor {row['real_time_factor']:.1f}\n"
            )
        else:
            sys.stdout.write(f"{name:<14} {row}\n")
    save_report(report, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
