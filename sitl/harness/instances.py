"""One allocator for SITL instances, so SITLs started by tests, campaigns and demos never share ports.

An instance (PX4's layout: every port shifted by the instance number, see :mod:`sitl.config`) is leased by holding an
exclusive ``flock`` on ``<tmp>/slz-sitl-instances/<N>.lock`` and checking that every port of that instance is free
right now (bound and released): the lock keeps out every SITL started through this module, in any checkout and any
user's process on the machine; the port check keeps out the ones that were not (``slz sitl --instance 0`` typed by
hand, a ground station). The lock goes when the lease is released or its process dies, even by ``kill -9``.

A lease does not hold the ports themselves between the check and the SITL's start: a foreign process that binds one
in that instant makes the SITL fail its start loudly (``SitlProcess`` checks the pid behind the control port), never
talk to the wrong vehicle.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import logging
import os
import socket
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from types import TracebackType

from companion.errors import SlzError
from sitl.config import MAX_INSTANCE, SitlConfig

logger = logging.getLogger(__name__)

LOCK_DIR = Path(tempfile.gettempdir()) / "slz-sitl-instances"


class InstanceError(SlzError):
    """No SITL instance could be leased (which were tried, and why)."""


def instance_ports(instance: int) -> list[tuple[int, int]]:
    """Every (socket type, port) an instance's SITL and its clients bind: the vehicle's links, control channel and
    frame server, and MAVSDK's port (where the companion listens)."""
    c = SitlConfig(instance=instance)
    udp, tcp = socket.SOCK_DGRAM, socket.SOCK_STREAM
    return [
        (udp, c.api_port_local),
        (udp, c.api_port_remote),
        (udp, c.gcs_port_local),
        (udp, c.control_port),
        (tcp, c.frame_port),
    ]


def ports_free(instance: int, host: str = "127.0.0.1") -> bool:
    """Every port of ``instance`` can be bound now."""
    for kind, port in instance_ports(instance):
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind((host, port))
            except OSError as exc:
                if exc.errno == errno.EADDRINUSE:
                    return False
                raise
    return True


def usable_instances() -> list[int]:
    """Instances 0..MAX_INSTANCE whose config is valid (instance 10 puts its API link on the GCS port)."""
    out = []
    for instance in range(MAX_INSTANCE + 1):
        try:
            SitlConfig(instance=instance)
        except ValueError:
            continue
        out.append(instance)
    return out


class InstanceLease:
    """A leased SITL instance: use :attr:`instance`, then :meth:`release` (or use it as a context manager)."""

    def __init__(self, instance: int, fd: int) -> None:
        self.instance = instance
        self._fd: int | None = fd

    @property
    def config(self) -> SitlConfig:
        """The instance's default SITL config (its ports and system id)."""
        return SitlConfig(instance=self.instance)

    def release(self) -> None:
        """Give the instance back (idempotent)."""
        if self._fd is not None:
            with contextlib.suppress(OSError):
                fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> InstanceLease:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.release()

    def __del__(self) -> None:
        self.release()


def lease_instance(candidates: Iterable[int] | None = None, lock_dir: Path = LOCK_DIR) -> InstanceLease:
    """Lease the first free instance of ``candidates`` (default: 1..MAX_INSTANCE, from a place that depends on this
    process id, so that parallel test runs seldom try the same ones first).

    Raises
    ------
    InstanceError
        Every candidate is locked by another lease or has a port in use.
    """
    usable = [i for i in usable_instances() if i != 0]  # 0 is PX4's default: left to SITLs started by hand
    if candidates is None:
        start = os.getpid() % len(usable)
        candidates = usable[start:] + usable[:start]
    lock_dir.mkdir(parents=True, exist_ok=True)
    busy: list[str] = []
    for instance in candidates:
        fd = os.open(lock_dir / f"{instance}.lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            busy.append(f"{instance} (leased)")
            continue
        if not ports_free(instance):
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
            busy.append(f"{instance} (a port in use)")
            continue
        logger.debug("leased SITL instance %d", instance)
        return InstanceLease(instance, fd)
    raise InstanceError(f"no free SITL instance: {', '.join(busy) or 'none to try'}")


@contextlib.contextmanager
def leased_instance(candidates: Iterable[int] | None = None) -> Iterator[InstanceLease]:
    """:func:`lease_instance` as a context manager."""
    lease = lease_instance(candidates)
    try:
        yield lease
    finally:
        lease.release()
