"""Run a campaign: its missions in parallel worker processes, a scene's missions by one worker in a row, each result
appended (and fsync'd) as its scene finishes.

A campaign folder holds ``spec.yaml`` (the spec it was started with), ``results.jsonl`` (one line per finished
mission), ``segments.jsonl`` (when each run of the campaign flew, at which commit, with how many workers: see
:mod:`sitl.campaign.provenance`) and, while missions fly, ``missions/<condition>/<strategy>/<run>/``. Started again
on the same folder, it resumes: finished missions are not flown again, a mission cut off mid-way, or one that failed
for an infrastructure reason (a process that did not start), is flown again from the start (its folder is cleared
first), and the spec must be the one it started with. Each mission is in lockstep, so its result depends on its seed
and config only, not on the number of workers or the machine's speed.
"""

from __future__ import annotations

import collections
import concurrent.futures
import contextlib
import enum
import json
import logging
import multiprocessing
import os
import signal
import sys
import time
from collections.abc import Callable
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any, TextIO

import yaml

from companion.config import ConfigError, read_yaml_file, validate_config
from companion.errors import SlzError
from companion.flightlog.recorder import open_append, read_log
from sitl.campaign.metrics import stale
from sitl.campaign.provenance import SegmentLog, source_commit, utc_now
from sitl.campaign.spec import CampaignSpec, MissionPlan
from sitl.campaign.worker import error_result, fly_one, warm_worker
from sitl.config import MAX_INSTANCE, SitlConfig
from sitl.harness.instances import InstanceLease, lease_instance
from sitl.harness.warm import WarmWorker

logger = logging.getLogger(__name__)

# By default each worker leases a free SITL instance for its lifetime (sitl.harness.instances), so campaigns, tests
# and demos share a machine. With an explicit instance base, worker k flies instance BASE + k.
INSTANCE_BASE = 30


class CampaignError(SlzError):
    """A campaign cannot start or resume (which folder, what is wrong)."""


def worker_instances(instance_base: int, workers: int) -> list[int]:
    """The SITL instances of ``workers`` workers from ``instance_base``; a clear error where one cannot be flown."""
    if workers < 1:
        raise CampaignError(f"workers must be at least 1, got {workers}")
    instances = list(range(instance_base, instance_base + workers))
    if instances[0] < 0 or instances[-1] > MAX_INSTANCE:
        raise CampaignError(
            f"{workers} workers from instance base {instance_base} need SITL instances {instances[0]} to "
            f"{instances[-1]}; instances are 0 to {MAX_INSTANCE} (PX4's ports meet from 40 up): "
            f"lower --instance-base to at most {MAX_INSTANCE + 1 - workers}"
        )
    for instance in instances:  # the SITL's own checks (an API link on the ground-station port)
        try:
            validate_config(SitlConfig, {"instance": instance}, source="campaign workers", prefix="sitl")
        except ConfigError as exc:
            raise CampaignError(f"{exc}; choose another --instance-base") from None
    return instances


_worker_instance = INSTANCE_BASE
_worker_lease: InstanceLease | None = None
_worker_warm: WarmWorker | None = None


def _init_worker(instances: Any, warm: bool) -> None:
    global _worker_instance, _worker_lease, _worker_warm
    if instances is None:  # lease a free instance for this worker's lifetime (released when it exits)
        _worker_lease = lease_instance()
        _worker_instance = _worker_lease.instance
    else:
        _worker_instance = int(instances.get())
    if warm:
        _worker_warm = warm_worker(_worker_instance)
    logging.basicConfig(level=logging.WARNING)
    # SIGTERM ends a worker at once (the default action: the pool would catch an exception and fly the next
    # mission); its SITL and companion get SIGTERM from the kernel as it dies (sitl.harness.process.die_with_parent).
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _fly_scene(
    spec_json: dict[str, Any], mission_ids: list[str], out_dir: str, keep: bool
) -> list[tuple[str, dict[str, Any] | Exception]]:
    """In a local worker process: :func:`fly_one` for each mission of one scene, one after the other, on the worker's
    SITL instance (and its warm processes, whose caches then build the scene once); each mission's result, or the
    exception it raised."""
    outcomes: list[tuple[str, dict[str, Any] | Exception]] = []
    for mission_id in mission_ids:
        try:
            outcomes.append((mission_id, fly_one(spec_json, mission_id, out_dir, keep, _worker_instance, _worker_warm)))
        except Exception as exc:  # a mission's own failure: recorded, flown again on resume
            outcomes.append((mission_id, exc))
    return outcomes


