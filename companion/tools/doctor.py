"""``slz doctor``: is this board ready to fly? One line per check, pass or fail, before any flight.

The checks use the mission config the flight will use, and the same classes ``slz fly`` uses:

- **disk**: the flight-log directory can be created and written (fsync'd), with enough free space;
- **model**: the density model loads with the configured execution providers (the one chosen is named, a fallback
  is flagged) and runs at least at the camera's rate;
- **validation**: what the model is validated on (``companion.perception.model_validation``): WARN for a model not
  validated for flight over real people (every shipped one), FAIL with
  ``perception.model.require_real_imagery_validation``;
- **link**: an autopilot answers on ``vehicle.url``, and position, attitude, flight mode (heartbeat), armed and
  in-air state all stream, position and attitude at a usable rate;
- **clock**: the vehicle clock is synchronised from the telemetry stamps, and evenly (95 % of the stamps within
  100 ms of the least delayed);
- **camera**: the source opens and delivers frames with increasing capture times that are fresh on the vehicle
  clock;
- **failsafe**: what the autopilot does when the companion dies in flight (PX4's ``COM_OF_LOSS_T`` and
  ``COM_OBL_ACT``/``COM_OBL_RC_ACT``, ArduPilot's ``FS_GCS_ENABLE``). Landing in place is a WARN: over a crowd it
  lands where the companion had refused to. Hold is what ``deploy/README.md`` asks for: the restarted companion takes
  over from HOLD.

Nothing is commanded: the doctor never arms, never changes mode and never sends a setpoint.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import itertools
import logging
import os
import shutil
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.app.mission import MissionConfig
from companion.camera.frames import CameraError, Frame
from companion.camera.sources import open_frame_source
from companion.perception.density import OnnxDensityModel
from companion.perception.errors import PerceptionError
from companion.perception.model_validation import validation_of
from companion.vehicle.clock import VehicleClock
from companion.vehicle.link import Action, FlightMode, Params, VehicleError
from companion.vehicle.mavsdk_link import MavsdkVehicleLink

logger = logging.getLogger(__name__)

POSE_STREAMS = ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION")
STATE_STREAMS = ("flight_mode", "armed", "in_air")


class Status(str, enum.Enum):
    """A check's verdict."""

    PASS = "PASS"
    WARN = "WARN"
    """Usable, but not as configured (a provider fallback): the flight may still go."""
    FAIL = "FAIL"
    SKIP = "SKIP"
    """Not checked because another check failed first (counts as a failure)."""


@dataclass(frozen=True)
class CheckResult:
    """One line of the doctor's report."""

    name: str
    status: Status
    detail: str

    @property
    def ok(self) -> bool:
        """Pass or warn."""
        return self.status in (Status.PASS, Status.WARN)

    def line(self) -> str:
        """``PASS model: ...``."""
        return f"{self.status.value} {self.name}: {self.detail}"


@dataclass(frozen=True)
class DoctorLimits:
    """What a board must reach to pass.

    Parameters
    ----------
    min_model_rate_hz : float
        Inferences per second the model must sustain (the camera's frame rate, 10 Hz in the paper's setup).
    min_pose_rate_hz : float
        Position and attitude samples per second each (the pose at a frame's capture time is interpolated).
    max_clock_spread_s : float
        Largest spread of the transport delay of telemetry stamps over the clock's window: how much later than the
        least delayed stamp ``clock_spread_fraction`` of them arrived.
    clock_spread_fraction : float
        The share of stamps the spread covers (the rest, a scheduling hiccup on a loaded board, is not held against
        the link).
    frames : int
        Camera frames to read.
    min_free_mb : float
        Free space for flight logs.
    window_s : float
        Wall time over which telemetry rates are measured.
    """

    min_model_rate_hz: float = 10.0
    min_pose_rate_hz: float = 10.0
    max_clock_spread_s: float = 0.1
    clock_spread_fraction: float = 0.95
    frames: int = 10
    min_free_mb: float = 1024.0
    window_s: float = 2.0


