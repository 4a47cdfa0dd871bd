"""What the live view costs the companion's loop (issue 67): the same real-time missions flown with the live view off,
on with a Foxglove client reading everything, and on with a client that subscribes and stops reading.

Run: ``.venv/bin/python -m bench.live_view [--seeds 1] [--out bench/results/live_view.json]``.

As ``bench.companion_latency``: the SITL in real time (no lockstep, camera at 10 Hz), ``slz fly`` with
``mission_configs/sitl.yaml``; the latency is frame arrival to the setpoint handed to MAVSDK, from the flight log's
``latency`` records, and the CPU share is the companion's CPU time over its wall time. The client is
:class:`sitl.testing.foxglove_client.FoxgloveClient` on this machine (the SITL and the client share the cores, as
they would not on a drone: an upper bound).
"""

from __future__ import annotations

import argparse
import json
import socket
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np

from bench.machine import machine_context, save_report
from companion.flightlog.flight_log import FlightLog, RecordKind
from sitl.harness.instances import lease_instance
from sitl.harness.mission import MissionSpec, fly
from sitl.testing.foxglove_client import FoxgloveClient

REPO_ROOT = Path(__file__).resolve().parent.parent
VARIANTS = ("off", "reading client", "stalled client")


def _free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def fly_one(seed: int, variant: str, tmp: Path) -> dict[str, Any]:
    """One real-time mission with the live view as ``variant`` says; its latency and CPU share."""
    port = _free_tcp_port()
    overrides = {} if variant == "off" else {"live_view": {"enabled": True, "port": port}}
    clients: list[FoxgloveClient] = []

    def connect() -> None:
        clients.append(
            FoxgloveClient(f"ws://127.0.0.1:{port}", connect_timeout_s=120, stall=variant != "reading client")
        )

    watcher = threading.Thread(target=connect, daemon=True)
    if variant != "off":
        watcher.start()
    lease = lease_instance()
    run_dir = tmp / f"seed{seed}-{variant.replace(' ', '-')}"
    spec = MissionSpec(
        seed=seed,
        run_dir=run_dir,
        instance=lease.instance,
        sitl_overrides={"lockstep": False, "speed_factor": 1.0},
        mission_overrides=overrides,
        timeout_s=300.0,
    )
    try:
        result = fly(spec)
    finally:
        lease.release()
        if watcher.is_alive():
            watcher.join(timeout=5.0)
        received = sum(clients[0].counts.values()) if clients else 0
        for client in clients:
            client.close()
    flight = FlightLog.read(run_dir / "flight")
    ms = [float(r["frame_to_command_ms"]) for r in flight.of(RecordKind.LATENCY)]
    outcome = flight.outcome
    return {
        "seed": seed,
        "variant": variant,
        "phase": result.phase,
        "setpoints": len(ms),
        "latency_ms_median": float(np.median(ms)) if ms else None,
        "latency_ms_p95": float(np.percentile(ms, 95)) if ms else None,
        "cpu_share": outcome["cpu_s"] / outcome["wall_s"] if outcome.get("wall_s") else None,
        "frames_dropped_old": outcome.get("frames_dropped_old"),
        "messages_received": received,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1", help="comma-separated mission seeds")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench" / "results" / "live_view.json")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="slz-live-view-") as tmp:
        for seed in (int(s) for s in args.seeds.split(",")):
            for variant in VARIANTS:
                row = fly_one(seed, variant, Path(tmp))
                rows.append(row)
                print(json.dumps(row), flush=True)
    summary = {}
    for variant in VARIANTS:
        mine = [r for r in rows if r["variant"] == variant and r["latency_ms_median"] is not None]
        summary[variant] = {
            "latency_ms_median": float(np.median([r["latency_ms_median"] for r in mine])) if mine else None,
            "latency_ms_p95": float(np.median([r["latency_ms_p95"] for r in mine])) if mine else None,
            "cpu_share": float(np.mean([r["cpu_share"] for r in mine])) if mine else None,
            "messages_received": int(sum(r["messages_received"] for r in mine)),
        }
    report = {
        "benchmark": "live view: the companion's latency and CPU with it off, with a reading and a stalled client",
        "machine": machine_context(),
        "missions": rows,
        "summary": summary,
    }
    print(json.dumps(summary, indent=2))
    save_report(report, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
