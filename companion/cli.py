"""The ``slz`` command: one entry point, one subcommand per job.

The drone's commands live here (``check-config``, ``fly``, ``doctor``, ``replay``, ``report``, and ``serve``, which runs
any of them one after another in one warm process); other packages add theirs through the ``slz.commands``
entry-point group (the lab's ``sitl``, ``demo`` and ``campaign``: ``sitl.cli``).
This module imports nothing outside ``companion``, and subcommands import what they need lazily.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import signal
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from companion import __version__
from companion.config import ConfigError

logger = logging.getLogger("slz")

DEFAULT_MISSION_CONFIG = Path("mission_configs/sitl.yaml")
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""What stops ``slz fly`` (the systemd unit's KillSignal, Ctrl-C, a harness): a vehicle it flies gets the last
resort first."""
EXIT_FAILSAFE = 3
"""``slz fly`` ended in a failsafe: the vehicle is the autopilot's (land, hold, return). The systemd unit does not
restart on it (``RestartPreventExitStatus``), so a companion never takes back a vehicle it handed over."""


def _cmd_check_config(args: argparse.Namespace) -> int:
    from companion.app.mission import validate_for_flight

    config, pipeline = validate_for_flight(args.path, never_arm=args.never_arm)
    providers = getattr(pipeline.density_model, "providers", ["?"])
    sys.stdout.write(
        f"{args.path}: valid for slz fly{' --never-arm' if args.never_arm else ''} "
        f"(mode {config.mode.value}, vehicle {config.vehicle.url}, camera {config.camera.url}, "
        f"model {config.perception.model.path.name} on {providers[0]})\n"
    )
    if args.show:
        sys.stdout.write(json.dumps(config.model_dump(mode="json"), indent=2) + "\n")
    return 0


