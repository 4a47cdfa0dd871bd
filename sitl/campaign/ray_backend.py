"""Ray as the campaign's distributed backend: the same missions as Ray tasks, on every node of a cluster.

Each mission is one Ray task (``num_cpus=1``, so Ray runs one per CPU it is given) in a Ray worker process, which Ray
keeps between tasks. At its first mission a worker leases a free SITL instance on its node
(:mod:`sitl.harness.instances`) and starts its warm SITL and companion processes (:mod:`sitl.harness.warm`), kept for
its later missions; each task flies its mission exactly as the local backend does (:func:`sitl.campaign.worker.fly_one`)
and returns the result's JSON. The driver streams the results into the same resumable campaign folder as they finish.
When a node dies, Ray flies its missions in flight again on another node (``max_retries``): the mission's SITL and
companion die with their worker (``sitl.harness.process.die_with_parent``), and a mission is in lockstep, so where and
how often it was started does not change its result.

A mission's folder (``missions/<id>``) is made under the campaign folder when the node sees that folder (the driver's
machine, or a shared file system), else under the node's temporary directory; ``--keep-runs`` keeps it there.

Ray is an optional dependency (the ``ray`` extra): nothing imports it unless this backend is chosen.
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from companion.errors import SlzError

if TYPE_CHECKING:
    from sitl.harness.instances import InstanceLease
    from sitl.harness.warm import WarmWorker

logger = logging.getLogger(__name__)

MAX_RETRIES = 3  # a mission is flown again this many times when its node or worker dies
WAIT_S = 1.0  # the driver wakes at least this often (wall), to notice an interrupt


class RayBackendError(SlzError):
    """Ray is missing, or the cluster cannot be reached (the address, and what went wrong)."""


_warm: WarmWorker | None = None  # this Ray worker process's warm processes, on the instance it leased for life
_warm_lease: InstanceLease | None = None


def fly_on_node(spec_json: dict[str, Any], mission_id: str, out_dir: str, keep: bool, warm: bool) -> dict[str, Any]:
    """In a Ray worker: fly the mission on this worker's warm processes (leasing a SITL instance for the worker's
    lifetime at its first mission), or, not ``warm``, lease an instance for this mission alone."""
    global _warm, _warm_lease
    from sitl.campaign.worker import fly_one, warm_worker
    from sitl.harness.instances import lease_instance, leased_instance

    folder = Path(out_dir)
    if not folder.is_dir():  # another machine than the driver's, without a shared file system
        folder = Path(tempfile.gettempdir()) / "slz-campaigns" / folder.name
    if warm:
        if _warm is None:
            _warm_lease = lease_instance()  # held until this worker process exits
            _warm = warm_worker(_warm_lease.instance)
        return fly_one(spec_json, mission_id, str(folder), keep, _warm.instance, _warm)
    with leased_instance() as lease:
        return fly_one(spec_json, mission_id, str(folder), keep, lease.instance)


def run_on_ray(
    spec_json: dict[str, Any],
    mission_ids: Iterable[str],
    out_dir: Path,
    keep: bool,
    address: str | None,
    workers: int,
    record: Callable[[str, dict[str, Any] | BaseException], None],
    warm: bool = True,
) -> None:
    """Fly ``mission_ids`` as Ray tasks and hand each result (or the exception that ended it) to ``record``, in the
    order they finish.

    Parameters
    ----------
    address : str or None
        ``auto`` (the cluster this machine belongs to, started with ``ray start``), ``HOST:PORT`` of a head node,
        ``ray://HOST:PORT`` (Ray Client), or None: a Ray instance on this machine with ``workers`` CPUs.
    """
    try:
        import ray
        from ray.exceptions import RayError
    except ImportError:
        raise RayBackendError("the ray backend needs Ray: pip install 'slz-lander[ray]'") from None
    try:
        if address is None:
            ray.init(num_cpus=workers, include_dashboard=False, logging_level=logging.WARNING, log_to_driver=False)
        else:
            ray.init(address=address, logging_level=logging.WARNING, log_to_driver=False)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise RayBackendError(f"cannot reach the Ray cluster at {address}: {exc}") from None
    pending: dict[Any, str] = {}
    try:
        fly = ray.remote(num_cpus=1, max_retries=MAX_RETRIES, retry_exceptions=False)(fly_on_node)
        for mission_id in mission_ids:
            pending[fly.remote(spec_json, mission_id, str(out_dir), keep, warm)] = mission_id
        logger.info("%d missions on Ray", len(pending))
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=WAIT_S)
            for ref in ready:
                mission_id = pending.pop(ref)
                try:
                    record(mission_id, ray.get(ref))
                except RayError as exc:  # its retries spent (the nodes kept dying), or the task raised
                    record(mission_id, exc)
    except BaseException:  # Ctrl-C or a failed write: the missions in flight are stopped
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
    finally:
        ray.shutdown()
