"""Helpers for SITL tests: waiting on conditions with deadlines, a pymavlink ground station, a lockstep client."""

from __future__ import annotations

import asyncio
import json
import math
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, TypeVar

from pymavlink.dialects.v20 import common as mavlink

from sitl.config import API_PORT_REMOTE, GCS_PORT_REMOTE, SitlConfig
from sitl.harness.lockstep import LockstepControl
from sitl.harness.process import SitlProcess

T = TypeVar("T")

REPO_ROOT = Path(__file__).resolve().parents[2]
SITL_MISSION_CONFIG = REPO_ROOT / "mission_configs" / "sitl.yaml"


def sitl_mission_yaml(
    instance: int, flights_dir: Path | None = None, replayable: bool = False, guidance: str = ""
) -> str:
    """mission_configs/sitl.yaml on SITL instance ``instance``'s ports (MAVSDK, camera, control channel). A SITL
    started without ``--lockstep`` answers the control channel with "running free": the companion runs free too.
    ``replayable``: every frame saved, losslessly (PNG), so that ``slz replay`` can re-run the flight. ``guidance``:
    YAML lines (indented by two) put first in its ``guidance`` section."""
    text = SITL_MISSION_CONFIG.read_text()
    if guidance:
        assert "\nguidance:\n" in text
        text = text.replace("\nguidance:\n", f"\nguidance:\n{guidance.rstrip()}\n")
    if replayable:
        assert "frame_every: 10" in text
        assert "frame_format: jpeg" in text
        text = text.replace("frame_every: 10", "frame_every: 1").replace("frame_format: jpeg", "frame_format: png")
    # Written elsewhere, its relative paths would be taken from there: the flights go to ``flights_dir``, or where the
    # shipped file says.
    flights = flights_dir or SITL_MISSION_CONFIG.parent.parent / "runs" / "flights"
    assert "directory: ../runs/flights" in text
    text = text.replace("directory: ../runs/flights", f"directory: {flights}")
    text = text.replace("udpin://0.0.0.0:14540", f"udpin://0.0.0.0:{14540 + instance}")
    text = text.replace("sitl://127.0.0.1:5600", f"sitl://127.0.0.1:{5600 + instance}")
    return text.replace("udp://127.0.0.1:4560", f"udp://127.0.0.1:{4560 + instance}")


def slz_fly_argv(mission: Path, out_dir: Path) -> list[str]:
    """The command line of ``slz fly --config MISSION --out OUT_DIR`` in this interpreter (a real companion process)."""
    return [sys.executable, "-m", "companion.cli", "fly", "--config", str(mission), "--out", str(out_dir)]


def write_sitl_mission(
    tmp_path: Path, instance: int, replayable: bool = False, guidance: str = "", extra: str = ""
) -> Path:
    """:func:`sitl_mission_yaml` written to ``tmp_path/mission.yaml``, its flights under ``tmp_path``, with ``extra``
    (whole YAML sections) appended; the file's path."""
    mission = tmp_path / "mission.yaml"
    mission.write_text(
        sitl_mission_yaml(instance, flights_dir=tmp_path, replayable=replayable, guidance=guidance) + extra
    )
    return mission


class CompanionFlight:
    """``slz fly`` as a real process against a SITL, the scaffold every SITL-flight test shares: started at once, its
    output kept (``capture``) or dropped, and on leaving the ``with`` block killed if it still runs and the SITL
    stopped, whatever the test's outcome.

    Parameters
    ----------
    sitl : SitlProcess
        The SITL it flies (stopped on leaving).
    mission : Path
        Its mission file (:func:`write_sitl_mission`).
    out_dir : Path
        Its flight folder (``--out``); the flight log is ``out_dir / "flight.jsonl"``.
    *args : str
        More of ``slz fly``'s options (``--replayable``, ``--dry-run``...).
    """

    def __init__(self, sitl: SitlProcess, mission: Path, out_dir: Path, *args: str, capture: bool = True) -> None:
        self.sitl = sitl
        self.log = out_dir / "flight.jsonl"
        output = subprocess.PIPE if capture else subprocess.DEVNULL
        self.process = subprocess.Popen(
            [*slz_fly_argv(mission, out_dir), *args], cwd=REPO_ROOT, stdout=output, stderr=output, text=True
        )

    def __enter__(self) -> CompanionFlight:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        try:
            if self.process.poll() is None:
                self.process.kill()
                self.process.communicate(timeout=30)
        finally:
            self.sitl.stop()

    def logged(self, text: str) -> bool:
        """Whether the flight log holds ``text`` yet (a condition for :func:`wait_until`)."""
        return self.log.is_file() and text in self.log.read_text()

    def finish(self, timeout_s: float) -> tuple[str, str]:
        """Wait for the program's end (``timeout_s``): its standard output and error."""
        out, err = self.process.communicate(timeout=timeout_s)
        return out or "", err or ""

    @property
    def returncode(self) -> int | None:
        """The program's exit status (None while it runs)."""
        return self.process.returncode