def _cmd_fly(args: argparse.Namespace) -> int:
    import asyncio
    import datetime
    import hashlib

    from companion.app.flight import FlightApp
    from companion.app.mission import FrameFormat, OperatingMode, validate_for_flight
    from companion.camera.frames import CameraError
    from companion.camera.sources import open_frame_source
    from companion.flightlog.flight_log import SCHEMA_VERSION, FlightHeader, RecordKind
    from companion.flightlog.recorder import FlightRecorder, prune_flights
    from companion.guidance.landing import LandingPhase
    from companion.perception.model_validation import validation_of
    from companion.vehicle.link import VehicleError
    from companion.vehicle.lockstep import LockstepClient, LockstepError
    from companion.vehicle.mavsdk_link import MavsdkVehicleLink

    if args.timeout is not None and not (math.isfinite(args.timeout) and args.timeout > 0.0):
        sys.stderr.write(f"slz fly: --timeout must be a positive number of seconds, got {args.timeout:g}\n")
        return 2
    config, pipeline = validate_for_flight(args.config, never_arm=args.never_arm)  # as `slz check-config` does
    if args.dry_run:
        config = config.model_copy(update={"mode": OperatingMode.DRY_RUN})
    if args.replayable:  # every frame, losslessly: `slz replay` can re-run the flight
        recorder_config = config.recorder.model_copy(update={"frame_every": 1, "frame_format": FrameFormat.PNG})
        config = config.model_copy(update={"recorder": recorder_config})
    validation = validation_of(config.perception.model.path)
    unvalidated = validation is None or not validation.real_imagery
    if unvalidated and config.mode is OperatingMode.FLY and config.simulator.lockstep_url is None:
        logger.warning(
            "%s is NOT validated for flight over real people: %s",
            config.perception.model.path.name,
            validation.summary if validation is not None else "no validation record for this model file",
        )
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    out = Path(args.out) if args.out else config.recorder.directory / stamp
    if not args.out:
        prune_flights(config.recorder.directory, config.recorder.keep_flights, config.recorder.max_total_mb)
    sim = config.simulator
    lockstep = LockstepClient(sim.lockstep_url, sim.tick_timeout_s) if sim.lockstep_url else None
    lossless = config.recorder.frame_format is FrameFormat.PNG
    recorder = FlightRecorder(out, config.recorder.frame_every, lossless)
    link = MavsdkVehicleLink(config.vehicle.url, config.vehicle.telemetry_rate_hz, config.vehicle.system_id)

    async def fly() -> int:
        try:
            source = open_frame_source(
                config.camera.url, vehicle_time_s=link.telemetry.clock.now_s, latency_s=config.camera.latency_s
            )
            app = FlightApp(config, link, source, pipeline, recorder, lockstep, wall_limit_s=args.timeout)
            if view is not None:
                recorder.listeners.append(view.record)
                app.intake.viewers.append(view.frame)
            loop = asyncio.get_running_loop()
            for stop_signal in STOP_SIGNALS:  # the service stopped, Ctrl-C: the last resort first, then the end
                loop.add_signal_handler(stop_signal, app.request_stop, f"{stop_signal.name} received")
            try:
                outcome = await app.run()
            finally:
                for stop_signal in STOP_SIGNALS:
                    loop.remove_signal_handler(stop_signal)
        finally:
            await link.close()
            if view is not None:
                view.close()
        ended.append(f"ended in {outcome.phase} ({outcome.reason})")
        if outcome.phase in (LandingPhase.DONE, LandingPhase.YIELDED) or config.mode is OperatingMode.DRY_RUN:
            return 0
        return EXIT_FAILSAFE if outcome.phase == LandingPhase.FAILSAFE else 1

    ended: list[str] = []  # the flight's own words, for the last line
    view = None
    if args.live_view is not None or config.live_view.enabled:  # the flight in Foxglove, while it flies
        from companion.app.live_view import LiveView, LiveViewError
        from companion.app.live_view_config import LiveViewConfig
        from companion.config import validate_config

        view_config = config.live_view
        try:
            if args.live_view is not None:
                asked = {**view_config.model_dump(), "enabled": True, "port": args.live_view}
                view_config = validate_config(LiveViewConfig, asked, source="--live-view", prefix="live_view")
            view = LiveView(view_config)
        except (LiveViewError, ConfigError) as exc:
            sys.stderr.write(f"slz fly: live view: {exc}\n")
            return 2
        sys.stdout.write(f"live view: ws://{view_config.host}:{view.port} (open it in Foxglove)\n")

    try:
        model_path = config.perception.model.path
        model_sha256 = hashlib.sha256(model_path.read_bytes()).hexdigest() if model_path.is_file() else None
        header = FlightHeader(
            config=config.model_dump(mode="json"),
            schema_version=SCHEMA_VERSION,
            model=str(model_path),
            model_sha256=model_sha256,
            model_validated_real_imagery=validation is not None and validation.real_imagery,
            version=__version__,
        )
        recorder.write(RecordKind.HEADER, None, **header.fields())
        return asyncio.run(fly())
    except (VehicleError, CameraError, LockstepError) as exc:
        recorder.write(RecordKind.ERROR, None, where="fly", error=str(exc))
        sys.stderr.write(f"slz fly: {exc}\n")
        return 1
    finally:
        recorder.close()
        if recorder.path.is_file():
            from companion.tools.landing_report import ENDING_WORDS, FlightEnding, write_landing_report

            report = write_landing_report(recorder.directory)  # beside the log: what the operator files
            says = "no landing report (the log could not be read)"
            if report is not None:
                outcome = json.loads(report.read_text(encoding="utf-8"))["outcome"]
                says = ENDING_WORDS[FlightEnding(outcome)]
            words = "; ".join([says, *ended])
            sys.stdout.write(f"{config.mode.value}: {words}; log {recorder.directory} (slz report takes it)\n")


def _cmd_doctor(args: argparse.Namespace) -> int:
    import asyncio

    from companion.app.mission import load_mission_config
    from companion.tools.doctor import DoctorLimits, Status, diagnose

    config = load_mission_config(args.config)
    limits = DoctorLimits(
        min_model_rate_hz=args.min_model_rate, frames=args.frames, min_free_mb=args.min_free_mb, window_s=args.window
    )
    sys.stdout.write(f"slz doctor: {args.config} (slz-lander {__version__})\n")
    results = asyncio.run(diagnose(config, limits, actuator_test=args.actuator_test))
    for result in results:
        sys.stdout.write(result.line() + "\n")
        sys.stdout.flush()
    failed = [r.name for r in results if r.status is Status.FAIL]
    skipped = [r.name for r in results if r.status is Status.SKIP]
    if failed or skipped:
        unchecked = f"; {', '.join(skipped)} not checked" if skipped else ""
        sys.stdout.write(f"NOT READY: {', '.join(failed) or 'nothing'} failed{unchecked}\n")
    else:
        sys.stdout.write("ready to fly\n")
    return 1 if failed or skipped else 0


