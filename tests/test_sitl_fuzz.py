"""Hostile input against a running SITL: it stays up, keeps heartbeating, is not taken over, and still flies.

A ground station holds the GCS link; a stray sender floods both MAVLink links with seeded malformed datagrams
(``sitl.harness.fuzz``) and the control channel with hostile requests; then a clean MAVSDK client arms, takes off and
enters OFFBOARD. The 100,000-datagram version is ``bench/sitl_fuzz.py``.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import socket
import time
from pathlib import Path

import pytest

from sitl.config import SitlConfig
from sitl.harness.fuzz import ControlFuzzer, MavlinkFuzzer
from sitl.harness.process import SitlProcess
from sitl.testing.helpers import MavlinkPeer, free_udp_port, wait_until
from sitl.testing.mavsdk_client import Client

pytestmark = pytest.mark.sitl

DATAGRAMS_PER_LINK = 3000
CONTROL_REQUESTS = 2000
MAX_HEARTBEAT_GAP_S = 1.5


def test_a_fuzzed_sitl_stays_up_keeps_its_partner_and_heartbeat_and_still_flies(tmp_path: Path, instance: int) -> None:
    config = SitlConfig(instance=instance)
    gcs_port = free_udp_port()
    sitl_yaml = tmp_path / "sitl.yaml"
    sitl_yaml.write_text(f"sitl:\n  gcs_port_remote: {gcs_port}\n  seed: 3\n")
    sitl = SitlProcess(["--config", str(sitl_yaml), "--speed", "1"], instance, tmp_path).start()
    gcs = MavlinkPeer(gcs_port)
    stray = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stray.bind(("127.0.0.1", 0))
    stray.setblocking(False)
    client: Client | None = None
    try:
        # The ground station speaks first: it is the GCS link's partner.
        wait_until(lambda: gcs.latest("HEARTBEAT"), 5.0, "a heartbeat on the GCS link")
        gcs.send(gcs.mav.heartbeat_encode(6, 8, 0, 0, 4))  # MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID
        partner = f"127.0.0.1:{gcs_port}"
        wait_until(lambda: sitl.state()["links"]["gcs"]["partner"] == partner or None, 3.0, "the GCS partner")

        mav_fuzz = MavlinkFuzzer(seed=23, target_system=config.system_id)
        targets = [("127.0.0.1", config.api_port_local), ("127.0.0.1", config.gcs_port_local)]
        for i, datagram in enumerate(mav_fuzz.datagrams(2 * DATAGRAMS_PER_LINK)):
            with contextlib.suppress(BlockingIOError):  # a full socket buffer loses it, as on a real link
                stray.sendto(datagram, targets[i % 2])
            if i % 200 == 199:
                sitl.state()  # paces the sender to the SITL's loop (its links are read in the same turn)
                gcs.poll()
        control_fuzz = ControlFuzzer(seed=29)
        for i, request in enumerate(control_fuzz.requests(CONTROL_REQUESTS)):
            with contextlib.suppress(OSError):  # a full buffer; a datagram over 64 KiB is refused by the kernel
                stray.sendto(request, sitl.control_addr)
            if i % 20 == 19:
                # A state round trip queues behind the requests sent so far: when it is answered, they were read,
                # so the socket buffer never overflows on a loaded machine (a dropped request would test nothing).
                sitl.state()
                gcs.poll()
        fuzz_end = time.monotonic()

        # It answers, counted what it dropped, never failed handling one, and the GCS link did not follow the stray.
        state = wait_until(
            lambda: ((s := sitl.state())["control_malformed"] > 0.4 * CONTROL_REQUESTS and s) or None,
            10.0,
            "the control fuzz to be read",
        )
        assert sitl.running
        assert state["handler_errors"] == 0
        links = state["links"]
        assert links["gcs"]["partner"] == partner
        assert links["gcs"]["stray_frames"] > 0
        for name in ("api", "gcs"):
            assert links[name]["dropped_malformed"] > DATAGRAMS_PER_LINK // 10, (name, links[name])
            assert links[name]["dropped_unknown"] > 0, (name, links[name])
        assert len(json.dumps(state)) < 60_000  # the state reply still fits a datagram
        assert state["armed"] is False
        assert state["mode"] == "AUTO.LOITER"

        # Heartbeats kept their rate through the flood, on the ground station's link.
        def beats_after_fuzz() -> int | None:
            gcs.poll()
            count = sum(t > fuzz_end for t in gcs.heartbeat_wall_times)
            return count if count >= 2 else None

        wait_until(beats_after_fuzz, 5.0, "two heartbeats after the fuzz")
        beats = gcs.heartbeat_wall_times
        gaps = [b - a for a, b in itertools.pairwise(beats)]
        assert len(beats) >= 3
        assert max(gaps) < MAX_HEARTBEAT_GAP_S, f"heartbeat gap {max(gaps):.2f} s"

        # A clean MAVSDK client on the API link still flies it.
        client = Client("hover", instance)
        client.expect("connected", 20)
        client.expect("healthy", 20)
        client.expect("armed", 10)
        client.expect("took_off", 30)
        client.expect("offboard", 10)
        flying = sitl.state()
        assert flying["mode"] == "OFFBOARD"
        assert flying["position_ned_m"][2] < -3.0
        assert flying["handler_errors"] == 0
    finally:
        if client is not None:
            client.kill()
        stray.close()
        gcs.close()
        sitl.stop()


@pytest.mark.unit
def test_the_fuzz_never_sets_a_real_parameter_to_a_number() -> None:
    """The SITL stores any finite value of a parameter, as PX4 does, and flies with it clamped: a fuzzed
    COM_OF_LOSS_T of -1e30 flew as 0 s, and the clean client after the fuzz lost OFFBOARD at once (when that datagram
    got through the flood, so the test failed on a loaded machine only). Every PARAM_SET the fuzzer builds for a real
    parameter carries NaN or infinity, which the SITL refuses."""
    from pymavlink.dialects.v20 import common as mavlink

    from sitl.px4_params import PARAMS

    names = {spec.name for spec in PARAMS}
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    sets = []
    for datagram in MavlinkFuzzer(seed=23, target_system=1).datagrams(6000):
        for msg in parser.parse_buffer(datagram) or []:
            if msg.get_type() == "PARAM_SET":
                name = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) else ""
                sets.append((name, msg.param_value))
    real = [(name, value) for name, value in sets if name in names]
    assert len(real) >= 20  # the fuzz does aim at real parameters
    assert all(not math.isfinite(value) for _, value in real), real[:5]
