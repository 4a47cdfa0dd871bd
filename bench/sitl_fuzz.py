"""Hostile input at scale: 100,000 malformed MAVLink datagrams and 10,000 hostile control requests against one SITL.

Run: ``.venv/bin/python -m bench.sitl_fuzz [--datagrams 100000] [--requests 10000] [--seed 23]``.

A ground-station peer and an API peer hold the two MAVLink links (each is its link's partner and heartbeats at 1 Hz, as
MAVSDK and QGroundControl do) and record every heartbeat's wall time. A stray sender then sends the seeded datagrams of
``sitl.harness.fuzz`` to both links, paced (every datagram reaches the SITL's parser), then an unthrottled 5 s flood,
then the control requests. Asserted, and printed with the machine's context into ``bench/results/sitl_fuzz.json``:

- the SITL process is alive, answers ``state``, and never failed to handle a message (``handler_errors`` 0);
- the heartbeat gap on both links stayed under 1.5 s throughout;
- neither link followed the stray sender;
- afterwards a clean MAVSDK client (``python -m sitl.testing.mavsdk_flight square``) flies the offboard square: take-off
  to 5 m, four corners each held within 0.3 m for 2 s, landing, disarm.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import socket
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench.machine import machine_context, save_report
from sitl.config import SitlConfig
from sitl.harness.fuzz import ControlFuzzer, MavlinkFuzzer
from sitl.harness.instances import lease_instance
from sitl.harness.process import SitlProcess
from sitl.testing.helpers import MavlinkPeer, wait_until
from sitl.testing.mavsdk_client import Client

REPO_ROOT = Path(__file__).resolve().parent.parent


MAX_HEARTBEAT_GAP_S = 1.5
PACE_PER_S = 4000.0  # paced phase: slow enough that the SITL's socket buffer never overflows
FLOOD_S = 5.0


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def parsed(links: dict[str, Any]) -> int:
    """Datagram-level events the SITL's parsers saw (good messages and drops of every kind)."""
    keys = ("received", "dropped_malformed", "dropped_unknown", "dropped_unsigned")
    return sum(int(link[k]) for link in links.values() for k in keys)


