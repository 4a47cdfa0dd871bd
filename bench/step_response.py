"""Closed-loop step response of the SITL vehicle (rigid body + cascaded controller), and what a physics step costs.

Run: ``.venv/bin/python -m bench.step_response``. In this process, without MAVLink: the default rigid-body quadrotor
hovering at 10 m under the default controller (position loops at 50 Hz, attitude and rates at the physics rate) is
given a 5 m step north and, separately, a 3 m step up. For each: rise time (10 % to 90 %), overshoot, settling time
(within 5 cm for good), and the end error. Then the wall time of one physics step (controller + dynamics) over 20 s
of hover. Prints and saves ``bench/results/step_response.json`` with the machine's context; a vehicle model that
steps differently (issue 34: floats instead of numpy) must keep the same response.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.machine import machine_context, save_report
from sitl.autopilot.controller import CascadedController, Setpoint
from sitl.dynamics.rigid_body import RigidBodyQuadrotor

REPO_ROOT = Path(__file__).resolve().parent.parent


PHYSICS_RATE_HZ = 400.0
OUTER_EVERY = 8  # position loops at 50 Hz, as the SITL vehicle runs them


def fly(goal_ned_m: tuple[float, float, float], duration_s: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Hover at 10 m, then hold ``goal_ned_m``; returns times (s), positions (N, 3) and the wall time of one step."""
    quad = RigidBodyQuadrotor()
    ctl = CascadedController(quad.airframe)
    dt_s = 1.0 / PHYSICS_RATE_HZ
    hover = Setpoint.hold(np.array([0.0, 0.0, -10.0]), 0.0)
    settle_steps = int(20.0 * PHYSICS_RATE_HZ)
    steps = int(duration_s * PHYSICS_RATE_HZ)
    times, positions = [], []
    wall = 0.0
    for k in range(settle_steps + steps):
        setpoint = hover if k < settle_steps else Setpoint.hold(np.array(goal_ned_m), 0.0)
        start = time.perf_counter()
        state = quad.state()
        if k % OUTER_EVERY == 0:
            ctl.update_position(state, setpoint, OUTER_EVERY * dt_s)
        quad.set_motor_commands(ctl.update_attitude(state, dt_s))
        quad.step(dt_s)
        wall += time.perf_counter() - start
        if k >= settle_steps:
            times.append((k - settle_steps + 1) * dt_s)
            positions.append(quad.state().position_ned_m)
    return np.array(times), np.array(positions), wall / (settle_steps + steps)


def response(times: np.ndarray, values: np.ndarray, start: float, goal: float) -> dict[str, float]:
    """Rise time, overshoot, 5 cm settling time and end error of one axis."""
    span = goal - start
    progress = (values - start) / span
    rise_s = float(times[np.argmax(progress >= 0.9)] - times[np.argmax(progress >= 0.1)])
    overshoot_m = float(max(0.0, np.max((values - goal) * np.sign(span))))
    outside = np.nonzero(np.abs(values - goal) > 0.05)[0]
    settling_s = float(times[outside[-1] + 1]) if len(outside) and outside[-1] + 1 < len(times) else float(times[0])
    return {
        "rise_10_90_s": round(rise_s, 4),
        "overshoot_m": round(overshoot_m, 4),
        "settling_5cm_s": round(settling_s, 4),
        "end_error_m": round(float(abs(values[-1] - goal)), 6),
    }


def main() -> int:
    report: dict[str, Any] = {"machine": machine_context(), "physics_rate_hz": PHYSICS_RATE_HZ}
    t, p, step_s = fly((5.0, 0.0, -10.0), 15.0)
    report["north_5m"] = response(t, p[:, 0], 0.0, 5.0)
    report["north_5m"]["max_altitude_error_m"] = round(float(np.max(np.abs(p[:, 2] + 10.0))), 4)
    t, p, step_up_s = fly((0.0, 0.0, -13.0), 15.0)
    report["up_3m"] = response(t, -p[:, 2], 10.0, 13.0)
    report["step_wall_us"] = round(1e6 * min(step_s, step_up_s), 2)
    for name in ("north_5m", "up_3m"):
        r = report[name]
        print(
            f"{name}: rise {r['rise_10_90_s']:.3f} s, overshoot {100 * r['overshoot_m']:.1f} cm, "
            f"settled (5 cm) at {r['settling_5cm_s']:.2f} s, end error {1000 * r['end_error_m']:.3f} mm"
        )
    print(f"one physics step (controller + rigid body): {report['step_wall_us']:.1f} us")
    save_report(report, REPO_ROOT / "bench" / "results" / "step_response.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