@dataclass(frozen=True)
class FlownMission:
    """A whole ``slz fly`` run (:func:`fly_to_the_end`): its exit status, output and the SITL's truth at its end."""

    returncode: int | None
    stdout: str
    stderr: str
    truth: dict[str, Any]


def fly_to_the_end(
    sitl: SitlProcess, mission: Path, out_dir: Path, *args: str, timeout_s: float = 300.0
) -> FlownMission:
    """Fly ``mission`` with ``slz fly`` against ``sitl`` until the program ends (``timeout_s``), read the SITL's state
    then, and stop the SITL."""
    with CompanionFlight(sitl, mission, out_dir, *args) as fly:
        out, err = fly.finish(timeout_s)
        truth = sitl.state()
    return FlownMission(fly.returncode, out, err, truth)


def as_schema_2(flight_dir: Path, out_dir: Path) -> Path:
    """The flight log in ``flight_dir`` written again in ``out_dir`` as flight-log schema 2 wrote it: each decision's
    ``stimulus`` back to ``inputs`` (without its type) and the header's version 2; the saved frames shared (a link).
    What an older log looks like, for the tests that replay one."""
    out_dir.mkdir(parents=True)
    lines = []
    for line in (flight_dir / "flight.jsonl").read_text().splitlines():
        record = json.loads(line)
        if record.get("kind") == "header":
            record["schema_version"] = 2
        if record.get("kind") == "decision":
            stimulus = record.pop("stimulus")
            stimulus.pop("type")
            record["inputs"] = stimulus
        lines.append(json.dumps(record))
    (out_dir / "flight.jsonl").write_text("\n".join(lines) + "\n")
    (out_dir / "frames").symlink_to((flight_dir / "frames").resolve(), target_is_directory=True)
    return out_dir


def run_python(*args: str, timeout_s: float = 120.0) -> subprocess.CompletedProcess[str]:
    """``python ARGS`` in this interpreter from the repository's root (a script, ``-m companion.cli ...``): a real
    process, its output captured, its exit status left to the test."""
    return subprocess.run(
        [sys.executable, *args], cwd=REPO_ROOT, capture_output=True, text=True, timeout=timeout_s, check=False
    )


def free_udp_port() -> int:
    """A UDP port free now on loopback (for a ground station: every SITL instance would send to 14550)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_until(condition: Callable[[], T | None], timeout_s: float, what: str, poll_s: float = 0.05) -> T:
    """Poll ``condition`` until it returns something truthy; fail with ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(poll_s)


