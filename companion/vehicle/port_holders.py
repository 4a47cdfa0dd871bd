"""Who else holds the vehicle's UDP port: a second MAVLink program on ``udpin://0.0.0.0:14540`` splits the telemetry.

Two programs that both bind a UDP port (with ``SO_REUSEPORT``, as MAVSDK's and other MAVLink tools' sockets do) each
get only part of the datagrams: the companion then sees its telemetry stop in bursts and calls the link lost, and
the vehicle is left to whoever holds the rest (issue 65, seen with a second MAVSDK client during a take-off). The
kernel's socket table (``/proc/net/udp`` and ``udp6``, Linux) says how many sockets have the port bound: checked
before the companion binds it (any holder is another program) and during the flight (more than one is a second
program beside it). Where there is no such table (not Linux), the check says it cannot tell (None).
"""

from __future__ import annotations

from pathlib import Path

from companion.config import host_port

TABLES = (Path("/proc/net/udp"), Path("/proc/net/udp6"))


def udp_port_holders(port: int, tables: tuple[Path, ...] = TABLES) -> int | None:
    """How many sockets have UDP ``port`` bound (any address), from the kernel's tables; None where there are none
    to read."""
    found, read = 0, False
    for table in tables:
        try:
            lines = table.read_text(encoding="ascii").splitlines()[1:]
        except OSError:
            continue
        read = True
        for line in lines:
            fields = line.split()
            if len(fields) < 2 or ":" not in fields[1]:
                continue
            try:
                local_port = int(fields[1].rsplit(":", 1)[1], 16)
            except ValueError:
                continue
            found += local_port == port
    return found if read else None


def listening_port(url: str) -> int | None:
    """The UDP port a ``udpin://HOST:PORT`` vehicle URL binds (None for any other kind of link)."""
    if not url.startswith("udpin://"):
        return None
    try:
        return host_port(url, "udpin")[1]
    except ValueError:
        return None


def taken_by_another(url: str) -> str | None:
    """Before the companion binds its vehicle port: why it cannot (another program has it), or None."""
    port = listening_port(url)
    if port is None:
        return None
    holders = udp_port_holders(port)
    if not holders:
        return None
    return (
        f"UDP port {port} is already bound by another program ({holders} socket{'s' * (holders > 1)}): a second "
        "MAVLink program there would take part of the vehicle's telemetry; stop it, or give this vehicle another port"
    )


def shared_now(url: str, own_sockets: int = 1) -> str | None:
    """During the flight: why the vehicle port is shared (another program bound it beside the companion's
    ``own_sockets``), or None."""
    port = listening_port(url)
    if port is None:
        return None
    holders = udp_port_holders(port)
    if holders is None or holders <= own_sockets:
        return None
    return (
        f"a second program bound the vehicle's UDP port {port} ({holders} sockets): the telemetry is split between "
        "them, and the link may be lost"
    )
