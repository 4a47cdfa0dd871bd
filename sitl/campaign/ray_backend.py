"""Ray as the campaign's distributed backend: the same missions as Ray tasks, on every node of a cluster.

Each mission is one Ray task (``num_cpus=1``, so Ray runs one per CPU it is given) in a Ray worker process, which Ray
keeps between tasks (its imports stay warm). The task leases a free SITL instance on its node
(:mod:`sitl.instances`), flies the mission exactly as the local backend does (:func:`sitl.campaign.runner.fly_one`),
gives the instance back and returns the result's JSON. The driver streams the results into the same resumable
campaign folder as they finish. When a node dies, Ray flies its missions in flight again on another node
(``max_retries``): the mission's SITL and companion die with their worker (``sitl.process.die_with_parent``), and a
mission is in lockstep, so where and how often it was started does not change its result.

A mission's folder (``missions/<id>``) is made under the campaign folder when the node sees that folder (the driver's
machine, or a shared file system), else under the node's temporary directory; ``--keep-runs`` keeps it there.

Ray is an optional dependency (the ``ray`` extra): nothing imports it unless this backend is chosen.
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

logger = logging.getLogger(__name__)

MAX_RETRIES = 3  # a mission is flown again this many times when its node or worker dies
WAIT_S = 1.0  # the driver wakes at least this often (wall), to notice an interrupt


class RayBackendError(Exception):
    """Ray is missing, or the cluster cannot be reached (the address, and what went wrong)."""


def fly_on_node(spec_json: dict[str, Any], mission_id: str, out_dir: str, keep: bool) -> dict[str, Any]:
    """In a Ray worker: lease a SITL instance on this node, fly the mission, give the instance back."""
    from sitl.campaign.runner import fly_one
    from sitl.instances import leased_instance

    folder = Path(out_dir)
    if not folder.is_dir():  # another machine than the driver's, without a shared file system
        folder = Path(tempfile.gettempdir()) / "slz-campaigns" / folder.name
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
            pending[fly.remote(spec_json, mission_id, str(out_dir), keep)] = mission_id
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