def worst_gap_s(beats: list[float]) -> float:
    return max((b - a for a, b in itertools.pairwise(beats)), default=float("inf"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datagrams", type=int, default=100_000)
    parser.add_argument("--requests", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=23)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench" / "results" / "sitl_fuzz.json")
    args = parser.parse_args()
    lease = lease_instance()
    work = Path("/tmp") / f"slz-bench-fuzz-{lease.instance}"
    config = SitlConfig(instance=lease.instance)
    gcs_port = free_udp_port()
    sitl_yaml = work / "sitl.yaml"
    sitl_yaml.parent.mkdir(parents=True, exist_ok=True)
    sitl_yaml.write_text(f"sitl:\n  gcs_port_remote: {gcs_port}\n  seed: {args.seed}\n")
    print(f"generating {args.datagrams} datagrams and {args.requests} requests (seed {args.seed})...", flush=True)
    mav_fuzz = MavlinkFuzzer(args.seed, config.system_id)
    datagrams = list(mav_fuzz.datagrams(args.datagrams))
    control_fuzz = ControlFuzzer(args.seed + 1)
    requests = list(control_fuzz.requests(args.requests))

    sitl = SitlProcess(["--config", str(sitl_yaml), "--speed", "1"], lease.instance, work).start()
    api = MavlinkPeer(config.api_port_remote)
    gcs = MavlinkPeer(gcs_port)
    peers = {"api": api, "gcs": gcs}
    stray = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stray.bind(("127.0.0.1", 0))
    stray.setblocking(False)
    targets = [("127.0.0.1", config.api_port_local), ("127.0.0.1", config.gcs_port_local)]
    report: dict[str, Any] = {"machine": machine_context(), "seed": args.seed}
    try:
        for name, peer in peers.items():
            wait_until(lambda p=peer: p.latest("HEARTBEAT"), 5.0, f"a heartbeat on {name}")  # type: ignore[misc]
            peer.send(peer.mav.heartbeat_encode(6, 8, 0, 0, 4))
        partners = {"api": f"127.0.0.1:{config.api_port_remote}", "gcs": f"127.0.0.1:{gcs_port}"}
        wait_until(
            lambda: all(sitl.state()["links"][n]["partner"] == partners[n] for n in partners) or None,
            5.0,
            "both partners",
        )

        last_beat = [time.monotonic()]

        def poll() -> None:
            """Read both links; each peer heartbeats at 1 Hz, as MAVSDK and ground stations do."""
            beat = time.monotonic() - last_beat[0] >= 1.0
            if beat:
                last_beat[0] = time.monotonic()
            for peer in peers.values():
                peer.poll()
                if beat:
                    peer.send(peer.mav.heartbeat_encode(6, 8, 0, 0, 4))

        # Paced: every datagram reaches a parser.
        t0 = time.monotonic()
        sent_paced = 0
        for i, datagram in enumerate(datagrams):
            while time.monotonic() < t0 + i / PACE_PER_S:
                poll()
            try:
                stray.sendto(datagram, targets[i % 2])
                sent_paced += 1
            except BlockingIOError:
                pass
        paced_s = time.monotonic() - t0

        def state_when(ready: Callable[[dict[str, Any]], bool]) -> Callable[[], dict[str, Any] | None]:
            def check() -> dict[str, Any] | None:
                state = sitl.state()
                return state if ready(state) else None

            return check

        after_paced = wait_until(state_when(lambda s: parsed(s["links"]) >= 0.99 * sent_paced), 10.0, "parsing")
        # Unthrottled: as fast as this process can send, for FLOOD_S.
        t1 = time.monotonic()
        sent_flood = 0
        for datagram in itertools.cycle(datagrams):
            if time.monotonic() - t1 > FLOOD_S:
                break
            try:
                stray.sendto(datagram, targets[sent_flood % 2])
                sent_flood += 1
            except BlockingIOError:
                poll()
            if sent_flood % 2000 == 0:
                poll()
        # Control requests, paced the same way.
        t2 = time.monotonic()
        for i, request in enumerate(requests):
            while time.monotonic() < t2 + i / PACE_PER_S:
                poll()
            with contextlib.suppress(OSError):  # a full buffer, or a datagram over 64 KiB
                stray.sendto(request, sitl.control_addr)
        state = wait_until(state_when(lambda s: s["control_malformed"] >= args.requests // 2), 10.0, "requests")

        def two_more_beats() -> bool | None:
            poll()
            return all(sum(t > t2 for t in p.heartbeat_wall_times) >= 2 for p in peers.values()) or None

        wait_until(two_more_beats, 5.0, "heartbeats after the fuzz")
        gaps = {name: worst_gap_s(p.heartbeat_wall_times) for name, p in peers.items()}
        links = state["links"]
        report["fuzz"] = {
            "datagrams": args.datagrams,
            "kinds": mav_fuzz.counts,
            "paced_per_s": round(args.datagrams / paced_s),
            "parsed_after_paced_phase": parsed(after_paced["links"]),
            "flood_s": FLOOD_S,
            "flood_sent": sent_flood,
            "flood_per_s": round(sent_flood / FLOOD_S),
            "control_requests": args.requests,
            "control_kinds": control_fuzz.counts,
            "control_malformed": state["control_malformed"],
            "handler_errors": state["handler_errors"],
            "links": {
                n: {k: links[n][k] for k in ("received", "dropped_malformed", "dropped_unknown", "stray_frames")}
                for n in links
            },
            "partners_kept": all(links[n]["partner"] == partners[n] for n in partners),
            "worst_heartbeat_gap_s": {n: round(g, 3) for n, g in gaps.items()},
            "heartbeats": {n: len(p.heartbeat_wall_times) for n, p in peers.items()},
        }
        print(report["fuzz"], flush=True)
        assert sitl.running, "the SITL died"
        assert state["handler_errors"] == 0
        assert report["fuzz"]["partners_kept"]
        assert max(gaps.values()) < MAX_HEARTBEAT_GAP_S, gaps
        api.close()  # MAVSDK listens on the API peer's port from here

        # A clean MAVSDK client flies the offboard square.
        t3 = time.monotonic()
        client = Client("square", lease.instance)
        try:
            for event, timeout_s in (("connected", 20), ("healthy", 20), ("armed", 10), ("took_off", 30)):
                client.expect(event, timeout_s)
            client.expect("offboard", 10)
            corners = [client.expect("corner_held", 40) for _ in range(4)]
            client.expect("on_ground", 60)
            client.expect("disarmed", 20)
        finally:
            client.kill()
        report["square"] = {
            "corners_worst_error_m": [round(c["worst_error_m"], 3) for c in corners],
            "wall_s": round(time.monotonic() - t3, 1),
        }
        assert all(c["worst_error_m"] <= 0.3 for c in corners)
        assert sitl.state()["handler_errors"] == 0
        print(report["square"], flush=True)
    finally:
        stray.close()
        for peer in peers.values():
            peer.close()
        sitl.stop()
        lease.release()
    save_report(report, args.out)
    print(f"saved {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