def check_disk(directory: Path, min_free_mb: float) -> CheckResult:
    """The flight-log directory is writable (a probe file written, fsync'd, removed) with ``min_free_mb`` free."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".doctor-{os.getpid()}"
        with probe.open("wb") as f:
            f.write(b"slz doctor\n")
            f.flush()
            os.fsync(f.fileno())
        probe.unlink()
    except OSError as exc:
        return CheckResult("disk", Status.FAIL, f"cannot write flight logs in {directory}: {exc.strerror or exc}")
    free_mb = shutil.disk_usage(directory).free / 1024 / 1024
    status = Status.PASS if free_mb >= min_free_mb else Status.FAIL
    return CheckResult("disk", status, f"{directory} writable, {free_mb:,.0f} MiB free (need {min_free_mb:,.0f})")


def check_model(config: MissionConfig, min_rate_hz: float, runs: int = 20) -> CheckResult:
    """Load the model as ``slz fly`` does and time ``runs`` inferences on a frame of the camera's size."""
    m = config.perception.model
    try:
        model = OnnxDensityModel.from_config(m)
    except PerceptionError as exc:
        return CheckResult("model", Status.FAIL, f"{exc.what}: {exc}")
    cam = config.perception.camera
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 256, size=(cam.height_px, cam.width_px, 3), dtype=np.uint8)
    model.predict(frame)  # warm-up (a TensorRT engine is built or loaded here)
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        model.predict(frame)
        times.append(time.perf_counter() - t0)
    rate_hz = 1.0 / statistics.median(times)
    provider = model.providers[0]
    detail = f"{m.path.name} on {provider}: {rate_hz:.1f} Hz median over {runs} runs (need {min_rate_hz:g})"
    if rate_hz < min_rate_hz:
        return CheckResult("model", Status.FAIL, detail)
    if provider != m.providers[0]:
        return CheckResult("model", Status.WARN, f"{detail}; fell back from {m.providers[0]}")
    return CheckResult("model", Status.PASS, detail)


def check_validation(config: MissionConfig) -> CheckResult:
    """Whether the model is validated for flight over real people: WARN when not (FAIL when the config requires it)."""
    m = config.perception.model
    record = validation_of(m.path)
    if record is not None and record.real_imagery:
        return CheckResult("validation", Status.PASS, f"{m.path.name}: {record.summary}")
    what = record.summary if record is not None else "no validation record for this model file (not a shipped model)"
    status = Status.FAIL if m.require_real_imagery_validation else Status.WARN
    return CheckResult("validation", status, f"{m.path.name} is NOT validated for flight over real people: {what}")


async def check_link(link: MavsdkVehicleLink, config: MissionConfig, limits: DoctorLimits) -> list[CheckResult]:
    """Connect, then count the telemetry streams over ``limits.window_s``; the clock check follows from them."""
    timeout_s = config.vehicle.connect_timeout_s
    try:
        await link.connect(timeout_s)
    except VehicleError as exc:
        return [
            CheckResult("link", Status.FAIL, str(exc)),
            CheckResult("clock", Status.SKIP, "no link: no vehicle clock"),
        ]
    telemetry = link.telemetry
    # The streams start a moment after the connection: count from the first sample of each.
    with contextlib.suppress(VehicleError):
        await telemetry.wait_for(
            lambda: all(telemetry.received.get(s) for s in (*POSE_STREAMS, *STATE_STREAMS)),
            time.monotonic() + max(5.0, limits.window_s),
            "the telemetry streams",
        )
    before = dict(telemetry.received)
    t0 = time.monotonic()
    await asyncio.sleep(limits.window_s)  # a rate is measured over a window of wall time, not waited for
    elapsed = time.monotonic() - t0
    rates = {s: (telemetry.received.get(s, 0) - before.get(s, 0)) / elapsed for s in POSE_STREAMS}
    missing_state = [s for s in STATE_STREAMS if not telemetry.received.get(s)]
    slow = [s for s, r in rates.items() if r < limits.min_pose_rate_hz]
    rate_text = ", ".join(f"{s} {r:.0f} Hz" for s, r in rates.items())
    status = telemetry.status
    detail = f"{link.name}: {rate_text}; mode {status.mode.value}, armed {status.armed}, in air {status.in_air}"
    if slow or missing_state or status.mode is FlightMode.UNKNOWN:
        problems = [f"{s} below {limits.min_pose_rate_hz:g} Hz" for s in slow]
        problems += [f"no {s} (heartbeat / extended state)" for s in missing_state]
        results = [CheckResult("link", Status.FAIL, f"{detail}; " + "; ".join(problems))]
    else:
        results = [CheckResult("link", Status.PASS, detail)]
    spread = telemetry.clock.delay_spread_s(limits.clock_spread_fraction)
    worst = telemetry.clock.offset_spread_s
    if spread is None or worst is None:
        results.append(CheckResult("clock", Status.FAIL, "no stamped telemetry: the vehicle clock is not synchronised"))
    else:
        text = (
            f"vehicle clock from time_boot_ms stamps, {100 * limits.clock_spread_fraction:g} % within "
            f"{1000 * spread:.1f} ms of the least delayed (limit {1000 * limits.max_clock_spread_s:g} ms; "
            f"all within {1000 * worst:.1f} ms)"
        )
        results.append(CheckResult("clock", Status.PASS if spread <= limits.max_clock_spread_s else Status.FAIL, text))
    return results


