"""Real-time factor of the SITL vehicle: headless for each dynamics backend, then with world and camera in lockstep.

Run: ``.venv/bin/python -m bench.sitl_speed [--sim-seconds 60]``. The whole vehicle runs in this process, as fast as
possible: physics and attitude control at 400 Hz, position control, commander, telemetry encoding and UDP sends at
100 Hz, trajectory log off. It takes off and flies to a point 22 m away and holds there. Then the full run: a SITL
process pinned to one core with the world and the 640x480 camera at 10 Hz, in lockstep with a client that arms, takes
off to 20 m over MAVLink and receives every frame (target: 60 s simulated in under 15 s). Prints and saves
``bench/results/sitl_speed.json`` with the machine's context.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import socket
import sys
import time
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from bench.machine import machine_context, save_report
from companion.camera.frames import SitlFrameSource
from sitl.autopilot.modes import FlightMode
from sitl.config import SitlConfig
from sitl.dynamics.base import DynamicsBackend
from sitl.harness.instances import leased_instance
from sitl.harness.lockstep import LockstepControl
from sitl.harness.process import SitlProcess
from sitl.vehicle.process import SitlVehicle

REPO_ROOT = Path(__file__).resolve().parent.parent


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


def full_run(sim_seconds: float, instance: int, log_dir: Path) -> dict[str, float]:
    """Vehicle + world + camera (640x480, 10 Hz) in lockstep with a client that takes every frame; SITL on CPU 0."""
    config = log_dir / "full-run.yaml"
    config.write_text(
        "sitl:\n  camera:\n    enabled: true\n  scenario:\n    moving_fraction: 0.2\n"
        "  params:\n    MIS_TAKEOFF_ALT: 20.0\n    MPC_Z_VEL_MAX_UP: 5.0\n    MPC_TKO_SPEED: 4.0\n"
    )
    args = ["--config", str(config), "--lockstep", "--speed", "0", "--duration", str(sim_seconds)]
    args += ["--log", str(log_dir / "trajectory.csv")]
    sitl = SitlProcess(args, instance, log_dir, cpu=0).start()
    control = LockstepControl(instance)
    # The API link, as MAVSDK would hold it: arm and take off at the first ticks, counted in the acknowledgements.
    mav_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    mav_sock.bind(("127.0.0.1", 14540 + instance))
    mav_sock.settimeout(5.0)
    _, vehicle = mav_sock.recvfrom(65535)
    mav = mavlink.MAVLink(None, srcSystem=control.system_id, srcComponent=control.component_id)
    commands = {
        1: (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [1.0, 0, 0, 0, 0, 0, 0]),
        2: (mavlink.MAV_CMD_NAV_TAKEOFF, [0, 0, 0, math.nan, math.nan, math.nan, math.nan]),
    }

    async def take_frames() -> tuple[int, float]:
        sent = 0
        frames = SitlFrameSource("127.0.0.1", 5600 + instance, timeout_s=30).frames()
        control.subscribe()
        count, start = 0, time.perf_counter()
        try:
            while True:
                try:
                    frame = await frames.__anext__()
                except StopAsyncIteration:
                    break
                tick = await asyncio.to_thread(control.next_tick, 30.0)
                if tick["seq"] != frame.seq:
                    raise RuntimeError(f"frame {frame.seq} arrived with tick {tick['seq']}")
                count += 1
                if tick["seq"] in commands:
                    command, params = commands[tick["seq"]]
                    message = mav.command_long_encode(1 + instance, 1, command, 0, *params)
                    mav_sock.sendto(message.pack(mav), vehicle)
                    mav.seq = (mav.seq + 1) % 256
                    sent += 1
                control.ack(tick["seq"], sent)
                if frame.t_capture_s >= sim_seconds - 0.1 - 1e-9:
                    break
        finally:
            await frames.aclose()  # type: ignore[attr-defined]
        return count, time.perf_counter() - start

    try:
        count, wall_s = asyncio.run(take_frames())
        if sitl.wait(timeout_s=60) != 0:
            raise RuntimeError(f"the SITL failed:\n{sitl.log_tail()}")
        altitude_m = max(
            -float(line.split(",")[3]) for line in (log_dir / "trajectory.csv").read_text().splitlines()[1:]
        )
    finally:
        control.close()
        mav_sock.close()
        sitl.stop()
    if altitude_m < 19.0:
        raise RuntimeError(f"the benchmark flight did not climb (max altitude {altitude_m:.1f} m)")
    return {
        "sim_s": sim_seconds,
        "frames": count,
        "max_altitude_m": altitude_m,
        "wall_s": wall_s,
        "real_time_factor": sim_seconds / wall_s,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sim-seconds", type=float, default=60.0)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench" / "results" / "sitl_speed.json")
    args = parser.parse_args()
    results: dict[str, dict[str, float] | str] = {}
    for backend in DynamicsBackend:
        try:
            with leased_instance() as lease:
                results[backend.value] = measure(backend, args.sim_seconds, instance=lease.instance)
        except Exception as exc:  # a missing optional backend is reported, not fatal
            results[backend.value] = f"not measured: {exc}"
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        try:
            with leased_instance() as lease:
                results["full_run_camera_lockstep"] = full_run(args.sim_seconds, lease.instance, Path(tmp))
        except Exception as exc:
            results["full_run_camera_lockstep"] = f"not measured: {exc}"
    report = {"benchmark": "sitl_speed", "machine": machine_context(), "backends": results}
    sys.stdout.write(f"SITL vehicle, headless, one process, {report['machine']}\n")
    for name, row in results.items():
        if isinstance(row, dict):
            sys.stdout.write(
                f"{name:<14} {row['sim_s']:.0f} s simulated in {row['wall_s']:.2f} s wall: "
                f"real-time factor {row['real_time_factor']:.1f}"
                + (f", {row['frames']:.0f} frames" if "frames" in row else "")
                + "\n"
            )
        else:
            sys.stdout.write(f"{name:<14} {row}\n")
    save_report(report, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
