"""The lab's ``slz`` commands: ``sitl``, ``demo`` and ``campaign``, a plugin of the drone's ``slz``.

``companion.cli`` knows nothing of the simulator: it adds every command registered in the ``slz.commands``
entry-point group, and this package registers :func:`register` there (``pyproject.toml``). An install without the
``sitl`` package (the drone's container) shows only the drone's commands. The SITL vehicle has its own entry points
too: ``slz-sitl`` and ``python -m sitl``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import signal
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from companion.cli import DEFAULT_MISSION_CONFIG, Parser, run_command
from companion.config import read_yaml_file


@contextlib.contextmanager
def _instance(requested: int | None) -> Iterator[int]:
    """The SITL instance to fly: the one asked for, or a free one leased from :mod:`sitl.harness.instances`."""
    if requested is not None:
        yield requested
        return
    from sitl.harness.instances import leased_instance

    with leased_instance() as lease:
        yield lease.instance


def _cmd_demo(args: argparse.Namespace) -> int:
    from companion.app.mission import load_mission_config
    from companion.perception.pipeline import SlzPipeline
    from sitl.harness import demo
    from sitl.harness.instances import InstanceError
    from sitl.harness.mission import MissionError

    config = load_mission_config(args.config)  # a bad config or a model that does not load fails before any process
    SlzPipeline.from_config(config.perception)
    try:
        with _instance(args.instance) as instance:
            outcome = demo.run(Path(args.out), seed=args.seed, mission_config=args.config, instance=instance)
    except (MissionError, InstanceError) as exc:
        sys.stderr.write(f"slz demo: {exc}\n")
        return 1
    sys.stdout.write(demo.describe(outcome) + "\n")
    return 0 if demo.safe(outcome.result) else 1


def _cmd_campaign(args: argparse.Namespace) -> int:
    from sitl.campaign.gate import GateError, check_against, make_baseline, read_baseline
    from sitl.campaign.provenance import source_commit
    from sitl.campaign.record import ResultError, parse_results
    from sitl.campaign.report import build_report
    from sitl.campaign.runner import Backend, CampaignError, check_folder_spec, read_results, run_campaign
    from sitl.campaign.spec import load_campaign_spec

    if args.action == "replay":
        return _campaign_replay(args)
    if args.spec is None:
        sys.stderr.write("slz campaign: --spec is required\n")
        return 2
    spec = load_campaign_spec(args.spec)
    out = Path(args.out) if args.out else Path("runs") / "campaigns" / spec.name
    if args.report_only:
        try:
            check_folder_spec(spec, out)  # a folder of hand-gathered results (no spec.yaml) is reported as it is
        except CampaignError as exc:
            sys.stderr.write(f"slz campaign: {exc}\n")
            return 1
        results = read_results(out / "results.jsonl")
    else:
        # SIGINT and SIGTERM stop the campaign cleanly, also when a shell started it in the background (which
        # leaves SIGINT ignored) or a service manager stops it.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, _interrupt)
        try:
            results = run_campaign(
                spec,
                out,
                workers=args.workers,
                keep_runs=args.keep_runs,
                instance_base=args.instance_base,
                backend=Backend(args.backend),
                address=args.address,
                warm=not args.cold,
            )
        except CampaignError as exc:
            sys.stderr.write(f"slz campaign: {exc}\n")
            return 1
        except KeyboardInterrupt:
            sys.stderr.write("\nslz campaign: interrupted; the same command resumes it\n")
            return 130
    previous = None
    if args.compare_with is not None:
        if not args.compare_with.is_file():
            sys.stderr.write(f"slz campaign: --compare-with {args.compare_with}: no such results file\n")
            return 2
        previous = (str(args.compare_with), read_results(args.compare_with))
    try:
        summary = build_report(spec, results, out, previous)
        records = parse_results(results)
    except ResultError as exc:  # a line that is not a campaign result: named, not reported as "n/a"
        sys.stderr.write(f"slz campaign: {exc}\n")
        return 1
    for name, cell in summary["cells"].items():
        success = cell["success"]
        sys.stdout.write(
            f"{name}: {cell['missions']} missions, success {100 * success['value']:.1f} % "
            f"[{100 * success['low']:.1f}, {100 * success['high']:.1f}]\n"
        )
    sys.stdout.write(f"wrote {out / 'report.md'}\n")
    if args.write_baseline:
        baseline = make_baseline(spec, records, source_commit())
        args.write_baseline.parent.mkdir(parents=True, exist_ok=True)
        args.write_baseline.write_text(json.dumps(baseline, indent=1) + "\n")
        sys.stdout.write(f"wrote baseline {args.write_baseline} ({len(baseline['missions'])} missions)\n")
    if args.check_against:
        try:
            gate = check_against(
                spec, records, read_baseline(args.check_against), args.alpha, name=str(args.check_against)
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

    from companion.tools.replay import replay
    from sitl.campaign.metrics import mission_metrics, stale
    from sitl.campaign.report import completed
    from sitl.campaign.runner import read_results
    from sitl.campaign.spec import CampaignSpec
    from sitl.campaign.worker import mission_spec
    from sitl.harness.instances import InstanceError
    from sitl.harness.mission import fly

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
    try:
        with _instance(args.instance) as instance:
            fly(mission_spec(spec, plan, out, instance, record_frames=True))
    except InstanceError as exc:
        sys.stderr.write(f"slz campaign replay: {exc}\n")
        return 1
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
        from sitl.render.snapshot import contact_sheet

        path = contact_sheet(args.seed or 0, args.out)
        sys.stdout.write(f"wrote {path}\n")
        return 0
    from companion.config import validate_config
    from sitl.config import SitlConfig, load_sitl_config
    from sitl.vehicle.process import SitlError, SitlVehicle, install_signal_handlers

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
            "ulog_path": str(args.ulog) if args.ulog else None,
            "live_view_port": args.live_view,
            "duration_s": args.duration,
            "bind_address": args.bind,
        }.items()
        if value is not None
    }
    # By hand, `slz sitl` is what `slz fly --config mission_configs/sitl.yaml` flies: its camera is on. A config file
    # says for itself (the camera's default there is off: most tests and benchmarks need no frames).
    camera = args.camera if args.camera is not None else (None if args.config else True)
    if camera is not None:
        overrides["camera"] = {**base.camera.model_dump(), "enabled": camera}
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


def _sitl_arguments(sitl: argparse.ArgumentParser) -> None:
    """``slz sitl``'s (and ``slz-sitl``'s) arguments."""
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
    sitl.add_argument("--ulog", type=Path, help="write the flight here as a PX4 ULog (.ulg), as PX4's SITL does")
    sitl.add_argument(
        "--live-view", type=int, metavar="PORT", help="serve the truth (people, vehicle) to Foxglove on this port"
    )
    sitl.add_argument("--duration", type=float, help="stop after this many simulated seconds")
    sitl.add_argument("--bind", help="local address (default 127.0.0.1)")
    sitl.add_argument(
        "--camera",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="stream camera frames on TCP 5600 + instance, as `slz fly` needs (default: on; with --config, the "
        "file's sitl.camera.enabled)",
    )
    sitl.set_defaults(func=_cmd_sitl)


def register(subcommands: Any) -> None:
    """Add the lab's commands to ``slz``'s subcommand parsers (the ``slz.commands`` entry point)."""
    _sitl_arguments(
        subcommands.add_parser("sitl", help="run the simulated PX4-style vehicle (MAVLink on UDP 14540/14550)")
    )

    campaign = subcommands.add_parser(
        "campaign", help="fly a campaign of seeded missions and report (or replay one mission)"
    )
    campaign.add_argument("action", nargs="?", choices=["run", "replay"], default="run")
    campaign.add_argument("spec_or_folder", nargs="?", help="replay: the campaign folder")
    campaign.add_argument("mission", nargs="?", help="replay: the mission id (condition/strategy/run)")
    campaign.add_argument("--spec", type=Path, help="campaign spec (mission_configs/campaigns/*.yaml)")
    campaign.add_argument("--out", type=Path, help="campaign folder (default runs/campaigns/<name>)")
    campaign.add_argument("--workers", type=int, help="parallel missions (default: the spec's)")
    campaign.add_argument("--keep-runs", action="store_true", help="keep every mission's logs")
    campaign.add_argument(
        "--backend",
        choices=["local", "ray"],  # sitl.campaign.runner.Backend (not imported to build the parser)
        default="local",
        help="local: worker processes on this machine (default); ray: Ray tasks on a cluster (the `ray` extra)",
    )
    campaign.add_argument(
        "--address",
        help="ray: the cluster (auto, HOST:PORT of the head, ray://HOST:PORT); default: Ray on this machine",
    )
    campaign.add_argument(
        "--cold",
        action="store_true",
        help="new SITL and companion processes for every mission (default: each worker keeps its own; same results)",
    )
    campaign.add_argument("--report-only", action="store_true", help="rebuild the report from the results")
    campaign.add_argument(
        "--check-against",
        type=Path,
        metavar="BASELINE",
        help="regression gate: exit 1 when a strategy is significantly worse than this baseline on the same scenes",
    )
    campaign.add_argument(
        "--compare-with",
        type=Path,
        metavar="RESULTS",
        help="report: compare each cell's success with an earlier flight of the same spec (its results.jsonl), "
        "mission by mission (McNemar)",
    )
    campaign.add_argument("--alpha", type=float, default=0.05, help="gate: family false-alarm rate (default 0.05)")
    campaign.add_argument("--write-baseline", type=Path, metavar="PATH", help="write this campaign as a baseline")
    campaign.add_argument("--instance", type=int, help="replay: SITL instance, 0 to 39 (default: a free one)")
    campaign.add_argument(
        "--instance-base",
        type=int,
        help="worker k flies SITL instance BASE + k, at most 39 (default: each worker leases a free instance)",
    )
    campaign.set_defaults(func=_cmd_campaign)

    demo = subcommands.add_parser("demo", help="fly one seeded landing mission in the SITL (lockstep) and draw it")
    demo.add_argument("--config", type=Path, default=DEFAULT_MISSION_CONFIG, help="the companion's mission config")
    demo.add_argument("--seed", type=int, default=1, help="the seed of the scene and the mission")
    demo.add_argument("--out", type=Path, default=Path("runs"), help="the run goes into OUT/<time>-seed<N>/")
    demo.add_argument("--instance", type=int, help="SITL instance (ports); default: a free one")
    demo.set_defaults(func=_cmd_demo)


def sitl_main(argv: Sequence[str] | None = None) -> int:
    """``slz-sitl`` and ``python -m sitl``: the vehicle alone (``slz sitl``'s arguments)."""
    parser = Parser(prog="slz-sitl", description="The SLZ Lander SITL vehicle.")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    _sitl_arguments(parser)
    return run_command(parser.parse_args(argv), prog="slz-sitl")