async def wait_until_async(condition: Callable[[], T | None], timeout_s: float, what: str, poll_s: float = 0.05) -> T:
    """:func:`wait_until` inside an event loop: the loop runs between polls (a flight under test keeps flying)."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        await asyncio.sleep(poll_s)


def start_camera_sitl(
    tmp_path: Path,
    instance: int,
    seed: int,
    gcs_port: int,
    lockstep: bool = False,
    scenario: dict[str, Any] | None = None,
) -> SitlProcess:
    """A SITL instance with its camera on, seeded, its ground-station link on ``gcs_port`` (``tmp_path/sitl.yaml``);
    in lockstep (``speed_factor`` 0: the companion's acknowledgements pace it) or running free; ``scenario``: its
    scenario's settings (the defaults otherwise)."""
    lines = ["sitl:", "  camera:", "    enabled: true", f"  seed: {seed}", f"  gcs_port_remote: {gcs_port}"]
    if lockstep:
        lines += ["  lockstep: true", "  speed_factor: 0.0"]
    if scenario is not None:
        lines.append(f"  scenario: {json.dumps(scenario)}")  # JSON is YAML's flow style
    config = tmp_path / "sitl.yaml"
    config.write_text("\n".join(lines) + "\n")
    return SitlProcess(["--config", str(config)], instance, tmp_path).start()


def state_when(
    sitl: SitlProcess, predicate: Callable[[dict[str, Any]], bool], timeout_s: float, what: str
) -> dict[str, Any]:
    """The SITL's ground truth once ``predicate`` holds for it."""

    def check() -> dict[str, Any] | None:
        state = sitl.state()
        return state if predicate(state) else None

    return wait_until(check, timeout_s, what)


class MavlinkPeer:
    """A raw-UDP MAVLink peer bound to ``port`` (the side MAVSDK or a ground station would be)."""

    def __init__(self, port: int, system_id: int = 255, component_id: int = 190, only_sysid: int | None = None) -> None:
        self.only_sysid = only_sysid
        """Listen to this vehicle only (other SITL instances send to the same GCS port, as PX4's do)."""
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self.sock.bind(("127.0.0.1", port))
        self.sock.setblocking(False)
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.mav.robust_parsing = True
        self.vehicle_addr: tuple[str, int] | None = None
        self.vehicle_sysid = 1
        self.messages: list[Any] = []
        self.heartbeat_wall_times: list[float] = []
        self.sent = 0

    def poll(self) -> list[Any]:
        """Read everything waiting; returns the new messages."""
        new: list[Any] = []
        while True:
            try:
                data, addr = self.sock.recvfrom(65535)
            except BlockingIOError:
                break
            msgs = self.mav.parse_buffer(data) or []
            if self.only_sysid is not None and any(m.get_srcSystem() != self.only_sysid for m in msgs):
                continue
            self.vehicle_addr = addr
            for msg in msgs:
                if msg.get_type() == "HEARTBEAT":
                    self.heartbeat_wall_times.append(time.monotonic())
                    self.vehicle_sysid = msg.get_srcSystem()
                new.append(msg)
        self.messages.extend(new)
        return new

    def latest(self, kind: str) -> Any:
        """The most recent message of a type (None if none yet)."""
        self.poll()
        for msg in reversed(self.messages):
            if msg.get_type() == kind:
                return msg
        return None

    def send(self, msg: Any) -> None:
        """Send to the vehicle (once it has been heard)."""
        assert self.vehicle_addr is not None, "the vehicle has not been heard yet"
        buf = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        self.sock.sendto(buf, self.vehicle_addr)
        self.sent += 1

    def send_raw(self, data: bytes) -> None:
        """Send arbitrary bytes (malformed input tests)."""
        assert self.vehicle_addr is not None
        self.sock.sendto(data, self.vehicle_addr)

    def command(self, command: int, *params: float, timeout_s: float = 2.0) -> int:
        """COMMAND_LONG to the autopilot; returns the ACK's result."""
        p = [*params, *([0.0] * (7 - len(params)))]
        self.messages.clear()
        self.send(self.mav.command_long_encode(self.vehicle_sysid, 1, command, 0, *p))

        def ack() -> Any:
            for msg in self.poll():
                if msg.get_type() == "COMMAND_ACK" and msg.command == command:
                    return msg
            return None

        return int(wait_until(ack, timeout_s, f"COMMAND_ACK for {command}", poll_s=0.01).result)

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()


class GroundStation(MavlinkPeer):
    """A pymavlink ground station on a SITL's GCS link that listens to that instance's vehicle only.

    Every instance sends to the same GCS port (14550), as PX4's do, so tests give their SITL its own
    ``gcs_port_remote`` (:func:`free_udp_port`); a message from another vehicle is dropped all the same.
    """

    def __init__(self, instance: int, port: int = GCS_PORT_REMOTE) -> None:
        super().__init__(port, system_id=255, component_id=190, only_sysid=SitlConfig(instance=instance).system_id)


def api_port(instance: int) -> int:
    """MAVSDK's port for a SITL instance."""
    return API_PORT_REMOTE + instance


class LockstepClient:
    """Drives a lockstep SITL from the API link: at each tick, send this tick's MAVLink, then acknowledge."""

    def __init__(self, instance: int, system_id: int = 245, component_id: int = 190) -> None:
        self.peer = MavlinkPeer(api_port(instance), system_id, component_id)
        self.control = LockstepControl(instance, system_id, component_id)

    def subscribe(self, timeout_s: float = 10.0) -> None:
        """Register for ticks and wait for the vehicle's heartbeat (its system id; telemetry may come first)."""
        self.control.subscribe()
        wait_until(lambda: self.peer.poll() is not None and self.peer.heartbeat_wall_times, timeout_s, "a heartbeat")

    def next_tick(self, timeout_s: float = 10.0) -> dict[str, Any]:
        """Wait for the next tick event."""
        return self.control.next_tick(timeout_s)

    def ack(self, seq: int) -> None:
        """Acknowledge tick ``seq``, stating how many MAVLink messages were sent before it."""
        self.control.ack(seq, self.peer.sent)

    def close(self) -> None:
        """Close both sockets."""
        self.peer.close()
        self.control.close()


def position_setpoint(
    mav: Any, north_m: float, east_m: float, down_m: float, yaw_rad: float = math.nan, target_system: int = 1
) -> Any:
    """SET_POSITION_TARGET_LOCAL_NED with position (and yaw when given), as MAVSDK sends it."""
    mask = 0b0000_1111_1111_1000 if math.isnan(yaw_rad) else 0b0000_1001_1111_1000
    return mav.set_position_target_local_ned_encode(
        0,
        target_system,
        1,
        mavlink.MAV_FRAME_LOCAL_NED,
        mask,
        north_m,
        east_m,
        down_m,
        0,
        0,
        0,
        0,
        0,
        0,
        0.0 if math.isnan(yaw_rad) else yaw_rad,
        0,
    )


class ListeningGroundStation:
    """A ground station that only listens, on its own thread, for the length of a ``with`` block (a mission flown by
    :func:`sitl.harness.mission.fly` blocks the test's thread). Keeps every message from any system: the vehicle and the
    companion behind it."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.messages: list[Any] = []
        self._stop = threading.Event()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self._sock.bind(("127.0.0.1", port))
        self._sock.settimeout(0.1)
        self._mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self._mav.robust_parsing = True
        self._thread = threading.Thread(target=self._listen, name=f"gcs-{port}", daemon=True)

    def _listen(self) -> None:
        while not self._stop.is_set():
            try:
                data, _ = self._sock.recvfrom(65535)
            except TimeoutError:
                continue
            except OSError:
                return
            self.messages.extend(m for m in self._mav.parse_buffer(data) or [] if m.get_type() != "BAD_DATA")

    def __enter__(self) -> ListeningGroundStation:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._sock.close()

    def of(self, kind: str, system_id: int | None = None) -> list[Any]:
        """The messages of one type (from one system when given), in arrival order."""
        return [m for m in self.messages if m.get_type() == kind and system_id in (None, m.get_srcSystem())]


def pilot_takes_off(
    sitl: SitlProcess, gcs: GroundStation, instance: int, altitude_m: float, then_modes: tuple[str, ...] = ()
) -> None:
    """The pilot (a ground station) arms and takes off; returns once the vehicle holds at ``altitude_m``, or is
    already in one of ``then_modes`` there (a companion waiting for the hold may take over before a poll sees it)."""
    wait_until(lambda: gcs.poll() is not None and gcs.vehicle_addr, 10, "the vehicle on the GCS link")
    sysid = SitlConfig(instance=instance).system_id  # PX4 style: instance + 1

    def armed() -> bool:  # the pre-arm checks pass a moment after start: the pilot retries, as pilots do
        gcs.send(gcs.mav.command_long_encode(sysid, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
        return bool(sitl.state()["armed"])

    wait_until(armed, 15, f"the pilot arming vehicle {sysid}")
    takeoff_amsl_m = SitlConfig().origin_alt_m + altitude_m
    gcs.send(gcs.mav.command_long_encode(sysid, 1, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, takeoff_amsl_m))
    state_when(
        sitl,
        lambda st: st["mode"] in ("AUTO.LOITER", *then_modes) and st["position_ned_m"][2] < -(altitude_m - 1.0),
        30,
        f"hover at {altitude_m:g} m",
    )
