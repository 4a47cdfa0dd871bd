"""FlightApp's supervision with a fake vehicle link and camera, in milliseconds: the pilot's takeover, a lost link,
a silent camera and a stalled decision loop. The same behaviours flown end to end are in
tests/test_companion_missions.py and tests/test_companion_fly.py."""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from companion.app.drivers import FreeRunningDriver
from companion.app.flight import FlightApp
from companion.app.mission import MissionConfig
from companion.camera.frames import CameraError, CameraFault, Frame
from companion.flightlog.recorder import FlightRecorder, read_log
from companion.guidance.landing import LandingPhase
from companion.perception.config import PerceptionConfig
from companion.perception.pipeline import SlzPipeline
from companion.vehicle.clock import VehicleClock
from companion.vehicle.ground_messages import GroundMessage
from companion.vehicle.link import FlightMode, LinkResult, Setpoint, VehicleError, VehicleStatus
from companion.vehicle.pose_buffer import PoseBuffer

pytestmark = pytest.mark.unit

ALTITUDE_M = 20.0


class FakeOffboard:
    """The fake's offboard part: each call recorded on the link, OFFBOARD accepted at once."""

    def __init__(self, link: FakeLink) -> None:
        self.link = link

    async def start(self, setpoint: Setpoint) -> None:
        self.link.commands.append(("start_offboard", setpoint))
        self.link.status.mode = FlightMode.OFFBOARD  # the autopilot accepts

    async def set_setpoint(self, setpoint: Setpoint) -> None:
        self.link.commands.append(("setpoint", setpoint))

    async def stop(self) -> None:
        self.link.commands.append(("stop_offboard", None))

    def stop_blocking(self) -> None:
        self.link.stopped_from_thread.set()


