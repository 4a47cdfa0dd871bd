"""A second program on the vehicle's UDP port, noticed (issue 65: another MAVSDK client bound 14540 during a take-off
and the companion only saw "link lost"), and MAVSDK's own log lines, plain."""

from __future__ import annotations

import logging
import socket
from pathlib import Path

import pytest

from companion.vehicle.link import VehicleError
from companion.vehicle.mavsdk_link import MavsdkVehicleLink
from companion.vehicle.port_holders import listening_port, shared_now, taken_by_another, udp_port_holders
from sitl.testing.helpers import free_udp_port

TABLE = """  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode ref
  621: 0100007F:38EC 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 577977 2 0000 0
  624: 00000000:38EC 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 580297 2 0000 0
  630: 00000000:15E0 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 580298 2 0000 0
"""


@pytest.mark.unit
def test_the_kernels_table_counts_every_socket_on_a_port(tmp_path: Path) -> None:
    table = tmp_path / "udp"
    table.write_text(TABLE)
    assert udp_port_holders(0x38EC, (table,)) == 2  # 14572, on loopback and on any address
    assert udp_port_holders(0x15E0, (table,)) == 1
    assert udp_port_holders(9, (table,)) == 0
    assert udp_port_holders(0x38EC, (tmp_path / "none",)) is None  # no table: cannot tell
    assert listening_port("udpin://0.0.0.0:14540") == 14540
    assert listening_port("serial:///dev/ttyTHS1:921600") is None


@pytest.mark.unit
def test_a_port_another_program_holds_is_named_before_the_companion_binds_it_and_a_second_one_during() -> None:
    port = free_udp_port()
    url = f"udpin://0.0.0.0:{port}"
    assert taken_by_another(url) is None
    first = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    first.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as MAVSDK binds it
    first.bind(("0.0.0.0", port))
    try:
        taken = taken_by_another(url)
        assert taken is not None
        assert f"UDP port {port} is already bound by another program (1 socket)" in taken
        assert shared_now(url) is None  # one socket: the companion's own
        second = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        second.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # a second MAVSDK client
        second.bind(("0.0.0.0", port))
        try:
            shared = shared_now(url)
            assert shared is not None
            assert f"a second program bound the vehicle's UDP port {port} (2 sockets)" in shared
        finally:
            second.close()
    finally:
        first.close()


@pytest.mark.integration
async def test_the_link_refuses_a_port_another_program_holds_and_mavsdks_lines_come_plain(
    caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]
) -> None:
    port = free_udp_port()
    squatter = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    squatter.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    squatter.bind(("0.0.0.0", port))
    try:
        with pytest.raises(VehicleError, match=f"UDP port {port} is already bound by another program"):
            await MavsdkVehicleLink(f"udpin://0.0.0.0:{port}").connect(2.0)
    finally:
        squatter.close()

    with caplog.at_level(logging.INFO, logger="mavsdk"):
        link = MavsdkVehicleLink(f"udpin://0.0.0.0:{free_udp_port()}")
        try:
            with pytest.raises(VehicleError, match="no autopilot answered"):
                await link.connect(1.0)
        finally:
            await link.close()
    assert any(r.name == "mavsdk" for r in caplog.records)  # MAVSDK's own lines, through Python's logging
    assert "\x1b[" not in capfd.readouterr().err  # and none of its colour codes printed by itself