async def check_camera(config: MissionConfig, clock: VehicleClock | None, limits: DoctorLimits) -> CheckResult:
    """Open the camera, read ``limits.frames`` frames within a deadline, check their stamps (on the vehicle's
    ``clock`` when it is synchronised, else on this computer's) and their age."""
    cam = config.camera
    clock = clock if clock is not None and clock.synced else None
    try:
        source = open_frame_source(
            cam.url, vehicle_time_s=clock.now_s if clock else time.monotonic, latency_s=cam.latency_s
        )
        await source.open()
    except CameraError as exc:
        return CheckResult("camera", Status.FAIL, str(exc))
    frames: list[Frame] = []
    ages_s: list[float] = []
    deadline_s = max(5.0, 3.0 * limits.frames * cam.max_frame_age_s)
    stream = source.frames()

    async def read() -> None:
        async for frame in stream:
            frames.append(frame)
            if clock is not None:
                ages_s.append(clock.now_s() - frame.t_capture_s)
            if len(frames) >= limits.frames:
                return

    try:
        await asyncio.wait_for(read(), deadline_s)
    except (TimeoutError, asyncio.TimeoutError):
        logger.info("camera: %d of %d frames within %g s", len(frames), limits.frames, deadline_s)  # judged below
    except CameraError as exc:
        return CheckResult("camera", Status.FAIL, str(exc))
    finally:
        with contextlib.suppress(Exception):
            await stream.aclose()  # type: ignore[attr-defined]
    if len(frames) < limits.frames:
        return CheckResult(
            "camera", Status.FAIL, f"{cam.url}: {len(frames)} of {limits.frames} frames within {deadline_s:g} s"
        )
    stamps = [f.t_capture_s for f in frames]
    h, w = frames[0].image_bgr.shape[:2]
    span_s = stamps[-1] - stamps[0]
    rate = (len(stamps) - 1) / span_s if span_s > 0 else float("inf")
    detail = f"{cam.url}: {len(frames)} frames {w}x{h}, {rate:.1f} Hz by capture time"
    if any(b <= a for a, b in itertools.pairwise(stamps)):
        return CheckResult("camera", Status.FAIL, f"{detail}; capture times do not increase")
    if clock is None:
        return CheckResult("camera", Status.FAIL, f"{detail}; frame age not checked: no vehicle clock")
    worst = max(ages_s)
    detail += f", age on the vehicle clock {1000 * min(ages_s):.0f}-{1000 * worst:.0f} ms"
    if worst > cam.max_frame_age_s or min(ages_s) < -0.05:
        return CheckResult("camera", Status.FAIL, f"{detail} (allowed 0-{1000 * cam.max_frame_age_s:.0f} ms)")
    return CheckResult("camera", Status.PASS, detail)


# What each offboard-loss setting does, and whether it lands where the vehicle is (over whatever is below it).
PX4_OBL_ACT = {0: ("land", True), 1: ("hold", False), 2: ("return", False)}  # PX4 up to v1.13
PX4_OBL_RC_ACT = {  # PX4 v1.14 and later (and this project's SITL): the three manual modes need RC, else hold
    0: ("position mode: the pilot's sticks, hold without RC", False),
    1: ("altitude mode: the pilot's sticks, hold without RC", False),
    2: ("manual: the pilot's sticks, hold without RC", False),
    3: ("return", False),
    4: ("land", True),
    5: ("hold", False),
    6: ("terminate", True),
    7: ("disarm", True),
}
ARDUPILOT_FS_GCS = {  # ArduCopter's GCS failsafe (the companion's heartbeat, when it is SYSID_MYGCS)
    0: ("disabled: guided mode holds the last target", False),
    1: ("RTL", False),
    2: ("continue the mission", False),
    3: ("SmartRTL or RTL", False),
    4: ("SmartRTL or land", True),
    5: ("land", True),
    6: ("auto DO_LAND_START or RTL", False),
    7: ("brake or land", True),
}


