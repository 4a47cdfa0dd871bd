"""MAVSDK client flights against a SITL instance, run as their own process (one Mavsdk instance per process).

Prints one JSON object per line: ``{"event": ...}``. Scenarios:

- ``square``: connect, wait healthy and armable, arm, take off to 5 m, fly an offboard square of position setpoints
  (each corner reached within 0.3 m and held 2 s), land with ``action.land()``, see on-ground and disarmed.
- ``hover``: arm, take off, enter OFFBOARD holding position, then keep streaming that setpoint until killed.
- ``push_north``: like ``hover``, then keep asking for a point 8 m north until killed (a takeover test).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
import time
from collections.abc import AsyncIterator
from typing import Any

from mavsdk.asyncio import Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.component_type import ComponentType
from mavsdk.plugins.offboard import PositionNedYaw

ALTITUDE_M = 5.0
TOLERANCE_M = 0.3
HOLD_S = 2.0


def emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}) + "\n")
    sys.stdout.flush()


async def first(stream: AsyncIterator[Any], predicate: Any, timeout_s: float, what: str) -> Any:
    """The first item of ``stream`` that satisfies ``predicate``, within ``timeout_s``."""

    async def scan() -> Any:
        async for item in stream:
            if predicate(item):
                return item
        raise RuntimeError(f"stream ended before {what}")

    try:
        return await asyncio.wait_for(scan(), timeout_s)
    except asyncio.TimeoutError:
        raise RuntimeError(f"timed out after {timeout_s} s waiting for {what}") from None


async def take_off(action: ActionAsync, telemetry: TelemetryAsync) -> None:
    await first(telemetry.subscribe_health(), lambda h: h.is_armable and h.is_local_position_ok, 20, "armable")
    emit("healthy")
    await action.set_takeoff_altitude(ALTITUDE_M)
    await action.arm()
    emit("armed")
    await action.takeoff()
    await first(
        telemetry.subscribe_position_velocity_ned(),
        lambda p: -p.position.down_m > ALTITUDE_M - TOLERANCE_M,
        30,
        "takeoff altitude",
    )
    emit("took_off")


async def reach_and_hold(telemetry: TelemetryAsync, north_m: float, east_m: float, down_m: float) -> float:
    """Wait until within TOLERANCE_M of the point, then until HOLD_S passes inside it; returns the worst error."""

    def error(p: Any) -> float:
        return math.dist((p.position.north_m, p.position.east_m, p.position.down_m), (north_m, east_m, down_m))

    stream = telemetry.subscribe_position_velocity_ned()
    await first(stream, lambda p: error(p) <= TOLERANCE_M, 30, f"corner ({north_m}, {east_m})")
    held_since = time.monotonic()
    worst = 0.0

    async def hold() -> float:
        nonlocal held_since, worst
        async for p in telemetry.subscribe_position_velocity_ned():
            e = error(p)
            if e > TOLERANCE_M:
                held_since, worst = time.monotonic(), 0.0
                continue
            worst = max(worst, e)
            if time.monotonic() - held_since >= HOLD_S:
                return worst
        raise RuntimeError("telemetry ended")

    return await asyncio.wait_for(hold(), 20)


async def square(system: Any) -> None:
    action, offboard, telemetry = ActionAsync(system), OffboardAsync(system), TelemetryAsync(system)
    await take_off(action, telemetry)
    await offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -ALTITUDE_M, 0.0))
    await offboard.start()
    emit("offboard")
    for north_m, east_m in [(6.0, 0.0), (6.0, 6.0), (0.0, 6.0), (0.0, 0.0)]:
        await offboard.set_position_ned(PositionNedYaw(north_m, east_m, -ALTITUDE_M, 0.0))
        worst = await reach_and_hold(telemetry, north_m, east_m, -ALTITUDE_M)
        emit("corner_held", north_m=north_m, east_m=east_m, worst_error_m=worst)
    await action.land()
    await first(telemetry.subscribe_in_air(), lambda in_air: not in_air, 40, "on the ground")
    emit("on_ground")
    await first(telemetry.subscribe_armed(), lambda armed: not armed, 20, "disarmed")
    emit("disarmed")


async def stream_forever(system: Any, target_north_m: float) -> None:
    action, offboard, telemetry = ActionAsync(system), OffboardAsync(system), TelemetryAsync(system)
    await take_off(action, telemetry)
    hold = PositionNedYaw(0.0, 0.0, -ALTITUDE_M, 0.0)
    await offboard.set_position_ned(hold)
    await offboard.start()
    emit("offboard")
    target = PositionNedYaw(target_north_m, 0.0, -ALTITUDE_M, 0.0)
    while True:  # until killed: a client that keeps commanding
        await offboard.set_position_ned(target)
        await asyncio.sleep(0.05)  # the client's own 20 Hz setpoint rate, not a synchronization


async def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("scenario", choices=["square", "hover", "push_north"])
    parser.add_argument("--port", type=int, default=14540)
    args = parser.parse_args()
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpin://0.0.0.0:{args.port}")
        system = await mavsdk.first_autopilot(timeout_s=15.0)
        if system is None:
            emit("error", error="no autopilot within 15 s")
            return 1
        emit("connected")
        try:
            if args.scenario == "square":
                await square(system)
            else:
                await stream_forever(system, 0.0 if args.scenario == "hover" else 8.0)
        except Exception as exc:
            emit("error", error=f"{type(exc).__name__}: {exc}")
            return 1
    emit("done")
    return 0


if __name__ == "__main__":
    sys.exit(asyncio.run(main()))