def _cmd_report(args: argparse.Namespace) -> int:
    from companion.flightlog.recorder import RecorderError
    from companion.tools.replay import ReplayError

    try:
        import matplotlib  # noqa: F401  (the plots)

        from companion.tools.report import ReportError, build_flight_report
    except ImportError as exc:
        sys.stderr.write(f"slz report: {exc}: install the plotting extra, pip install 'slz-lander[report]'\n")
        return 1
    from companion.flightlog.flight_log import flight_folder

    try:
        report = build_flight_report(flight_folder(args.flight), args.out, video=not args.no_video, ulog=args.ulog)
    except (ReportError, RecorderError, ReplayError, OSError) as exc:
        sys.stderr.write(f"slz report: {exc}\n")
        return 1
    for path in report.files:
        sys.stdout.write(f"wrote {path}\n")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from companion.flightlog.flight_log import flight_folder
    from companion.tools.mcap_export import ExportError, export_mcap

    if not args.mcap:
        sys.stderr.write("slz export: say the format: --mcap\n")
        return 2
    flight_dir = flight_folder(args.flight)
    truth = args.truth
    if truth is None:  # a SITL run's truth beside its flight folder, when there is one
        found = [p / "truth.jsonl" for p in (Path(args.flight), flight_dir.parent) if (p / "truth.jsonl").is_file()]
        truth = found[0] if found else None
    out = args.out or flight_dir / "flight.mcap"
    try:
        counts = export_mcap(flight_dir, out, truth)
    except (ExportError, OSError) as exc:
        sys.stderr.write(f"slz export: {exc}\n")
        return 1
    sys.stdout.write(f"wrote {out}: " + ", ".join(f"{topic} {n}" for topic, n in sorted(counts.items())) + "\n")
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from companion.flightlog.flight_log import flight_folder
    from companion.flightlog.recorder import RecorderError
    from companion.tools.replay import ReplayError, replay

    try:
        report = replay(flight_folder(args.flight), video_path=args.video)
    except (ReplayError, RecorderError, OSError) as exc:
        sys.stderr.write(f"slz replay: {exc}\n")
        return 1
    sys.stdout.write(
        f"{report.frames} frames, {report.decisions} decisions replayed: {report.frame_mismatches} frame and "
        f"{report.decision_mismatches} decision differences\n"
    )
    for line in report.differences:
        sys.stdout.write(f"  {line}\n")
    if args.video:
        sys.stdout.write(f"wrote {args.video}\n")
    sys.stdout.write("identical\n" if report.identical else "DIFFERENT\n")
    return 0 if report.identical else 1


def _positive(value: float | None, flag: str) -> str | None:
    """Why ``value`` is not a finite positive number (None when it is, or not given)."""
    if value is None or (math.isfinite(value) and value > 0):
        return None
    return f"{flag} must be a positive number, got {value:g}"


