"""The SITL instance allocator: a lease is exclusive across processes, skips busy ports and names exhaustion.

Each test takes its instance numbers from the real allocator (the ``instances`` fixture), so nothing else on the
machine uses them, then exercises a private allocator (its own lock folder) on those numbers.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from sitl.config import SitlConfig
from sitl.harness.instances import InstanceError, lease_instance, usable_instances

pytestmark = pytest.mark.unit

REPO_ROOT = Path(__file__).resolve().parent.parent


def test_instance_10_is_never_offered() -> None:
    usable = usable_instances()
    assert 10 not in usable  # its API link would sit on the ground-station port
    assert usable[0] == 0
    assert usable[-1] == 39


def test_two_leases_differ_and_a_released_one_is_offered_again(tmp_path: Path, instances: Callable[[], int]) -> None:
    pair = [instances(), instances()]
    first = lease_instance(pair, lock_dir=tmp_path)
    second = lease_instance(pair, lock_dir=tmp_path)
    assert {first.instance, second.instance} == set(pair)
    with pytest.raises(InstanceError, match=rf"{pair[0]} \(leased\), {pair[1]} \(leased\)"):
        lease_instance(pair, lock_dir=tmp_path)
    first.release()
    assert lease_instance(pair, lock_dir=tmp_path).instance == first.instance


def test_a_lease_held_by_another_process_is_respected_until_that_process_dies(tmp_path: Path, instance: int) -> None:
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from pathlib import Path; from sitl.harness.instances import lease_instance\n"
            f"lease = lease_instance([{instance}], lock_dir=Path({str(tmp_path)!r}))\n"
            "print('leased', flush=True)\n"
            "sys.stdin.read()\n",  # holds the lease until it is killed (or its stdin closes)
        ],
        cwd=REPO_ROOT,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None
        assert holder.stdout.readline().strip() == "leased"
        with pytest.raises(InstanceError, match=rf"{instance} \(leased\)"):
            lease_instance([instance], lock_dir=tmp_path)
    finally:
        holder.kill()  # a killed holder's lock goes with it
        holder.wait(timeout=10)
    deadline = time.monotonic() + 5.0
    while True:
        try:
            assert lease_instance([instance], lock_dir=tmp_path).instance == instance
            break
        except InstanceError:
            assert time.monotonic() < deadline, "the dead holder's lock was not released"


def test_an_instance_with_a_port_in_use_is_skipped(tmp_path: Path, instances: Callable[[], int]) -> None:
    busy, free = instances(), instances()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as squatter:
        squatter.bind(("127.0.0.1", SitlConfig(instance=busy).control_port))
        assert lease_instance([busy, free], lock_dir=tmp_path).instance == free
        with pytest.raises(InstanceError, match=rf"{busy} \(a port in use\)"):
            lease_instance([busy], lock_dir=tmp_path)
