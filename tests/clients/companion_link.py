"""The companion's MAVSDK vehicle link against a SITL instance, in its own process (one Mavsdk per process).

Prints one JSON object per line. Connects, checks that stamped poses arrive, arms and takes off to 5 m, enters
OFFBOARD at a point 3 m north, waits until there, reports the interpolated pose, lands and waits for the ground.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import time
from typing import Any

from companion.vehicle.link import FlightMode, Setpoint
from companion.vehicle.mavsdk_link import MavsdkVehicleLink


def emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}) + "\n")
    sys.stdout.flush()


async def until(link: MavsdkVehicleLink, condition: Any, timeout_s: float, what: str) -> None:
    await link.telemetry.wait_for(condition, time.monotonic() + timeout_s, what)


async def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--port", type=int, required=True)
    args = parser.parse_args()
    link = MavsdkVehicleLink(f"udpin://0.0.0.0:{args.port}")
    try:
        await link.connect(timeout_s=15.0)
        emit("connected")
        await until(link, lambda: link.telemetry.poses.latest_t_s is not None, 10.0, "stamped poses")
        t0 = link.telemetry.poses.latest_t_s
        await until(
            link, lambda: (link.telemetry.poses.latest_t_s or 0.0) > (t0 or 0.0) + 1.0, 10.0, "a second of poses"
        )
        emit("poses", latest_t_s=link.telemetry.poses.latest_t_s, clock_now_s=link.telemetry.clock.now_s())
        await link.action.arm_and_takeoff(5.0, timeout_s=40.0)
        emit("took_off", mode=link.telemetry.status.mode.value, armed=link.telemetry.status.armed)
        target = Setpoint(3.0, 0.0, -5.0, 0.0)
        await link.offboard.start(target)
        await until(link, lambda: link.telemetry.status.mode is FlightMode.OFFBOARD, 10.0, "OFFBOARD")

        def near() -> bool:
            t = link.telemetry.poses.latest_t_s
            pose = link.telemetry.poses.pose_at(t) if t is not None else None
            return pose is not None and abs(pose.position_ned_m[0] - 3.0) < 0.3 and abs(pose.altitude_m - 5.0) < 0.3

        await until(link, near, 30.0, "the setpoint")
        t = link.telemetry.poses.latest_t_s
        assert t is not None
        poses = link.telemetry.poses
        latest, between = poses.pose_at(t), poses.pose_at(t - 0.005)  # the second one is interpolated
        assert latest is not None
        assert between is not None
        emit(
            "reached",
            north_m=float(latest.position_ned_m[0]),
            altitude_m=latest.altitude_m,
            mode=link.telemetry.status.mode.value,
            interpolation_step_m=float(abs(latest.position_ned_m - between.position_ned_m).max()),
        )
        await link.action.land()
        await until(link, lambda: not link.telemetry.status.in_air, 40.0, "on the ground")
        emit("landed", dropped=link.telemetry.dropped_samples)
    except Exception as exc:
        emit("error", error=f"{type(exc).__name__}: {exc}")
        return 1
    finally:
        await link.close()
    return 0


if __name__ == "__main__":
    sys.exit(asyncio.run(main()))