def _cmd_height_map(args: argparse.Namespace) -> int:
    from companion.tools.height_pair import HeightPairError, run

    for value, flag in (
        (args.altitude_m, "--altitude-m"),
        (args.baseline_m, "--baseline-m"),
        (args.hfov_deg, "--hfov-deg"),
    ):
        why = _positive(value, flag)
        if why is not None:
            sys.stderr.write(f"slz height-map: {why}\n")
            return 2
    if args.hfov_deg is not None and args.hfov_deg >= 179.0:
        sys.stderr.write(f"slz height-map: --hfov-deg must be below 179, got {args.hfov_deg:g}\n")
        return 2
    if not 160 <= args.width_px <= 8192:
        sys.stderr.write(f"slz height-map: --width-px must lie in [160, 8192], got {args.width_px}\n")
        return 2
    try:
        result = run(args.a, args.b, args.out, args.altitude_m, args.baseline_m, args.hfov_deg, args.width_px)
    except (HeightPairError, OSError) as exc:
        sys.stderr.write(f"slz height-map: {exc}\n")
        return 1
    g = result["geometry"]
    sys.stdout.write(
        f"{result['share_of_frame_above_ground']:.1%} of the frame above the ground, "
        f"{result['share_of_frame_measured_flat']:.1%} measured flat, {result['share_of_frame_unknown']:.1%} unknown "
        f"(altitude {g['altitude_m']:.1f} m {g['altitude_source']}, baseline {g['baseline_m']:.1f} m "
        f"{g['baseline_source']}, focal {g['focal_px']:.0f} px {g['focal_source']})\n"
    )
    if result["unknown_because"]:
        sys.stdout.write(f"unknown because: {result['unknown_because']}\n")
    sys.stdout.write(f"wrote {args.out}/summary.json, height_m.npy, above_ground.png, overlay.png\n")
    return 0


