"""Ground-station commands to a companion flying the SITL: a pymavlink ground station sends signed and unsigned
COMMAND_LONGs to the companion's own component over real UDP, and the vehicle's behaviour is checked in its flight log
and the SITL's ground truth: go-around, reject, land-now (denied away from the target, and over a person the SITL puts
under the descent unless forced), the next fallback site. The logic of each command on hand-made maps:
tests/test_operator_commands.py and tests/test_fallback.py."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pytest

from companion.flightlog.recorder import read_log
from companion.ground import mavlink_frames as frames
from companion.ground.command_channel import AckResult
from companion.tools.replay import replay
from sitl.campaign.landing_kinds import LandingKind, landing_outcome_of_run
from sitl.config import SitlConfig
from sitl.harness.process import SitlProcess
from sitl.testing.helpers import (
    CompanionFlight,
    as_schema_2,
    free_udp_port,
    start_camera_sitl,
    wait_until,
    write_sitl_mission,
)
from tests.mavproxy_client import MavProxy
from tests.test_ground_channel import Gcs

pytestmark = pytest.mark.sitl

REPO_ROOT = Path(__file__).resolve().parent.parent
KEY = frames.key_from_passphrase("secret")  # docs/ground_station.md's passphrase
DOC = REPO_ROOT / "docs" / "ground_station.md"
GO_AROUND, REJECT, LAND_NOW, NEXT_SITE = 191, 31010, 31011, 31012


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


def answered(gcs: Gcs, mav_cmd: int, timeout_s: float = 30.0, nth: int = 1) -> int:
    """The final answer (not IN_PROGRESS) to the ``nth`` ``mav_cmd`` sent (the first by default)."""
    final = wait_until(
        lambda: [r for c, r in gcs.acks() if c == mav_cmd and r != AckResult.IN_PROGRESS][nth - 1 :],
        timeout_s,
        f"the answer to command {mav_cmd} (number {nth})",
    )
    return int(final[0])


def fly_with_commands(
    sitl: SitlProcess, tmp_path: Path, instance: int, port: int, guidance: str, ground_station: str = ""
) -> CompanionFlight:
    """``slz fly`` started against ``sitl`` with ``guidance`` lines and the command channel on ``port`` (unsigned,
    or as the further ``ground_station`` lines say), every frame saved for a replay."""
    section = f"ground_station:\n  command_url: udpin://127.0.0.1:{port}\n{ground_station}"
    mission = write_sitl_mission(tmp_path, instance, replayable=True, guidance=guidance, extra=section)
    return CompanionFlight(sitl, mission, tmp_path / "flight")


def test_signed_commands_reject_a_zone_and_go_around_unsigned_ones_are_refused_and_the_flight_replays(
    tmp_path: Path, instance: int
) -> None:
    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port(), lockstep=True)
    port = free_udp_port()
    sysid = SitlConfig(instance=instance).system_id  # the autopilot's, which the companion takes and answers on
    link_args, console = documented_mavproxy(port)
    link_args = [a.replace("--target-system=1", f"--target-system={sysid}") for a in link_args]
    assert console[:2] == ["signing key secret", "long DO_GO_AROUND"]
    pilot = Gcs(port, KEY, link_id=1, reply_key=KEY, vehicle_sysid=sysid)
    stranger = Gcs(port, reply_key=KEY, vehicle_sysid=sysid)
    signed = f"  signing_key_hex: {KEY.hex()}\n"
    with fly_with_commands(sitl, tmp_path, instance, port, "", signed) as fly, pilot, stranger:
        log = fly.log
        mavproxy = MavProxy(port, tmp_path, link_args)  # the pilot's console, as docs/ground_station.md writes it
        try:
            wait_until(lambda: any(d["phase"] == "approach" for d in decisions(log)), 180, "the first approach")
            mavproxy.start()
            stranger.command(GO_AROUND)  # unsigned: refused, and the vehicle flies on
            assert answered(stranger, GO_AROUND) == AckResult.DENIED
            # Land-now as the first approach starts, 19 m from its target: nothing to land here. (Not after the
            # rejection: the zone chosen next may lie right under the vehicle, and land-now would land on it.)
            pilot.command(LAND_NOW)
            assert answered(pilot, LAND_NOW) == AckResult.DENIED
            pilot.command(REJECT)
            assert answered(pilot, REJECT) == AckResult.ACCEPTED, pilot.texts()
            n_before = len(decisions(log))
            mavproxy.expect(rf"Detected vehicle {sysid}:191", 20)  # the companion's heartbeat, on the autopilot's id
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
            _, err = fly.finish(300)  # the landing goes on to its end
        finally:
            mavproxy.close()
    assert fly.returncode == 0, err[-3000:]
    assert stranger.texts() == ["refused: not signed"]
    assert [t for t in pilot.texts() if re.match(r"land_now denied: [\d.]+ m from the target", t)], pilot.texts()
    records = read_log(log)
    commands = [r for r in records if r["kind"] == "ground_command"]
    assert [(r["command"], r["result"]) for r in commands] == [
        ("go_around", "denied"),  # the stranger's, unsigned: refused, and recorded since issue 65
        ("land_now", "denied"),
        ("reject_zone", "accepted"),
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
    # The flight replays identically, the ground station's decisions included; so does its log as schema 2 wrote it
    # (each decision's inputs where schema 3 has its stimulus).
    report = replay(tmp_path / "flight")
    assert report.identical, report.differences
    older = replay(as_schema_2(tmp_path / "flight", tmp_path / "as_schema_2"))
    assert (older.identical, older.decisions) == (True, report.decisions), older.differences


def test_next_fallback_site_from_the_ground_station_flies_to_the_site_checks_it_and_lands_there(
    tmp_path: Path, instance: int
) -> None:
    site_ne_m = (21.0, -4.0)  # north of the crowd's ROI, inside the fence; the park keeps objects off it
    clear = {"clear_ne_m": [[*site_ne_m, 3.0]]}
    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port(), lockstep=True, scenario=clear)
    port = free_udp_port()
    site = f"{{name: lawn, north_m: {site_ne_m[0]}, east_m: {site_ne_m[1]}, radius_m: 3.0}}"
    pilot = Gcs(port, vehicle_sysid=SitlConfig(instance=instance).system_id)
    with fly_with_commands(sitl, tmp_path, instance, port, f"  fallback: {{sites: [{site}]}}") as fly, pilot:
        log = fly.log
        wait_until(lambda: any(d["phase"] == "approach" for d in decisions(log)), 180, "the first approach")
        pilot.command(NEXT_SITE)
        assert answered(pilot, NEXT_SITE) == AckResult.ACCEPTED, pilot.texts()
        pilot.command(NEXT_SITE)  # the only site is flown to: none left
        assert answered(pilot, NEXT_SITE, nth=2) == AckResult.DENIED
        _, err = fly.finish(300)
        truth = sitl.state()
    assert fly.returncode == 0, err[-3000:]
    assert [t for t in pilot.texts() if t.startswith("next_fallback denied: no fallback site left")]  # 50 characters
    commands = [r for r in read_log(log) if r["kind"] == "ground_command"]
    assert [(r["command"], r["result"]) for r in commands] == [
        ("next_fallback", "accepted"),
        ("next_fallback", "denied"),
    ]
    assert commands[1]["reason"] == "next_fallback denied: no fallback site left to try in reach"
    by_operator = [d for d in decisions(log) if d["source"] == "operator"]
    assert [(d["event"], d["cause"]) for d in by_operator] == [("fallback_site", "operator")]
    assert by_operator[0]["target"]["north_m"] == site_ne_m[0]
    outcome = landing_outcome_of_run(tmp_path / "flight")
    assert outcome.kind is LandingKind.FALLBACK_SITE
    north_m, east_m, _ = truth["position_ned_m"]
    assert math.hypot(north_m - site_ne_m[0], east_m - site_ne_m[1]) <= 1.5  # down at the site's centre
    report = replay(tmp_path / "flight")
    assert report.identical, report.differences


def test_land_now_over_a_person_at_the_walker_gate_is_denied_unless_forced_and_the_force_is_logged(
    tmp_path: Path, instance: int
) -> None:
    # People who may step away from a warning may be moved (none is sounded here): one is put under the descent.
    scenario = {"reaction": {"enabled": True}}
    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port(), lockstep=True, scenario=scenario)
    port = free_udp_port()
    # The person is seen from 12 m down to the gate: no abort on the way (the gate waits, as for a walker).
    pilot = Gcs(port, vehicle_sysid=SitlConfig(instance=instance).system_id)
    with fly_with_commands(sitl, tmp_path, instance, port, "  unsafe_frames_to_abort: 100") as fly, pilot:
        log = fly.log
        wait_until(
            lambda: any(d["phase"] == "descent" for d in decisions(log)) and -sitl.state()["position_ned_m"][2] < 12.0,
            180,
            "a descent below 12 m",
        )
        target = next(d["target"] for d in reversed(decisions(log)) if d["phase"] == "descent")
        placed = sitl.request({"cmd": "place_person", "north_m": target["north_m"], "east_m": target["east_m"]})
        assert "index" in placed, placed
        wait_until(
            lambda: any(d["event"] == "wait_at_gate" and d["cause"] == "person_in_footprint" for d in decisions(log)),
            120,
            "the descent waiting at the gate for the person in the footprint",
        )
        pilot.command(LAND_NOW)
        assert answered(pilot, LAND_NOW) == AckResult.DENIED
        pilot.command(LAND_NOW, param1=1.0)  # forced
        assert answered(pilot, LAND_NOW, nth=2) == AckResult.ACCEPTED
        _, err = fly.finish(300)
        truth = sitl.state()
    assert fly.returncode == 0, err[-3000:]
    assert [t for t in pilot.texts() if t.startswith("land_now denied: a person in the footprint")]
    commands = [r for r in read_log(log) if r["kind"] == "ground_command"]
    assert [(r["result"], r["force"], r["person_seen"]) for r in commands] == [
        ("denied", False, True),
        ("accepted", True, True),
    ]
    by_operator = [d for d in decisions(log) if d["source"] == "operator"]
    assert [(d["event"], d["kind"]) for d in by_operator] == [("operator_land", "land")]
    assert "(forced: a person in the footprint on the newest map)" in by_operator[0]["reason"]
    assert decisions(log)[-1]["phase"] == "done"
    north_m, east_m, _ = truth["position_ned_m"]  # landed where the operator forced it
    assert math.hypot(north_m - target["north_m"], east_m - target["east_m"]) <= 1.5
    report = replay(tmp_path / "flight")
    assert report.identical, report.differences
