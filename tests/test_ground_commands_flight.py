"""Ground-station commands to a companion flying the SITL: a pymavlink ground station sends signed and unsigned
COMMAND_LONGs to the companion's own component over real UDP, and the vehicle's behaviour is checked in its flight log
and the SITL's ground truth. The logic of each command on hand-made maps: tests/test_operator_commands.py."""

from __future__ import annotations

import math
import re
import subprocess
from pathlib import Path
from typing import Any

import pytest

from companion.app.recorder import read_log
from companion.app.replay import replay
from companion.ground import mavlink_frames as frames
from companion.ground.command_channel import AckResult
from sitl.testing.helpers import free_udp_port, sitl_mission_yaml, slz_fly_argv, start_camera_sitl, wait_until
from tests.mavproxy_client import MavProxy
from tests.test_ground_channel import Gcs

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent
KEY = frames.key_from_passphrase("secret")  # docs/ground_station.md's passphrase
DOC = REPO_ROOT / "docs" / "ground_station.md"
GO_AROUND, REJECT, LAND_NOW = 191, 31010, 31011


def decisions(log: Path) -> list[dict[str, Any]]:
    """The decisions logged so far (each with its ``source``, ``t_s`` and its fields)."""
    records = read_log(log) if log.is_file() else []
    return [{**r["decision"], "source": r["source"]} for r in records if r["kind"] == "decision"]


def documented_mavproxy(port: int) -> tuple[list[str], list[str]]:
    """docs/ground_station.md's MAVProxy command line (its arguments, on the test's port) and console lines."""
    text = DOC.read_text()
    line = re.search(r"^mavproxy\.py (.*)$", text, re.M)
    console = re.search(r"^```mavproxy\n(.*?)^```", text, re.M | re.S)
    assert line is not None
    assert console is not None
    args = line.group(1).replace("COMPANION_IP:14595", f"127.0.0.1:{port}").split()
    return args, console.group(1).splitlines()


def answered(gcs: Gcs, mav_cmd: int, timeout_s: float = 30.0) -> int:
    """The final answer (not IN_PROGRESS) to ``mav_cmd``."""
    final = wait_until(
        lambda: [r for c, r in gcs.acks() if c == mav_cmd and r != AckResult.IN_PROGRESS],
        timeout_s,
        f"the answer to command {mav_cmd}",
    )
    return int(final[-1])


def test_signed_commands_reject_a_zone_and_go_around_unsigned_ones_are_refused_and_the_flight_replays(
    tmp_path: Path, instance: int
) -> None:
    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port(), lockstep=True)
    port = free_udp_port()
    text = sitl_mission_yaml(instance, flights_dir=tmp_path, replayable=True)
    text += f"ground_station:\n  command_url: udpin://127.0.0.1:{port}\n  signing_key_hex: {KEY.hex()}\n"
    mission = tmp_path / "mission.yaml"
    mission.write_text(text)
    log = tmp_path / "flight" / "flight.jsonl"
    link_args, console = documented_mavproxy(port)
    assert console[:2] == ["signing key secret", "long DO_GO_AROUND"]
    pilot, stranger = Gcs(port, KEY, link_id=1, reply_key=KEY), Gcs(port, reply_key=KEY)
    fly = subprocess.Popen(
        slz_fly_argv(mission, tmp_path / "flight"),
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    mavproxy = MavProxy(port, tmp_path, link_args)  # the pilot's console, as docs/ground_station.md writes it
    try:
        wait_until(lambda: any(d["phase"] == "approach" for d in decisions(log)), 180, "the first approach")
        mavproxy.start()
        stranger.command(GO_AROUND)  # unsigned: refused, and the vehicle flies on
        assert answered(stranger, GO_AROUND) == AckResult.DENIED
        pilot.command(REJECT)
        assert answered(pilot, REJECT) == AckResult.ACCEPTED, pilot.texts()
        n_before = len(decisions(log))
        pilot.command(LAND_NOW)  # searching again, or approaching the next zone from afar: nothing to land on here
        assert answered(pilot, LAND_NOW) == AckResult.DENIED
        mavproxy.expect(r"Detected vehicle 1:191", 20)  # the companion's heartbeat
        mavproxy.send(console[0])  # signing key secret
        mavproxy.expect(r"Setup signing key", 10)
        # A new zone, and a descent over it (below 15 m: the go-around has somewhere to climb back to).
        wait_until(
            lambda: (
                any(d["phase"] == "descent" for d in decisions(log)[n_before:])
                and -sitl.state()["position_ned_m"][2] < 15.0
            ),
            180,
            "a descent over another zone",
        )
        mavproxy.send(console[1])  # long DO_GO_AROUND
        mavproxy.expect(r"Got COMMAND_ACK: DO_GO_AROUND: ACCEPTED", 30)
        _, err = fly.communicate(timeout=300)  # the landing goes on to its end
    finally:
        if fly.poll() is None:
            fly.kill()
        mavproxy.close()
        sitl.stop()
        pilot.poll()
        stranger.poll()
        pilot.close()
        stranger.close()
    assert fly.returncode == 0, err[-3000:]
    assert stranger.texts() == ["refused: not signed"]
    assert [t for t in pilot.texts() if t.startswith("land_now denied: ")]
    records = read_log(log)
    commands = [r for r in records if r["kind"] == "ground_command"]
    assert [(r["command"], r["result"]) for r in commands] == [
        ("reject_zone", "accepted"),
        ("land_now", "denied"),
        ("go_around", "accepted"),
    ]
    flown = decisions(log)
    by_operator = [d for d in flown if d["source"] == "operator"]
    assert [d["event"] for d in by_operator] == ["operator_reject", "operator_go_around"]
    # The rejected zone is not chosen again: every target after the rejection lies outside the refused radius.
    k = flown.index(by_operator[0])
    rejected = next(d["target"] for d in reversed(flown[:k]) if d["target"] is not None)
    later = [d["target"] for d in flown[k + 1 :] if d["target"] is not None and d["t_s"] - flown[k]["t_s"] < 60.0]
    assert later
    assert all(math.hypot(t["north_m"] - rejected["north_m"], t["east_m"] - rejected["east_m"]) >= 1.5 for t in later)
    # The go-around climbs: within 10 s of it the vehicle is 1.5 m higher than where it was sent.
    records_go = [r for r in records if r["kind"] == "decision" and r["source"] == "operator"][1]
    go_t_s, go_alt_m = records_go["t_s"], -records_go["state"]["down_m"]
    poses = [r for r in records if r["kind"] == "pose" and go_t_s < r["t_s"] <= go_t_s + 10.0]
    assert max(-p["down_m"] for p in poses) > go_alt_m + 1.5
    assert flown[-1]["phase"] == "done"
    # The flight replays identically, the ground station's decisions included.
    report = replay(tmp_path / "flight")
    assert report.identical, report.differences