def scene_groups(todo: list[MissionPlan]) -> list[list[MissionPlan]]:
    """``todo`` grouped by scene (condition and run: one seed, so one park, one crowd, one weather), each group in
    ``todo``'s order, the groups in the order of their first mission. A warm worker that flies a scene's strategies
    in a row builds its scene once (the scene caches of :mod:`sitl.render.camera`); spread over workers, each would
    build it."""
    groups: dict[tuple[str, int], list[MissionPlan]] = {}
    for plan in todo:
        groups.setdefault((plan.condition.name, plan.run), []).append(plan)
    return list(groups.values())


def _stop_workers(pool: concurrent.futures.ProcessPoolExecutor) -> None:
    """Cancel the missions not started and terminate the workers (their SITLs and companions die with them)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())  # public only from Python 3.14
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        with contextlib.suppress(OSError, ValueError):
            process.terminate()


def read_results(path: Path) -> list[dict[str, Any]]:
    """The missions of a campaign folder's ``results.jsonl`` as stored lines, one per mission (a later line for the same
    mission, a re-flown error, supersedes the earlier one), in file order; a torn last line is skipped. What resumes a
    campaign and completes an older result reads these; the report, the gate and the benchmark read them typed
    (:func:`sitl.campaign.record.parse_results`)."""
    latest: dict[str, dict[str, Any]] = {}
    for record in read_log(path) if path.is_file() else []:
        latest.pop(record["mission_id"], None)
        latest[record["mission_id"]] = record
    return list(latest.values())


class Progress:
    """A one-line progress bar on stderr: missions done, rate, ETA, failures, and missions per node."""

    def __init__(self, total: int, done: int, stream: TextIO = sys.stderr) -> None:
        self.total, self.done, self.stream = total, done, stream
        self._start_done = done
        self._start = time.monotonic()
        self.failures = 0
        self.nodes: collections.Counter[str] = collections.Counter()

    def count(self, result: dict[str, Any]) -> None:
        """Note one finished mission's result (its node, whether it failed)."""
        self.failures += "error" in result
        self.nodes[str(result.get("node", "?"))] += 1

    def update(self, done: int) -> None:
        """Redraw with ``done`` missions finished."""
        self.done = done
        elapsed = time.monotonic() - self._start
        flown = done - self._start_done
        rate_per_h = 3600.0 * flown / elapsed if elapsed > 0 and flown else 0.0
        eta = (self.total - done) / rate_per_h * 60.0 if rate_per_h else float("nan")
        width = 30
        filled = round(width * done / max(self.total, 1))
        nodes = ", ".join(f"{node} {n}" for node, n in sorted(self.nodes.items()))
        self.stream.write(
            f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{self.total} missions, {rate_per_h:.0f}/h, "
            f"ETA {eta:.0f} min, {self.failures} failed" + (f"; by node: {nodes} " if nodes else " ")
        )
        self.stream.flush()

    def close(self) -> None:
        """End the line."""
        self.stream.write("\n")
        self.stream.flush()


def missions_to_fly(plans: list[MissionPlan], done: dict[str, dict[str, Any]]) -> list[MissionPlan]:
    """The planned missions without a usable result, run by run across the cells (so a campaign stopped part-way has
    every cell about equally far). A mission is flown again when it could not be flown (an infrastructure error, not
    a landing) or its result is :func:`~sitl.campaign.metrics.stale` (computed by definitions since changed)."""
    todo = [
        p
        for p in plans
        if p.mission_id not in done
        or "error" in done[p.mission_id]
        or stale(done[p.mission_id], p.strategy.policy.value)
    ]
    return sorted(todo, key=lambda p: p.run)


class Backend(str, enum.Enum):
    """Where a campaign's missions fly."""

    LOCAL = "local"  # worker processes on this machine (no Ray needed)
    RAY = "ray"  # Ray tasks on a Ray cluster (sitl.campaign.ray_backend)


def _run_local(
    spec_json: dict[str, Any],
    todo: list[MissionPlan],
    out_dir: Path,
    keep_runs: bool,
    workers: int,
    worker_ids: list[int] | None,
    record: Callable[[str, dict[str, Any] | BaseException], None],
    warm: bool,
) -> None:
    """Fly ``todo`` in ``workers`` spawned worker processes (each with its warm processes when ``warm``), a scene's
    missions by one worker in a row (:func:`scene_groups`); each result (or exception) to ``record`` as its scene
    ends."""
    context = multiprocessing.get_context("spawn")
    instances = None
    if worker_ids is not None:
        instances = context.Queue()
        for instance in worker_ids:
            instances.put(instance)
    with concurrent.futures.ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_init_worker, initargs=(instances, warm)
    ) as pool:
        futures = {
            pool.submit(_fly_scene, spec_json, [p.mission_id for p in group], str(out_dir), keep_runs): group
            for group in scene_groups(todo)
        }
        try:
            for future in concurrent.futures.as_completed(futures):
                try:
                    outcomes: list[tuple[str, dict[str, Any] | Exception]] = future.result()
                except BrokenProcessPool as exc:  # a worker died: the missions not finished stay unflown
                    raise CampaignError(
                        f"a worker process died ({exc}); the missions not finished are flown when the "
                        "campaign is started again"
                    ) from None
                except Exception as exc:  # the results could not come back (one that cannot be unpickled)
                    outcomes = [(p.mission_id, exc) for p in futures[future]]
                for mission_id, outcome in outcomes:
                    record(mission_id, outcome)
        except BaseException:  # Ctrl-C or a dead worker: no more missions, those in flight stopped
            _stop_workers(pool)
            raise


