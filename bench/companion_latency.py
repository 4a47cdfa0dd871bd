"""The companion's frame-arrival to setpoint-sent latency and CPU share, flying real missions in real time.

Run: ``.venv/bin/python -m bench.companion_latency [--seeds 1,2] [--out bench/results/companion_latency.json]``.

Each mission is the SITL in real time (no lockstep, camera at 10 Hz, as a drone's camera would run) and ``slz fly``
with ``mission_configs/sitl.yaml``: the latency is from the moment the companion has a whole frame to the moment the
setpoint decided on it has been handed to MAVSDK (pose pairing, the pipeline, the state machine, the send), from the
flight log's ``latency`` records. The CPU share is the companion process's CPU time over its wall time (1.0 = one
core). The SITL (renderer included) shares the machine, as it would not on a drone: the numbers are an upper bound.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from bench.machine import machine_context, save_report
from companion.flightlog.flight_log import FlightLog, RecordKind
from sitl.harness.instances import lease_instance
from sitl.harness.mission import MissionSpec, fly

REPO_ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1,2", help="comma-separated mission seeds")
    parser.add_argument("--instance", type=int, help="SITL instance (default: a free one, leased)")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench" / "results" / "companion_latency.json")
    args = parser.parse_args()

    latencies: list[float] = []
    missions = []
    with tempfile.TemporaryDirectory(prefix="slz-latency-") as tmp:
        for seed in (int(s) for s in args.seeds.split(",")):
            lease = lease_instance() if args.instance is None else None
            spec = MissionSpec(
                seed=seed,
                run_dir=Path(tmp) / f"seed{seed}",
                instance=args.instance if lease is None else lease.instance,
                sitl_overrides={"lockstep": False, "speed_factor": 1.0},
                timeout_s=300.0,
            )
            try:
                result = fly(spec)
            finally:
                if lease is not None:
                    lease.release()
            flight = FlightLog.read(spec.run_dir / "flight")
            mission_ms = [float(r["frame_to_command_ms"]) for r in flight.of(RecordKind.LATENCY)]
            outcome = flight.outcome
            share = outcome["cpu_s"] / outcome["wall_s"] if outcome["wall_s"] > 0 else float("nan")
            latencies += mission_ms
            missions.append(
                {
                    "seed": seed,
                    "phase": result.phase,
                    "decisions_sent": len(mission_ms),
                    "frames_processed": outcome["frames_processed"],
                    "frames_dropped_old": outcome["frames_dropped_old"],
                    "frames_dropped_no_pose": outcome["frames_dropped_no_pose"],
                    "cpu_share": share,
                    "wall_s": outcome["wall_s"],
                }
            )
            print(
                f"seed {seed}: {result.phase}, {len(mission_ms)} setpoints, median {np.median(mission_ms):.1f} ms, "
                f"CPU share {share:.2f}"
            )
    ms = np.asarray(latencies)
    report = {
        "benchmark": "companion frame-arrival to setpoint-sent latency, real-time SITL missions",
        "machine": machine_context(),
        "missions": missions,
        "setpoints": len(ms),
        "latency_ms": {
            "median": float(np.median(ms)),
            "p95": float(np.percentile(ms, 95)),
            "p99": float(np.percentile(ms, 99)),
            "max": float(ms.max()),
        },
        "cpu_share_mean": float(np.mean([m["cpu_share"] for m in missions])),
    }
    print(json.dumps(report, indent=2))
    save_report(report, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