class FakeGround:
    """The fake's ground part: each message kept as a ground station would see it (its name and fields)."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, dict[str, Any]]] = []

    async def send(self, message: GroundMessage) -> None:
        self.sent.append((message.message_name, dict(message.fields())))


class FakeLink:
    """A VehicleLink that records every command; the test moves the vehicle and sets its mode. It is its own
    telemetry, action, mission and params parts; its offboard and ground parts record on it."""

    name = "fake"
    system_id = 1

    def __init__(self) -> None:
        self.poses = PoseBuffer()
        self.clock = VehicleClock()
        self.status = VehicleStatus(mode=FlightMode.HOLD, armed=True, in_air=True, last_telemetry_wall_s=None)
        self.commands: list[tuple[str, Any]] = []
        self.stopped_from_thread = threading.Event()
        self.telemetry = self.action = self.mission = self.params = self
        self.offboard = FakeOffboard(self)
        self.ground = FakeGround()

    def at(self, t_s: float, north_m: float = 0.0, east_m: float = 0.0, altitude_m: float = ALTITUDE_M) -> None:
        """A pose sample at vehicle time ``t_s`` (level, facing north) and fresh telemetry."""
        self.poses.add_position(t_s, north_m, east_m, -altitude_m)
        self.poses.add_attitude(t_s, [1.0, 0.0, 0.0, 0.0])
        self.clock.observe(t_s)
        self.status.last_telemetry_wall_s = time.monotonic()

    async def connect(self, timeout_s: float) -> None:
        """Connected at once: the fake is its own autopilot."""

    async def wait_for(self, condition: Callable[[], bool], deadline: float, what: str) -> None:
        if not condition():
            raise VehicleError(self.name, f"{what} did not happen", LinkResult.TIMEOUT)

    async def arm_and_takeoff(self, altitude_m: float, timeout_s: float) -> None:
        self.commands.append(("arm_and_takeoff", altitude_m))

    async def take_off(self, altitude_m: float) -> None:
        self.commands.append(("take_off", altitude_m))

    async def land(self) -> None:
        self.commands.append(("land", None))
        self.status.mode = FlightMode.LAND

    async def hold(self) -> None:
        self.commands.append(("hold", None))
        self.status.mode = FlightMode.HOLD

    async def return_to_launch(self) -> None:
        self.commands.append(("return", None))

    async def set_actuator(self, index: int, value: float) -> None:
        self.commands.append(("actuator", (index, value)))

    async def global_origin(self, timeout_s: float) -> tuple[float, float]:
        """The EKF origin these tests fly from (Zurich, PX4's SITL default)."""
        return 47.397742, 8.545594

    async def rally_points(self, timeout_s: float) -> list[tuple[float, float]]:
        """None uploaded."""
        return []

    async def read_all(self, timeout_s: float = 15.0) -> dict[str, float] | None:
        """No parameters."""
        return None

    async def close(self) -> None:
        """Nothing to release."""


class NoFrames:
    """A camera that opens and then delivers nothing."""

    async def open(self) -> None:
        """Opens at once."""

    async def frames(self) -> AsyncIterator[Frame]:
        await asyncio.Event().wait()
        yield  # type: ignore[misc]  # never reached: an async generator that waits for ever


def field_flight(tmp_path: Path, config: PerceptionConfig, link: FakeLink) -> FlightApp:
    """A field flight (the pilot hands over in HOLD at 20 m) with the blob model, over ``link``; T2's failsafe is the
    SITL's land (the default is hold)."""
    mission = MissionConfig.model_validate(
        {
            "start": {"arm_and_takeoff": False},
            "guidance": {"failsafe_action": "land"},
            "perception": config.model_dump(mode="json"),
            "recorder": {"directory": str(tmp_path), "frame_every": 0},
        }
    )
    return FlightApp(mission, link, NoFrames(), SlzPipeline.from_config(mission.perception), FlightRecorder(tmp_path))


@pytest.fixture
def app_and_link(tmp_path: Path, config: PerceptionConfig) -> tuple[FlightApp, FakeLink]:
    link = FakeLink()
    return field_flight(tmp_path, config, link), link


async def hand_over(app: FlightApp, link: FakeLink, t_s: float = 1.0) -> None:
    """The pilot hovers in HOLD: the companion takes over and starts its search in OFFBOARD."""
    link.at(t_s)
    state = app.vehicle_state()
    assert state is not None
    await app.on_tick(state)
    assert link.commands[0][0] == "start_offboard"
    assert app.landing.guidance.phase is LandingPhase.SEARCH


async def tick(
    app: FlightApp, link: FakeLink, t_s: float, north_m: float = 0.0, altitude_m: float = ALTITUDE_M
) -> None:
    link.at(t_s, north_m=north_m, altitude_m=altitude_m)
    state = app.vehicle_state()
    assert state is not None
    await app.on_tick(state)


async def test_the_pilot_switching_mode_ends_commanding_at_once_and_for_good(app_and_link: Any) -> None:
    app, link = app_and_link

    await hand_over(app, link)
    link.status.mode = FlightMode.POSCTL  # the pilot's switch
    sent = len(link.commands)
    await tick(app, link, 1.1)
    assert app.landing.guidance.phase is LandingPhase.YIELDED
    for k in range(20):  # whatever happens next, nothing more goes out
        link.status.mode = FlightMode.HOLD if k % 2 else FlightMode.OFFBOARD
        await tick(app, link, 1.2 + 0.1 * k)
    assert len(link.commands) == sent
    assert app.outcome.phase == "yielded"
    assert "pilot took over (mode POSCTL)" in app.outcome.reason


class PilotRightAfterOffboardLink(FakeLink):
    """The autopilot enters OFFBOARD and the pilot switches to POSCTL before the companion reads the telemetry: both
    reports arrive in one batch, so the companion only ever sees POSCTL (and the entry counted). Until ``ack`` is set
    the OFFBOARD request waits for its acknowledgement."""

    def __init__(self) -> None:
        super().__init__()
        self.requested = asyncio.Event()
        self.ack = asyncio.Event()
        self.offboard = PilotRightAfterOffboard(self)


class PilotRightAfterOffboard(FakeOffboard):
    """OFFBOARD acknowledged when the test says, reported together with the pilot's mode."""

    link: PilotRightAfterOffboardLink

    async def start(self, setpoint: Setpoint) -> None:
        link = self.link
        link.commands.append(("start_offboard", setpoint))
        link.requested.set()
        await link.ack.wait()
        link.status.offboard_entries += 1  # the report of OFFBOARD ...
        link.status.mode = FlightMode.POSCTL  # ... and the pilot's, read together


async def test_a_pilot_who_takes_over_while_offboard_starts_gets_the_vehicle_and_keeps_it(
    tmp_path: Path, config: PerceptionConfig
) -> None:
    link = PilotRightAfterOffboardLink()
    app = field_flight(tmp_path, config, link)
    silence_s = app.config.guidance.hold_after_silence_s

    handover = asyncio.create_task(tick(app, link, 1.0))  # the search starts: OFFBOARD requested
    await asyncio.wait_for(link.requested.wait(), 5.0)
    # Meanwhile the other loop decides too (the camera is silent: hold on the spot, a setpoint). It must not ask
    # for OFFBOARD a second time while the first request is still out.
    second = asyncio.create_task(tick(app, link, 1.0 + silence_s + 0.2))
    for _ in range(100):  # until it has decided to hold and waits for the first command to go out
        if app.outcome.phase == LandingPhase.HOLD.value:
            break
        await asyncio.sleep(0)  # one turn of the event loop
    assert app.outcome.phase == LandingPhase.HOLD.value
    link.ack.set()
    await asyncio.wait_for(asyncio.gather(handover, second), 5.0)
    for k in range(10):  # the ticks that follow see the pilot's mode
        await tick(app, link, 2.5 + 0.1 * k)
    assert [kind for kind, _ in link.commands] == ["start_offboard"]  # no second OFFBOARD, no setpoint after
    assert app.outcome.phase == "yielded"
    assert "pilot took over (mode POSCTL)" in app.outcome.reason


async def test_a_silent_camera_holds_after_t1_and_lands_after_t2(app_and_link: Any, tmp_path: Path) -> None:
    app, link = app_and_link
    t1 = app.config.guidance.hold_after_silence_s
    t2 = app.config.guidance.failsafe_after_silence_s
    start_s, period_s = 10.0, 0.1

    async def flight() -> tuple[float, Any, float]:
        await hand_over(app, link, t_s=start_s)
        hold: tuple[float, Any] | None = None
        t_s = start_s
        while app.landing.guidance.phase is not LandingPhase.FAILSAFE and t_s < start_s + t2 + 2.0:
            t_s = round(t_s + period_s, 3)
            await tick(app, link, t_s)
            if hold is None and app.landing.guidance.phase is LandingPhase.HOLD:
                hold = (t_s, link.commands[-1])
        assert hold is not None, "never held"
        return hold[0], hold[1], t_s

    hold_at, hold_command, failsafe_at = await flight()
    # T1: hold where it is (a setpoint on the spot, still in OFFBOARD); T2: the configured failsafe, land.
    assert start_s + t1 <= hold_at <= start_s + t1 + period_s + 1e-9
    kind, setpoint = hold_command
    assert kind == "setpoint"
    assert (setpoint.north_m, setpoint.east_m, setpoint.down_m) == pytest.approx((0.0, 0.0, -ALTITUDE_M), abs=1e-6)
    assert start_s + t2 <= failsafe_at <= start_s + t2 + period_s + 1e-9
    assert link.commands[-1] == ("land", None)
    assert app.outcome.failsafes
    phases = [r["phase"] for r in read_log(tmp_path / "flight.jsonl") if r["kind"] == "phase"]
    assert phases[-2:] == ["hold", "failsafe"]


async def test_telemetry_silent_past_its_limit_is_a_lost_link_and_nothing_more_is_sent(app_and_link: Any) -> None:
    app, link = app_and_link

    await hand_over(app, link)
    sent = len(link.commands)
    link.status.last_telemetry_wall_s = time.monotonic() - 2 * app.config.vehicle.link_lost_after_s
    await asyncio.wait_for(FreeRunningDriver(app).ticks(), 5.0)
    assert len(link.commands) == sent
    assert app.outcome.link_lost
    assert app.done.is_set()


async def test_a_stalled_decision_loop_stops_offboard_from_the_watchdog_thread(app_and_link: Any) -> None:
    app, link = app_and_link
    await hand_over(app, link)
    assert app.commands.in_offboard
    app.watchdog.clock = lambda: time.monotonic() + 10.0  # the event loop has not beaten for 10 s
    app.watchdog.start()
    try:
        assert link.stopped_from_thread.wait(timeout=5.0)  # within a quarter of the limit, on a free machine
    finally:
        app.watchdog.stop()
    assert not app.commands.in_offboard
    assert not app.commands.commanding
    assert not app.watchdog.check()  # disengaged: once is enough


class Clock:
    """A wall clock the test moves (the wall limit's only input)."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def limited_flight(tmp_path: Path, config: PerceptionConfig, **guidance: object) -> tuple[FlightApp, FakeLink, Clock]:
    """A field flight as :func:`field_flight` with a wall limit of 300 s: the app, its fake link and its wall clock."""
    link, clock = FakeLink(), Clock()
    mission = MissionConfig.model_validate(
        {
            "start": {"arm_and_takeoff": False},
            "guidance": guidance,
            "perception": config.model_dump(mode="json"),
            "recorder": {"directory": str(tmp_path), "frame_every": 0},
        }
    )
    pipeline = SlzPipeline.from_config(mission.perception)
    app = FlightApp(mission, link, NoFrames(), pipeline, FlightRecorder(tmp_path), wall_limit_s=300.0, wall_clock=clock)
    return app, link, clock


def supervision(tmp_path: Path) -> list[tuple[str, str]]:
    return [(r["event"], r["reason"]) for r in read_log(tmp_path / "flight.jsonl") if r["kind"] == "supervision"]


async def test_a_wall_limit_in_flight_holds_and_the_program_stays_until_the_pilot_has_the_vehicle(
    tmp_path: Path, config: PerceptionConfig
) -> None:
    app, link, clock = limited_flight(tmp_path, config)

    await hand_over(app, link)
    await tick(app, link, 1.1)
    assert app.landing.guidance.phase is LandingPhase.SEARCH
    clock.now_s = 300.0  # the wall limit, mid-flight
    await tick(app, link, 1.2)
    assert link.commands[-1] == ("hold", None)  # the last resort, at once: never the offboard-loss failsafe
    assert app.outcome.phase == LandingPhase.FAILSAFE.value
    sent = len(link.commands)
    for k in range(50):  # holding: the program stays, watches and sends nothing more
        await tick(app, link, 1.3 + 0.1 * k)
        assert not app.done.is_set()
    assert len(link.commands) == sent
    link.status.mode = FlightMode.POSCTL  # the pilot takes the vehicle
    await tick(app, link, 7.0)
    assert app.done.is_set()
    assert len(link.commands) == sent
    assert app.outcome.phase == "failsafe"
    assert "wall limit of 300 s reached (slz fly --timeout): hold" in app.outcome.reason
    assert app.outcome.reason.endswith("the pilot has it (mode POSCTL)")
    events = supervision(tmp_path)
    assert [e for e, _ in events] == ["watching", "pilot_has_it"]
    decisions = [r for r in read_log(tmp_path / "flight.jsonl") if r["kind"] == "decision"]
    assert decisions[-1]["source"] == "limit"


async def test_a_wall_limit_with_return_as_last_resort_watches_the_return_down_to_the_ground(
    tmp_path: Path, config: PerceptionConfig
) -> None:
    app, link, clock = limited_flight(tmp_path, config, last_resort="return")

    await hand_over(app, link)
    clock.now_s = 1000.0
    await tick(app, link, 1.1)
    assert link.commands[-1] == ("return", None)
    link.status.mode = FlightMode.RETURN_TO_LAUNCH
    for k in range(20):
        await tick(app, link, 1.2 + 0.1 * k, north_m=-0.5 * k)
    link.status.mode = FlightMode.LAND  # PX4's return ends in its own landing: still the failsafe's
    await tick(app, link, 3.5, north_m=-10.0, altitude_m=3.0)
    assert not app.done.is_set()
    link.status.in_air = False
    await tick(app, link, 9.0, north_m=-10.0, altitude_m=0.0)
    assert app.done.is_set()
    assert app.outcome.touchdown_ne_m == pytest.approx((-10.0, 0.0))
    assert app.outcome.reason.endswith("on the ground at north -10.0 m, east 0.0 m")
    assert [e for e, _ in supervision(tmp_path)] == ["watching", "on_ground"]


async def test_a_wall_limit_before_the_handover_ends_the_run_and_commands_nothing(
    tmp_path: Path, config: PerceptionConfig
) -> None:
    app, link, clock = limited_flight(tmp_path, config)
    link.status.mode = FlightMode.POSCTL  # the pilot flies and has not handed over

    await tick(app, link, 1.0)
    clock.now_s = 301.0
    await tick(app, link, 1.1)
    assert app.done.is_set()
    assert link.commands == []
    assert app.outcome.reason == "wall limit of 300 s reached (slz fly --timeout): nothing commanded, the run ends"


async def test_a_dry_run_on_the_bench_waits_decides_in_the_air_and_ends_once_the_vehicle_is_down_and_disarmed(
    tmp_path: Path, config: PerceptionConfig
) -> None:
    link = FakeLink()
    link.status = VehicleStatus(mode=FlightMode.MANUAL, armed=False, in_air=False)
    mission = MissionConfig.model_validate(
        {
            "mode": "dry_run",
            "start": {"arm_and_takeoff": False},
            "perception": config.model_dump(mode="json"),
            "recorder": {"directory": str(tmp_path), "frame_every": 0},
        }
    )
    app = FlightApp(mission, link, NoFrames(), SlzPipeline.from_config(mission.perception), FlightRecorder(tmp_path))
    t2 = mission.guidance.failsafe_after_silence_s

    for k in range(300):  # 30 s on the bench: no failsafe, no start
        await tick(app, link, 0.1 * k, altitude_m=0.0)
    assert app.landing.guidance.phase is LandingPhase.IDLE
    link.status.armed = link.status.in_air = True
    await tick(app, link, 31.0, altitude_m=1.0)  # the head plane (1.7 m up) not yet below the camera
    assert app.landing.guidance.phase is LandingPhase.IDLE
    t_s = 32.0
    await tick(app, link, t_s)  # 20 m: deciding starts
    assert app.outcome.phase == LandingPhase.SEARCH.value
    while app.outcome.phase != LandingPhase.FAILSAFE.value:  # a silent camera: the failsafe it would take ...
        assert t_s < 32.0 + t2 + 1.0
        t_s = round(t_s + 0.1, 3)
        await tick(app, link, t_s)
    assert "perception silent" in " ".join(app.outcome.failsafes)
    await tick(app, link, t_s + 0.1)  # ... is logged, and it decides again while the pilot flies on
    await tick(app, link, t_s + 0.2)
    assert app.outcome.phase == LandingPhase.SEARCH.value
    assert not app.done.is_set()
    link.status.in_air = False  # the pilot lands ...
    await tick(app, link, t_s + 5.0, altitude_m=0.0)
    assert not app.done.is_set()
    link.status.armed = False  # ... and disarms: the flight is over
    await tick(app, link, t_s + 7.0, altitude_m=0.0)
    assert app.done.is_set()
    assert link.commands == []
    records = read_log(tmp_path / "flight.jsonl")
    waits = [r["waiting_for"] for r in records if r["kind"] == "waiting"]
    assert waits[:2] == ["the vehicle armed and in the air", "the head plane in view (in the air at 1.0 m)"]
    starts = [r for r in records if r["kind"] == "decision" and r["source"] == "start"]
    assert len(starts) >= 2
    assert app.outcome.reason.endswith("the flight is over: on the ground and disarmed")


async def test_a_pilot_who_takes_over_as_the_wall_limit_passes_keeps_the_vehicle(
    tmp_path: Path, config: PerceptionConfig
) -> None:
    app, link, clock = limited_flight(tmp_path, config)

    await hand_over(app, link)
    sent = len(link.commands)
    link.status.mode = FlightMode.POSCTL  # the pilot's switch and the limit, seen at the same tick
    clock.now_s = 1000.0
    await tick(app, link, 1.1)
    for k in range(10):
        await tick(app, link, 1.2 + 0.1 * k)
    assert len(link.commands) == sent  # no hold, no return: the vehicle is the pilot's
    assert app.outcome.phase == "yielded"


async def test_a_stop_in_flight_sends_the_last_resort_at_the_next_tick_and_ends(app_and_link: Any) -> None:
    app, link = app_and_link

    await hand_over(app, link)
    app.request_stop("SIGTERM received")
    assert not app.done.is_set()  # the stop waits for a tick: the vehicle's state to decide at
    await tick(app, link, 1.1)
    assert link.commands[-1] == ("hold", None)  # the configured last resort, then the end (no watch)
    assert app.done.is_set()
    assert app.outcome.phase == "failsafe"
    assert "SIGTERM received: stopping: hold" in app.outcome.reason


async def test_a_stop_that_no_tick_takes_ends_without_the_last_resort_within_its_bound(
    app_and_link: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The SITL stopped with us (a campaign interrupted) or the link is gone: no tick will ever come to act at.
    app, link = app_and_link
    monkeypatch.setattr("companion.app.run_end.STOP_UNHEARD_S", 0.2)

    await hand_over(app, link)
    sent = len(link.commands)
    app.request_stop("SIGTERM received")
    await asyncio.wait_for(app.done.wait(), timeout=10.0)
    assert len(link.commands) == sent  # nothing sent without a state to decide it at
    assert app.outcome.reason == "SIGTERM received: no vehicle tick within 0.2 s, ending without the last resort"
    events = [r for r in read_log(app.recorder.path) if r["kind"] == "supervision"]
    assert [(r["event"], r["reason"]) for r in events] == [("stopped", app.outcome.reason)]


class SilentLink(FakeLink):
    """A vehicle that never answers: its connect waits out its whole timeout (a SITL stopped with us)."""

    def __init__(self) -> None:
        super().__init__()
        self.connecting = asyncio.Event()
        self.connect_cancelled = False

    async def connect(self, timeout_s: float) -> None:
        self.connecting.set()
        try:
            await asyncio.wait_for(asyncio.Event().wait(), timeout_s)
        except asyncio.CancelledError:
            self.connect_cancelled = True
            raise
        raise VehicleError(self.name, f"no autopilot answered within {timeout_s:g} s", LinkResult.TIMEOUT)


async def test_a_stop_while_the_vehicle_is_not_yet_found_ends_the_run_without_waiting_out_the_connect(
    tmp_path: Path, config: PerceptionConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A campaign interrupted as its companion starts: the SITL died with the worker, the connect would wait 20 s.
    link = SilentLink()
    app = field_flight(tmp_path, config, link)
    monkeypatch.setattr("companion.app.run_end.STOP_UNHEARD_S", 0.2)

    run = asyncio.create_task(app.run())
    await asyncio.wait_for(link.connecting.wait(), timeout=10.0)
    app.request_stop("SIGTERM received")
    await asyncio.wait_for(run, timeout=10.0)  # the connect's own timeout is 20 s
    assert link.connect_cancelled
    assert link.commands == []
    assert app.outcome.reason == "SIGTERM received: no vehicle tick within 0.2 s, ending without the last resort"
    kinds = [r["kind"] for r in read_log(app.recorder.path)]
    assert kinds == ["start", "supervision", "end"]


async def test_every_fallback_site_chosen_is_said_to_the_ground_station_even_without_a_phase_change(
    tmp_path: Path, config: PerceptionConfig
) -> None:
    link = FakeLink()
    mission = MissionConfig.model_validate(
        {
            "start": {"arm_and_takeoff": False},
            "guidance": {
                "mission_time_limit_s": 30.0,
                "fallback": {"sites": [{"name": "north_lawn", "north_m": 10.0, "east_m": 0.0}]},
            },
            "perception": config.model_dump(mode="json"),
            "recorder": {"directory": str(tmp_path), "frame_every": 0},
        }
    )
    app = FlightApp(mission, link, NoFrames(), SlzPipeline.from_config(mission.perception), FlightRecorder(tmp_path))

    await hand_over(app, link)
    app.landing.guidance.enter(LandingPhase.APPROACH, 2.0)  # approaching a zone when the time runs out
    app.outcome.phase = LandingPhase.APPROACH.value
    await tick(app, link, 31.5)
    assert app.landing.guidance.phase is LandingPhase.APPROACH
    texts = [fields["text"] for name, fields in link.ground.sent if name == "STATUSTEXT"]
    assert "fallback site north_lawn" in "".join(texts), texts  # (chunked at 50 characters)


async def test_a_stop_while_watching_after_a_failsafe_ends_at_once_and_says_so(
    tmp_path: Path, config: PerceptionConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Issue 65: a stop while watching after a failsafe logged "no vehicle tick within 3 s" with ticks all along.
    monkeypatch.setattr("companion.app.run_end.STOP_UNHEARD_S", 0.2)
    app, link, clock = limited_flight(tmp_path, config)

    await hand_over(app, link)
    await tick(app, link, 1.1)
    clock.now_s = 300.0  # the wall limit: hold, then watch
    await tick(app, link, 1.2)
    assert app.supervision.watching is not None
    sent = len(link.commands)
    app.request_stop("SIGTERM received")
    await tick(app, link, 1.3)
    assert app.done.is_set()
    assert len(link.commands) == sent  # the vehicle is the autopilot's: nothing sent
    await asyncio.sleep(0.4)  # past the unheard stop's bound: it must not speak now
    assert "SIGTERM received while watching after the failsafe" in app.outcome.reason
    assert "no vehicle tick" not in app.outcome.reason
    events = supervision(tmp_path)
    assert [e for e, _ in events] == ["watching", "stopped"]


async def test_a_frame_perceived_while_a_tick_ended_the_mission_is_not_decided_on(app_and_link: Any) -> None:
    # Issue 65: after Ctrl-C mid-descent a frame in flight was decided on in the failsafe phase: a second failsafe
    # record ("frame ignored in failsafe") and the outcome's reason overwritten.
    app, link = app_and_link

    await hand_over(app, link)
    perceive = app.intake.perceive

    async def slow_perceive(*args: Any, **kwargs: Any) -> Any:
        result = await perceive(*args, **kwargs)
        app.request_stop("SIGINT received")
        await tick(app, link, 1.15)  # the stop's last resort goes out while the frame is being perceived
        return result

    app.intake.perceive = slow_perceive
    link.at(1.1)
    await app.on_frame(Frame(1, 1.1, np.full((480, 640, 3), 90, np.uint8)))
    records = read_log(app.recorder.path)
    failsafes = [r for r in records if r["kind"] == "failsafe"]
    assert len(failsafes) == 1
    assert failsafes[0]["reason"].startswith("SIGINT received: stopping")
    assert app.outcome.reason.startswith("SIGINT received: stopping")
    assert app.outcome.failsafes == [app.outcome.reason]


class LateCamera(NoFrames):
    """A camera service that comes up after the companion: its first opens fail."""

    def __init__(self, failures: int) -> None:
        self.failures = failures
        self.attempts = 0

    async def open(self) -> None:
        self.attempts += 1
        if self.attempts <= self.failures:
            raise CameraError("sitl", "cannot connect: [Errno 111] Connection refused", CameraFault.CONNECT_FAILED)


async def test_a_camera_that_comes_up_after_the_companion_is_waited_for_within_its_bound(
    tmp_path: Path, config: PerceptionConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Issue 65: `slz fly` started before the camera failed at once; on a drone they start in any order.
    monkeypatch.setattr("companion.camera.waiting.CAMERA_RETRY_S", 0.01)
    link = FakeLink()
    app = field_flight(tmp_path, config, link)
    app.source = late = LateCamera(failures=3)
    await app._open()  # the camera first: no vehicle touched before it is up
    assert late.attempts == 4
    waits = [r["waiting_for"] for r in read_log(app.recorder.path) if r["kind"] == "waiting"]
    assert waits == ["the camera: sitl: cannot connect: [Errno 111] Connection refused"]  # said once, not per try
    soon = app.config.camera.model_copy(update={"wait_for_s": 0.05})
    app.landing.config = app.config.model_copy(update={"camera": soon})
    app.source = LateCamera(failures=1000)
    with pytest.raises(CameraError, match="cannot connect"):
        await app._open()  # past the bound: the camera's own error


async def test_the_console_says_how_the_flight_goes_every_few_seconds_and_while_watching(
    tmp_path: Path, config: PerceptionConfig, caplog: pytest.LogCaptureFixture
) -> None:
    # Issue 65: nothing on the console for 4 minutes of watching after a failsafe, nor during take-off or descent.
    app, link, clock = limited_flight(tmp_path, config)
    with caplog.at_level(logging.INFO, logger="companion.app.journal"):
        await hand_over(app, link)
        for k in range(1, 60):  # 6 s of searching at 10 Hz
            await tick(app, link, 1.0 + 0.1 * k)
        clock.now_s = 300.0  # the wall limit: hold, then watch
        for k in range(60, 180):  # 12 s of watching
            await tick(app, link, 1.0 + 0.1 * k)
    lines = [r.message for r in caplog.records if r.name == "companion.app.journal" and r.message.startswith("t ")]
    flying = [line for line in lines if line.startswith("t ") and "search" in line]
    watching = [line for line in lines if "watching after the failsafe" in line]
    assert flying
    assert "altitude 20.0 m" in flying[0]
    assert "mode OFFBOARD" in flying[0]
    assert len(watching) >= 2  # every 5 s of vehicle time, calm
    assert "mode HOLD" in watching[0]
    assert len(lines) <= 5  # 18 s of flight: a line per 5 s, not per tick