def check_folder_spec(spec: CampaignSpec, out_dir: Path) -> bool:
    """Whether ``out_dir`` holds a campaign's ``spec.yaml`` (False: none yet); :class:`CampaignError` when that
    campaign is not ``spec`` (flying or reporting it there would file its missions under the wrong campaign)."""
    spec_path = out_dir / "spec.yaml"
    if not spec_path.is_file():
        return False
    saved = read_yaml_file(spec_path)
    if saved != spec.model_dump(mode="json"):
        name = saved.get("name") if isinstance(saved, dict) else None
        raise CampaignError(
            f"{out_dir} holds another campaign's results ({name or 'its spec.yaml'} differs from {spec.name}); "
            "use that campaign's spec, or a new folder"
        )
    return True


def run_campaign(
    spec: CampaignSpec,
    out_dir: Path,
    workers: int | None = None,
    keep_runs: bool = False,
    on_result: Callable[[dict[str, Any]], None] | None = None,
    progress: bool = True,
    instance_base: int | None = None,
    backend: Backend = Backend.LOCAL,
    address: str | None = None,
    warm: bool = True,
) -> list[dict[str, Any]]:
    """Fly every mission of ``spec`` not yet in ``out_dir/results.jsonl``; returns all results in plan order.

    ``backend`` says where: local worker processes (``workers`` of them, on ``instance_base`` + k or leased
    instances), or Ray tasks on the cluster at ``address`` (None: a Ray instance on this machine with ``workers``
    CPUs). ``warm``: each worker keeps a SITL and a companion process across its missions (:mod:`sitl.harness.warm`);
    False starts both anew for every mission. Every backend writes the same results, warm or not: a mission's
    depends on its seed and config alone.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    spec_json = spec.model_dump(mode="json")
    if not check_folder_spec(spec, out_dir):
        (out_dir / "spec.yaml").write_text(yaml.safe_dump(spec_json, sort_keys=False))
    results_path = out_dir / "results.jsonl"
    done = {r["mission_id"]: r for r in read_results(results_path)}
    plans = spec.missions()
    by_id = {p.mission_id: p for p in plans}
    todo = missions_to_fly(plans, done)
    workers = workers or spec.workers
    if backend is Backend.RAY and instance_base is not None:
        raise CampaignError("--instance-base is for the local backend: on Ray every mission leases a free instance")
    worker_ids = worker_instances(instance_base, workers) if instance_base is not None else None

    policies = spec.policies()

    def flown() -> int:  # an error or a stale result is not a mission done: it is flown again
        return sum("error" not in r and not stale(r, policies.get(k)) for k, r in done.items())

    bar = Progress(len(plans), flown()) if progress else None
    if todo:
        segment_log = SegmentLog(out_dir / "segments.jsonl")
        commit = source_commit()
        segment = segment_log.start(commit, workers, flown())
        stamp = {"segment": segment, "commit": commit}
        flown_here, interrupted = 0, True
        try:
            with open_append(results_path) as results:

                def record(mission_id: str, outcome: dict[str, Any] | BaseException) -> None:
                    nonlocal flown_here
                    if isinstance(outcome, BaseException):
                        result = error_result(by_id[mission_id], f"{type(outcome).__name__}: {outcome}")
                    else:
                        result = outcome
                    result |= stamp | {"finished_utc": utc_now()}
                    results.write(json.dumps(result, separators=(",", ":")) + "\n")
                    results.flush()
                    os.fsync(results.fileno())  # a kill loses at most the scenes in flight
                    done[result["mission_id"]] = result
                    flown_here += "error" not in result
                    if on_result is not None:
                        on_result(result)
                    if bar is not None:
                        bar.count(result)
                        bar.update(flown())

                if backend is Backend.RAY:
                    from sitl.campaign.ray_backend import RayBackendError, run_on_ray

                    try:
                        ids = [p.mission_id for p in todo]
                        run_on_ray(spec_json, ids, out_dir, keep_runs, address, workers, record, warm)
                    except RayBackendError as exc:
                        raise CampaignError(str(exc)) from None
                else:
                    _run_local(spec_json, todo, out_dir, keep_runs, workers, worker_ids, record, warm)
            interrupted = False
        finally:
            segment_log.end(segment, flown_here, interrupted)
    if bar is not None:
        bar.update(flown())
        bar.close()
    return [done[p.mission_id] for p in plans]
