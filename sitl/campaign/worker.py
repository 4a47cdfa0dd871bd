"""What a campaign worker does with one mission, on every backend: its :class:`~sitl.harness.mission.MissionSpec` from
the campaign's plan, the flight on the worker's SITL instance (new processes, or a warm worker's), and the result line
(its metrics, or the error that kept it from flying, with the wall time and the node that flew it).

The local backend (:mod:`sitl.campaign.runner`) and the Ray backend (:mod:`sitl.campaign.ray_backend`) both call
:func:`fly_one`; neither imports the other.
"""

from __future__ import annotations

import atexit
import shutil
import socket
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sitl.campaign.metrics import mission_metrics
from sitl.campaign.spec import CampaignSpec, MissionPlan
from sitl.harness.mission import MissionError, MissionProcesses, MissionSpec, fly
from sitl.harness.process import SitlProcessError
from sitl.harness.warm import ServeProcessError, WarmWorker
from sitl.vehicle.truth import TruthError


def mission_spec(spec: CampaignSpec, plan: MissionPlan, run_dir: Path, instance: int, **extra: Any) -> MissionSpec:
    """The :class:`MissionSpec` of one planned mission."""
    sitl, mission = plan.overrides(spec)
    return MissionSpec(
        seed=plan.seed,
        run_dir=run_dir,
        instance=instance,
        mission_config=spec.mission_config,
        sitl_overrides=sitl,
        mission_overrides=mission,
        timeout_s=spec.timeout_s,
        **extra,
    )


def error_result(plan: MissionPlan, error: str) -> dict[str, Any]:
    """The result line of a mission that could not be flown."""
    return {
        "mission_id": plan.mission_id,
        "condition": plan.condition.name,
        "strategy": plan.strategy.name,
        "run": plan.run,
        "seed": plan.seed,
        "error": error[-2000:],
    }


def node_name() -> str:
    """This node's name in the results: its host name and, in a Ray worker, its Ray node id's first 8 characters.
    Only a Ray worker has Ray imported: a local worker never imports it."""
    host = socket.gethostname()
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        return f"{host}/{ray.get_runtime_context().get_node_id()[:8]}"
    return host


def warm_worker(instance: int) -> WarmWorker:
    """This process's warm worker on ``instance`` (its processes stopped when this process exits)."""
    worker = WarmWorker(instance, Path(tempfile.gettempdir()) / "slz-warm")
    atexit.register(worker.close)
    return worker


def fly_one(
    spec_json: dict[str, Any],
    mission_id: str,
    out_dir: str,
    keep: bool,
    instance: int,
    processes: MissionProcesses | None = None,
) -> dict[str, Any]:
    """Fly one mission on SITL ``instance`` and return its metrics (or its error) as JSON, with the wall time it took
    and the node that flew it (every backend flies a mission through here). ``processes``: a warm worker's, or
    None for new processes."""
    spec = CampaignSpec.model_validate(spec_json)
    plan = next(p for p in spec.missions() if p.mission_id == mission_id)
    run_dir = Path(out_dir) / "missions" / mission_id
    shutil.rmtree(run_dir, ignore_errors=True)  # a mission cut off by a kill starts again from nothing
    started = time.monotonic()
    try:
        fly(mission_spec(spec, plan, run_dir, instance), processes)
        metrics = mission_metrics(run_dir, mission_id, plan.condition.name, plan.strategy.name, plan.run, plan.seed)
        result: dict[str, Any] = metrics.to_json()
    except (MissionError, TruthError, SitlProcessError, ServeProcessError, OSError, ValueError, KeyError) as exc:
        result = error_result(plan, str(exc))
    result["wall_s"] = round(time.monotonic() - started, 3)
    result["node"] = node_name()
    if not keep:
        shutil.rmtree(run_dir, ignore_errors=True)
    return result