def _cmd_serve(args: argparse.Namespace) -> int:
    from companion.tools.serve import serve

    return serve(main, preload=args.preload)


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """Help that names each option's default, unless it has none (None, off) or its text already says it."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if not action.option_strings or action.default in (None, False, [], argparse.SUPPRESS) or "default" in text:
            return action.help
        return f"{text} (default: %(default)s)"


class Parser(argparse.ArgumentParser):
    """``slz``'s parsers, its subcommands' and the plugins' alike: help with defaults."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", DefaultsHelpFormatter)
        super().__init__(*args, **kwargs)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``slz``."""
    parser = Parser(prog="slz", description="SLZ Lander: safe landing in populated areas.")
    parser.add_argument("--version", action="version", version=f"slz-lander {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    check = sub.add_parser("check-config", help="validate a mission config exactly as `slz fly` does")
    check.add_argument("path", type=Path)
    check.add_argument("--never-arm", action="store_true", help="as `slz fly --never-arm` (the systemd unit)")
    check.add_argument("--show", action="store_true", help="print the config with every default filled in")
    check.set_defaults(func=_cmd_check_config)

    fly = sub.add_parser("fly", help="land the vehicle safely (or only watch and decide, with --dry-run)")
    fly.add_argument("--config", type=Path, required=True, help="mission config (mission_configs/*.yaml)")
    fly.add_argument("--dry-run", action="store_true", help="perceive and decide, never command the vehicle")
    fly.add_argument("--out", type=Path, help="flight log folder (default: recorder.directory/<UTC time>)")
    fly.add_argument(
        "--timeout",
        type=float,
        default=None,
        help="wall seconds after which the mission gives up: a vehicle the companion flies then gets "
        "guidance.last_resort (hold or return) and the program stays until it is on the ground or the pilot has it; "
        "a dry run or a wait for the handover just ends (default: no wall limit; guidance.mission_time_limit_s, on "
        "the vehicle clock, bounds the search)",
    )
    fly.add_argument(
        "--live-view",
        type=int,
        metavar="PORT",
        help="serve the flight to Foxglove on this port while it flies (live_view in the config says the rest)",
    )
    fly.add_argument(
        "--replayable",
        action="store_true",
        help="save every frame losslessly (PNG), whatever recorder says, so that slz replay can re-run the flight "
        "(about 0.5 MB a frame)",
    )
    fly.add_argument(
        "--never-arm",
        action="store_true",
        help="refuse a config that arms and takes off (services: a restarted companion must never take off)",
    )
    fly.set_defaults(func=_cmd_fly)

    doctor = sub.add_parser("doctor", help="check a board before flight: model, camera, autopilot link, clock, disk")
    doctor.add_argument("--config", type=Path, required=True, help="the mission config the flight will use")
    doctor.add_argument("--min-model-rate", type=float, default=10.0, help="inferences per second needed (Hz)")
    doctor.add_argument("--frames", type=int, default=10, help="camera frames to read")
    doctor.add_argument(
        "--actuator-test",
        action="store_true",
        help="also switch the warning device (guidance.warning) on for 2 s and off again through the autopilot: on "
        "the bench, props off",
    )
    doctor.add_argument("--min-free-mb", type=float, default=1024.0, help="free space needed for flight logs (MiB)")
    doctor.add_argument("--window", type=float, default=2.0, help="seconds over which telemetry rates are measured")
    doctor.set_defaults(func=_cmd_doctor)

    replay = sub.add_parser("replay", help="re-run a recorded flight and check it decides the same")
    replay.add_argument(
        "flight", type=Path, help="flight folder (flight.jsonl and frames/, recorded with png frames), or a demo's run"
    )
    replay.add_argument("--video", type=Path, help="also write the annotated camera view here (MP4)")
    replay.set_defaults(func=_cmd_replay)

    export = sub.add_parser("export", help="write a recorded flight in a format other tools open (MCAP: Foxglove)")
    export.add_argument("flight", type=Path, help="flight folder (flight.jsonl, frames/), or a demo's run folder")
    export.add_argument("--mcap", action="store_true", help="as MCAP, with Foxglove's schemas")
    export.add_argument("--out", type=Path, help="the file (default FLIGHT/flight.mcap)")
    export.add_argument(
        "--truth", type=Path, help="a SITL run's truth.jsonl (default: the run folder's, when there is one)"
    )
    export.set_defaults(func=_cmd_export)

    report = sub.add_parser("report", help="turn a flight log (real, dry run or SITL) into plots, video and a page")
    report.add_argument("flight", type=Path, help="flight folder (flight.jsonl, frames/), or a demo's run folder")
    report.add_argument("--out", type=Path, help="output folder (default FLIGHT/report)")
    report.add_argument("--no-video", action="store_true", help="skip camera.mp4 (the contact sheet is kept)")
    report.add_argument(
        "--ulog",
        type=Path,
        help="the autopilot's PX4 ULog of the same flight (an SD card's, or the SITL's flight.ulg): drawn beside the "
        "companion's log on the same clock",
    )
    report.set_defaults(func=_cmd_report)

    height = sub.add_parser(
        "height-map",
        help="what stands above the ground in two overlapping photographs of a site (motion parallax), before a flight",
    )
    height.add_argument("a", type=Path, help="the photograph the map is drawn over")
    height.add_argument("b", type=Path, help="a second photograph of the same ground from elsewhere")
    height.add_argument(
        "--out", type=Path, required=True, help="folder for the map, the mask, the overlay, the summary"
    )
    height.add_argument(
        "--altitude-m", type=float, help="height of the camera above the ground, m (EXIF's is above sea)"
    )
    height.add_argument("--baseline-m", type=float, help="distance between the two shots, m (default: their EXIF GPS)")
    height.add_argument("--hfov-deg", type=float, help="horizontal field of view (default: from EXIF's focal length)")
    height.add_argument("--width-px", type=int, default=1280, help="working width the photographs are resized to")
    height.set_defaults(func=_cmd_height_map)

    serve = sub.add_parser(
        "serve", help="run slz commands named on standard input, one after another, in this one warm process"
    )
    serve.add_argument(
        "--preload", action="append", default=[], metavar="MODULE", help="import this before the first command"
    )
    serve.set_defaults(func=_cmd_serve)

    for plugin in _plugins():
        plugin(sub)
    return parser


def _plugins() -> list[Callable[[Any], None]]:
    """The ``register(subcommands)`` functions of the ``slz.commands`` entry points whose package is installed."""
    from importlib.metadata import entry_points

    found = []
    for point in sorted(entry_points(group="slz.commands"), key=lambda p: p.name):
        try:
            found.append(point.load())
        except ImportError as exc:  # registered by this distribution, but its package is not shipped here
            logger.debug("slz commands %s not available: %s", point.name, exc)
    return found


def run_command(args: argparse.Namespace, prog: str = "slz") -> int:
    """Set up logging and run a parsed command: a bad config exits 2 and a perception error 1, each in one line."""
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    from companion.perception.errors import PerceptionError

    try:
        code: int = args.func(args)
    except ConfigError as exc:
        sys.stderr.write(f"{prog}: {exc}\n")
        return 2
    except PerceptionError as exc:
        sys.stderr.write(f"{prog}: perception error in {exc}\n")
        return 1
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``slz``; returns the process exit code."""
    return run_command(build_parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
