"""The ``slz`` command: one entry point, one subcommand per job.

Subcommands import what they need lazily, so the companion on the drone never imports simulation code.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
from collections.abc import Sequence
from pathlib import Path

from companion import __version__
from companion.config import ConfigError, read_yaml_file

logger = logging.getLogger("slz")

DEFAULT_MISSION_CONFIG = Path("mission_configs/sitl.yaml")
EXIT_FAILSAFE = 3
"""``slz fly`` ended in a failsafe: the vehicle is the autopilot's (land, hold, return). The systemd unit does not
restart on it (``RestartPreventExitStatus``), so a companion never takes back a vehicle it handed over."""


def _cmd_check_config(args: argparse.Namespace) -> int:
    from companion.perception.config import load_perception_config

    config = load_perception_config(args.path, section=args.section or None)
    sys.stdout.write(f"{args.path}: valid\n")
    if args.show:
        sys.stdout.write(json.dumps(config.model_dump(mode="json"), indent=2) + "\n")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from companion.app.mission import load_mission_config
    from companion.perception.pipeline import SlzPipeline
    from sitl import demo
    from sitl.mission import MissionError

    config = load_mission_config(args.config)  # a bad config or a model that does not load fails before any process
    SlzPipeline.from_config(config.perception)
    try:
        outcome = demo.run(Path(args.out), seed=args.seed, mission_config=args.config, instance=args.instance)
    except MissionError as exc:
        sys.stderr.write(f"slz demo: {exc}\n")
        return 1
    sys.stdout.write(demo.describe(outcome) + "\n")
    return 0 if demo.safe(outcome.result) else 1


def _cmd_fly(args: argparse.Namespace) -> int:
    import asyncio
    import datetime
    import hashlib

    from companion.app.flight import FlightApp
    from companion.app.mission import FrameFormat, OperatingMode, load_mission_config
    from companion.app.recorder import FlightRecorder, prune_flights
    from companion.camera.frames import CameraError, open_frame_source
    from companion.perception.pipeline import SlzPipeline
    from companion.vehicle.link import VehicleError
    from companion.vehicle.lockstep import LockstepClient, LockstepError
    from companion.vehicle.mavsdk_link import MavsdkVehicleLink

    config = load_mission_config(args.config)
    if args.never_arm and config.start.arm_and_takeoff:
        raise ConfigError(
            str(args.config),
            ["start.arm_and_takeoff: must be false with --never-arm (the systemd unit): the pilot takes off"],
        )
    if args.dry_run:
        config = config.model_copy(update={"mode": OperatingMode.DRY_RUN})
    pipeline = SlzPipeline.from_config(config.perception)  # a model that does not load fails before any link
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    out = Path(args.out) if args.out else config.recorder.directory / stamp
    if not args.out:
        prune_flights(config.recorder.directory, config.recorder.keep_flights, config.recorder.max_total_mb)
    sim = config.simulator
    lockstep = LockstepClient(sim.lockstep_url, sim.tick_timeout_s) if sim.lockstep_url else None
    lossless = config.recorder.frame_format is FrameFormat.PNG
    recorder = FlightRecorder(out, config.recorder.frame_every, lossless)
    link = MavsdkVehicleLink(config.vehicle.url, config.vehicle.telemetry_rate_hz)

    async def fly() -> int:
        try:
            source = open_frame_source(
                config.camera.url, vehicle_time_s=link.clock.now_s, latency_s=config.camera.latency_s
            )
            app = FlightApp(config, link, source, pipeline, recorder, lockstep)
            outcome = await app.run(timeout_s=args.timeout)
        finally:
            await link.close()
        sys.stdout.write(f"{config.mode.value}: ended in {outcome.phase} ({outcome.reason}); log {recorder.path}\n")
        if outcome.phase in ("done", "yielded") or config.mode is OperatingMode.DRY_RUN:
            return 0
        return EXIT_FAILSAFE if outcome.phase == "failsafe" else 1

    try:
        model_path = config.perception.model.path
        model_sha256 = hashlib.sha256(model_path.read_bytes()).hexdigest() if model_path.is_file() else None
        recorder.write(
            "header",
            None,
            config=config.model_dump(mode="json"),
            model=str(model_path),
            model_sha256=model_sha256,
            version=__version__,
        )
        return asyncio.run(fly())
    except (VehicleError, CameraError, LockstepError) as exc:
        recorder.write("error", None, where="fly", error=str(exc))
        sys.stderr.write(f"slz fly: {exc}\n")
        return 1
    finally:
        recorder.close()


def _cmd_doctor(args: argparse.Namespace) -> int:
    import asyncio

    from companion.app.doctor import DoctorLimits, diagnose
    from companion.app.mission import load_mission_config

    config = load_mission_config(args.config)
    limits = DoctorLimits(
        min_model_rate_hz=args.min_model_rate, frames=args.frames, min_free_mb=args.min_free_mb, window_s=args.window
    )
    sys.stdout.write(f"slz doctor: {args.config} (slz-lander {__version__})\n")
    results = asyncio.run(diagnose(config, limits))
    for result in results:
        sys.stdout.write(result.line() + "\n")
        sys.stdout.flush()
    failed = [r.name for r in results if not r.ok]
    sys.stdout.write(f"NOT READY: {', '.join(failed)} failed\n" if failed else "ready to fly\n")
    return 1 if failed else 0


def _cmd_report(args: argparse.Namespace) -> int:
    from companion.app.recorder import RecorderError
    from companion.app.replay import ReplayError

    try:
        import matplotlib  # noqa: F401  (the plots)

        from companion.app.report import ReportError, build_flight_report
    except ImportError as exc:
        sys.stderr.write(f"slz report: {exc}: install the plotting extra, pip install 'slz-lander[report]'\n")
        return 1
    try:
        report = build_flight_report(Path(args.flight), args.out, video=not args.no_video)
    except (ReportError, RecorderError, ReplayError, OSError) as exc:
        sys.stderr.write(f"slz report: {exc}\n")
        return 1
    for path in report.files:
        sys.stdout.write(f"wrote {path}\n")
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from companion.app.recorder import RecorderError
    from companion.app.replay import ReplayError, replay

    try:
        report = replay(Path(args.flight), video_path=args.video)
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


def _cmd_campaign(args: argparse.Namespace) -> int:
    from sitl.campaign.gate import GateError, check_against, make_baseline, read_baseline
    from sitl.campaign.provenance import source_commit
    from sitl.campaign.report import build_report
    from sitl.campaign.runner import INSTANCE_BASE, CampaignError, read_results, run_campaign
    from sitl.campaign.spec import load_campaign_spec

    if args.action == "replay":
        return _campaign_replay(args)
    if args.spec is None:
        sys.stderr.write("slz campaign: --spec is required\n")
        return 2
    spec = load_campaign_spec(args.spec)
    out = Path(args.out) if args.out else Path("runs") / "campaigns" / spec.name
    if args.report_only:
        results = read_results(out / "results.jsonl")
    else:
        # SIGINT and SIGTERM stop the campaign cleanly, also when a shell started it in the background (which
        # leaves SIGINT ignored) or a service manager stops it.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, _interrupt)
        try:
            base = INSTANCE_BASE if args.instance_base is None else args.instance_base
            results = run_campaign(spec, out, workers=args.workers, keep_runs=args.keep_runs, instance_base=base)
        except CampaignError as exc:
            sys.stderr.write(f"slz campaign: {exc}\n")
            return 1
        except KeyboardInterrupt:
            sys.stderr.write("\nslz campaign: interrupted; the same command resumes it\n")
            return 130
    summary = build_report(spec, results, out)
    for name, cell in summary["cells"].items():
        success = cell["success"]
        sys.stdout.write(
            f"{name}: {cell['missions']} missions, success {100 * success['value']:.1f} % "
            f"[{100 * success['low']:.1f}, {100 * success['high']:.1f}]\n"
        )
    sys.stdout.write(f"wrote {out / 'report.md'}\n")
    if args.write_baseline:
        baseline = make_baseline(spec, results, source_commit())
        args.write_baseline.parent.mkdir(parents=True, exist_ok=True)
        args.write_baseline.write_text(json.dumps(baseline, indent=1) + "\n")
        sys.stdout.write(f"wrote baseline {args.write_baseline} ({len(baseline['missions'])} missions)\n")
    if args.check_against:
        try:
            gate = check_against(
                spec, results, read_baseline(args.check_against), args.alpha, name=str(args.check_against)
            )
        except GateError as exc:
            sys.stderr.write(f"slz campaign: {exc}\n")
            return 2
        (out / "gate.md").write_text(gate.to_markdown())
        (out / "gate.json").write_text(json.dumps(gate.to_json(), indent=1) + "\n")
        sys.stdout.write(gate.to_markdown())
        return 1 if gate.failed else 0
    return 0


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def _campaign_replay(args: argparse.Namespace) -> int:
    import json

    from companion.app.replay import replay
    from sitl.campaign.metrics import mission_metrics, stale
    from sitl.campaign.report import completed
    from sitl.campaign.runner import mission_spec, read_results
    from sitl.campaign.spec import CampaignSpec
    from sitl.mission import fly

    folder = Path(args.spec_or_folder or "")
    spec_path = folder / "spec.yaml"
    if args.mission is None or not spec_path.is_file():
        sys.stderr.write("slz campaign replay: usage: slz campaign replay CAMPAIGN_FOLDER MISSION_ID\n")
        return 2
    spec = CampaignSpec.model_validate(read_yaml_file(spec_path))
    plan = next((p for p in spec.missions() if p.mission_id == args.mission), None)
    if plan is None:
        sys.stderr.write(f"slz campaign replay: no mission {args.mission!r} in {folder}\n")
        return 2
    out = Path(args.out) if args.out else folder / "replays" / args.mission
    fly(mission_spec(spec, plan, out, args.instance, record_frames=True))
    report = replay(out / "flight", video_path=out / "camera.mp4")
    again = mission_metrics(out, plan.mission_id, plan.condition.name, plan.strategy.name, plan.run, plan.seed)
    logged = next((r for r in read_results(folder / "results.jsonl") if r["mission_id"] == args.mission), None)
    # A result of an earlier metrics definition that the change leaves alone (not stale) compares field by field,
    # completed as the report completes it; a distance completed from the stored (rounded) touchdown point agrees
    # within 1e-5 m. The people map under the touchdown (``people_cells``, for the plots, not a metric) is compared
    # where the result holds one: results restored from a ``results.csv`` do not.
    full = completed(spec, [logged])[0] if logged is not None else {}
    same = logged is not None and all(
        full.get(k) == v
        or (k not in logged and isinstance(v, float) and isinstance(full.get(k), float) and abs(full[k] - v) <= 1e-5)
        for k, v in again.to_json().items()
        if k != "metrics_version" and (k != "people_cells" or k in logged)
    )
    sys.stdout.write(json.dumps(again.to_json(), indent=2) + "\n")
    sys.stdout.write(f"wrote {out / 'camera.mp4'} (replay {'identical' if report.identical else 'DIFFERENT'})\n")
    if logged is not None and stale(logged, plan.strategy.policy.value):
        sys.stdout.write(
            "the campaign's result is stale (an earlier metrics definition): the campaign flies it again\n"
        )
        return 0 if report.identical else 1
    if logged is not None:
        sys.stdout.write(f"metrics {'identical to' if same else 'DIFFERENT from'} the campaign's result\n")
    return 0 if report.identical and (logged is None or same) else 1


def _cmd_sitl(args: argparse.Namespace) -> int:
    if args.action == "snapshot":
        from sitl.snapshot import contact_sheet

        path = contact_sheet(args.seed or 0, args.out)
        sys.stdout.write(f"wrote {path}\n")
        return 0
    from companion.config import validate_config
    from sitl.config import SitlConfig, load_sitl_config
    from sitl.vehicle import SitlError, SitlVehicle, install_signal_handlers

    base = load_sitl_config(args.config) if args.config else SitlConfig()
    overrides = {
        key: value
        for key, value in {
            "instance": args.instance,
            "speed_factor": args.speed,
            "lockstep": True if args.lockstep else None,
            "seed": args.seed,
            "dynamics": args.dynamics,
            "log_path": str(args.log) if args.log else None,
            "duration_s": args.duration,
            "bind_address": args.bind,
        }.items()
        if value is not None
    }
    config = validate_config(SitlConfig, {**base.model_dump(), **overrides}, source="command line", prefix="sitl")
    try:
        vehicle = SitlVehicle(config)
    except SitlError as exc:
        sys.stderr.write(f"slz sitl: {exc}\n")
        return 1
    install_signal_handlers(vehicle)
    try:
        return vehicle.run()
    finally:
        vehicle.close()


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``slz``."""
    parser = argparse.ArgumentParser(prog="slz", description="SLZ Lander: safe landing in populated areas.")
    parser.add_argument("--version", action="version", version=f"slz-lander {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True)

    check = sub.add_parser("check-config", help="validate a mission config file")
    check.add_argument("path", type=Path)
    check.add_argument("--section", default="perception", help="top-level section to check ('' for the whole file)")
    check.add_argument("--show", action="store_true", help="print the config with every default filled in")
    check.set_defaults(func=_cmd_check_config)

    sitl = sub.add_parser("sitl", help="run the simulated PX4-style vehicle (MAVLink on UDP 14540/14550)")
    sitl.add_argument(
        "action",
        nargs="?",
        choices=["run", "snapshot"],
        default="run",
        help="run the vehicle, or render a contact sheet",
    )
    sitl.add_argument("--out", type=Path, default=Path("docs/images/sitl_contact_sheet.png"), help="snapshot: PNG path")
    sitl.add_argument("--config", type=Path, help="YAML file with a 'sitl' section")
    sitl.add_argument("--instance", type=int, help="shifts every port, as PX4 does")
    sitl.add_argument("--speed", type=float, help="simulated seconds per wall second; 0 = as fast as possible")
    sitl.add_argument("--lockstep", action="store_true", help="wait for the client's acknowledgement at each tick")
    sitl.add_argument("--seed", type=int)
    sitl.add_argument("--dynamics", choices=["rigid_body", "jsbsim_f450"])
    sitl.add_argument("--log", type=Path, help="write the true trajectory here (CSV)")
    sitl.add_argument("--duration", type=float, help="stop after this many simulated seconds")
    sitl.add_argument("--bind", help="local address (default 127.0.0.1)")
    sitl.set_defaults(func=_cmd_sitl)

    fly = sub.add_parser("fly", help="land the vehicle safely (or only watch and decide, with --dry-run)")
    fly.add_argument("--config", type=Path, required=True, help="mission config (mission_configs/*.yaml)")
    fly.add_argument("--dry-run", action="store_true", help="perceive and decide, never command the vehicle")
    fly.add_argument("--out", type=Path, help="flight log folder (default: recorder.directory/<UTC time>)")
    fly.add_argument("--timeout", type=float, default=600.0, help="wall seconds before the mission gives up")
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
    doctor.add_argument("--min-free-mb", type=float, default=1024.0, help="free space needed for flight logs (MiB)")
    doctor.add_argument("--window", type=float, default=2.0, help="seconds over which telemetry rates are measured")
    doctor.set_defaults(func=_cmd_doctor)

    campaign = sub.add_parser("campaign", help="fly a campaign of seeded missions and report (or replay one mission)")
    campaign.add_argument("action", nargs="?", choices=["run", "replay"], default="run")
    campaign.add_argument("spec_or_folder", nargs="?", help="replay: the campaign folder")
    campaign.add_argument("mission", nargs="?", help="replay: the mission id (condition/strategy/run)")
    campaign.add_argument("--spec", type=Path, help="campaign spec (mission_configs/campaigns/*.yaml)")
    campaign.add_argument("--out", type=Path, help="campaign folder (default runs/campaigns/<name>)")
    campaign.add_argument("--workers", type=int, help="parallel missions (default: the spec's)")
    campaign.add_argument("--keep-runs", action="store_true", help="keep every mission's logs")
    campaign.add_argument("--report-only", action="store_true", help="rebuild the report from the results")
    campaign.add_argument(
        "--check-against",
        type=Path,
        metavar="BASELINE",
        help="regression gate: exit 1 when a strategy is significantly worse than this baseline on the same scenes",
    )
    campaign.add_argument("--alpha", type=float, default=0.05, help="gate: family false-alarm rate (default 0.05)")
    campaign.add_argument("--write-baseline", type=Path, metavar="PATH", help="write this campaign as a baseline")
    campaign.add_argument("--instance", type=int, default=29, help="replay: SITL instance, 0 to 39 (default 29)")
    campaign.add_argument(
        "--instance-base",
        type=int,
        help="worker k flies SITL instance BASE + k, at most 39 (default 30: beside the tests' 1 to 29)",
    )
    campaign.set_defaults(func=_cmd_campaign)

    replay = sub.add_parser("replay", help="re-run a recorded flight and check it decides the same")
    replay.add_argument("flight", type=Path, help="flight folder (flight.jsonl and frames/, recorded with png frames)")
    replay.add_argument("--video", type=Path, help="also write the annotated camera view here (MP4)")
    replay.set_defaults(func=_cmd_replay)

    report = sub.add_parser("report", help="turn a flight log (real, dry run or SITL) into plots, video and a page")
    report.add_argument("flight", type=Path, help="flight folder (flight.jsonl, frames/)")
    report.add_argument("--out", type=Path, help="output folder (default FLIGHT/report)")
    report.add_argument("--no-video", action="store_true", help="skip camera.mp4 (the contact sheet is kept)")
    report.set_defaults(func=_cmd_report)

    demo = sub.add_parser("demo", help="fly one seeded landing mission in the SITL (lockstep) and draw it")
    demo.add_argument("--config", type=Path, default=DEFAULT_MISSION_CONFIG, help="the companion's mission config")
    demo.add_argument("--seed", type=int, default=1)
    demo.add_argument("--out", type=Path, default=Path("runs"), help="the run goes into OUT/<time>-seed<N>/")
    demo.add_argument("--instance", type=int, default=0, help="SITL instance (ports), for parallel runs")
    demo.set_defaults(func=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``slz``; returns the process exit code."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    from companion.perception.errors import PerceptionError

    try:
        code: int = args.func(args)
    except ConfigError as exc:
        sys.stderr.write(f"slz: {exc}\n")
        return 2
    except PerceptionError as exc:
        sys.stderr.write(f"slz: perception error in {exc}\n")
        return 1
    return code


if __name__ == "__main__":
    sys.exit(main())