async def check_failsafe(params_part: Params) -> CheckResult:
    """Read the autopilot's offboard-loss parameters and say what it does if the companion dies in flight.

    WARN when the configured action lands (or drops) the vehicle where it is; FAIL when no known parameter answers.
    """
    params = await params_part.read_all()
    if params is None:
        return CheckResult("failsafe", Status.FAIL, "the autopilot's parameter list did not arrive")
    loss_s = params.get("COM_OF_LOSS_T")
    if loss_s is not None:  # PX4: COM_OBL_ACT up to v1.13, COM_OBL_RC_ACT (alone) from v1.14: whichever it has
        actions: list[tuple[str, float, dict[int, tuple[str, bool]]]] = []
        for name, table in (("COM_OBL_ACT", PX4_OBL_ACT), ("COM_OBL_RC_ACT", PX4_OBL_RC_ACT)):
            value = params.get(name)
            if value is not None:
                actions.append((name, value, table))
        if not actions:
            detail = "COM_OF_LOSS_T found, but neither COM_OBL_ACT nor COM_OBL_RC_ACT"
            return CheckResult("failsafe", Status.FAIL, detail)
        texts, lands = [], []
        for name, value, table in actions:
            what, in_place = table.get(int(value), (f"unknown action {value:g}", True))
            texts.append(f"{name} = {value:g} ({what})")
            if in_place:
                lands.append(name)
        detail = f"companion lost for COM_OF_LOSS_T = {loss_s:g} s: " + ", ".join(texts)
    else:
        value = params.get("FS_GCS_ENABLE")
        if value is None:
            return CheckResult(
                "failsafe", Status.FAIL, "no offboard-loss parameter answered (COM_OF_LOSS_T, FS_GCS_ENABLE)"
            )
        what, in_place = ARDUPILOT_FS_GCS.get(int(value), (f"unknown action {value:g}", True))
        detail = f"companion lost: FS_GCS_ENABLE = {value:g} ({what})"
        lands = ["FS_GCS_ENABLE"] if in_place else []
    if lands:
        return CheckResult(
            "failsafe",
            Status.WARN,
            f"{detail}; {' and '.join(lands)} lands in place if the companion dies, over whatever is below "
            "(set hold: see deploy/README.md)",
        )
    return CheckResult("failsafe", Status.PASS, detail)


ACTUATOR_ON_S = 2.0
"""How long the bench test keeps the warning device on (wall seconds)."""


async def check_actuator(action: Action, config: MissionConfig, on_s: float = ACTUATOR_ON_S) -> CheckResult:
    """The warning device on the bench (``--actuator-test``): its output switched to ``on_value``, held ``on_s``,
    then back to ``off_value``, each through the autopilot (MAV_CMD_DO_SET_ACTUATOR, acknowledged). Whether a siren
    sounded or a strobe flashed is for the person at the bench to say: the check says what the autopilot answered."""
    w = config.guidance.warning
    if not w.enabled:
        return CheckResult("actuator", Status.SKIP, "guidance.warning is not enabled in this config")
    try:
        await action.set_actuator(w.actuator, w.on_value)
    except VehicleError as exc:
        return CheckResult("actuator", Status.FAIL, f"output {w.actuator} to {w.on_value:g} refused: {exc}")
    try:
        await asyncio.sleep(on_s)
    finally:
        try:
            await action.set_actuator(w.actuator, w.off_value)
        except VehicleError as exc:
            return CheckResult("actuator", Status.FAIL, f"switched on, but off ({w.off_value:g}) refused: {exc}")
    return CheckResult(
        "actuator",
        Status.PASS,
        f"Offboard Actuator Set {w.actuator} switched to {w.on_value:g} for {on_s:g} s, then {w.off_value:g}: "
        "the autopilot accepted both (did the device sound or flash?)",
    )


async def diagnose(
    config: MissionConfig, limits: DoctorLimits | None = None, actuator_test: bool = False
) -> list[CheckResult]:
    """Run every check in order: disk, model, validation, link, clock, camera, failsafe (and with ``actuator_test``,
    the warning device on the bench)."""
    limits = limits or DoctorLimits()
    results = [check_disk(config.recorder.directory, limits.min_free_mb)]
    results.append(
        await asyncio.get_running_loop().run_in_executor(None, check_model, config, limits.min_model_rate_hz)
    )
    results.append(check_validation(config))
    link = MavsdkVehicleLink(config.vehicle.url, config.vehicle.telemetry_rate_hz, config.vehicle.system_id)
    try:
        link_results = await check_link(link, config, limits)
        results += link_results
        linked = link_results[0].ok or link.telemetry.clock.synced
        results.append(await check_camera(config, link.telemetry.clock if linked else None, limits))
        if link_results[0].ok:
            results.append(await check_failsafe(link.params))
        else:
            results.append(CheckResult("failsafe", Status.SKIP, "no link: the autopilot's parameters are unknown"))
        if actuator_test:
            no_link = CheckResult("actuator", Status.SKIP, "no link: nothing to switch")
            results.append(await check_actuator(link.action, config) if link_results[0].ok else no_link)
    finally:
        await link.close()
    return results
