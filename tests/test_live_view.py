"""The flight live in Foxglove (issue 67): a Foxglove WebSocket client receives every topic the live view serves,
with its schema, from the view itself and from a real SITL flight; a client that stops reading never holds the
flight up; nothing is built for topics nobody watches."""

from __future__ import annotations

import base64
import json
import socket
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from companion.app.live_view_config import LiveViewConfig
from companion.flightlog.foxglove_topics import TOPICS
from sitl.testing.helpers import free_udp_port, sitl_mission_yaml, slz_fly_argv, start_camera_sitl, wait_until

foxglove = pytest.importorskip("foxglove")
pytest.importorskip("websockets")

from companion.app.live_view import LiveView  # noqa: E402  (needs foxglove)
from sitl.testing.foxglove_client import FoxgloveClient  # noqa: E402

REPO_ROOT = Path(__file__).resolve().parent.parent
COMPANION_TOPICS = {topic: schema for topic, schema in TOPICS.items() if not topic.startswith("/truth/")}


def free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.unit
def test_nothing_is_built_for_nobody_and_a_stalled_client_never_holds_the_flight_up() -> None:
    view = LiveView(LiveViewConfig(enabled=True, port=free_tcp_port(), backlog_messages=64))
    record = {"t_s": 1.0, "kind": "decision", "decision": {"phase": "search", "kind": "setpoint", "reason": "r"}}
    try:
        for _ in range(100):
            view.record(record)
        assert view.sent["/slz/decisions"] == 0  # no client: nothing built, nothing sent
        stalled = FoxgloveClient(f"ws://127.0.0.1:{view.port}", stall=True)
        reader = FoxgloveClient(f"ws://127.0.0.1:{view.port}")
        wait_until(lambda: stalled.by_topic and reader.by_topic, 10, "both clients' subscriptions sent")

        def probe_arrived() -> bool:  # the server took the subscriptions: a probe reaches the reader
            view.record({**record, "t_s": 1.5})
            return reader.received()["/slz/decisions"].count > 0

        wait_until(probe_arrived, 10, "a probe at the reader")
        start = time.perf_counter()
        for k in range(5000):  # far beyond the stalled client's 64-message backlog, and the view's own queue
            view.record({**record, "t_s": 2.0 + k * 0.01})
        per_record_us = (time.perf_counter() - start) / 5000 * 1e6
        assert per_record_us < 2000.0  # the flight only queues (a blocked send would take seconds)
        final = {**record, "t_s": 100.0, "decision": {"phase": "land", "kind": "land", "reason": "the last"}}

        def final_arrived() -> bool:  # the newest still reaches a reading client past the stalled one
            view.record(final)
            return reader.received()["/slz/decisions"].last_log_time_ns == 100_000_000_000

        wait_until(final_arrived, 20, "the final decision at the reader")
        got = reader.received()["/slz/decisions"]
        assert got.schema_name == "foxglove.Log"
        assert got.first is not None
        assert got.first["message"] == "search: setpoint (r)"
        assert got.count >= 64
        reader.close()
    finally:
        closing = time.perf_counter()
        view.close()  # with the stalled client still connected
        assert time.perf_counter() - closing < 5.0
        stalled.close()


@pytest.mark.sitl
def test_a_sitl_flight_with_the_live_view_on_serves_every_topic_with_its_schema(tmp_path: Path, instance: int) -> None:
    sitl = start_camera_sitl(tmp_path, instance, seed=1, gcs_port=free_udp_port(), lockstep=True)
    mission = tmp_path / "mission.yaml"
    mission.write_text(sitl_mission_yaml(instance, flights_dir=tmp_path))
    port = free_tcp_port()
    fly = subprocess.Popen(
        [*slz_fly_argv(mission, tmp_path / "flight"), "--live-view", str(port)],
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    client = None
    try:
        client = FoxgloveClient(f"ws://127.0.0.1:{port}", connect_timeout_s=60)
        out, err = fly.communicate(timeout=600)
        received = client.received()
    finally:
        if client is not None:
            client.close()
        if fly.poll() is None:
            fly.kill()
        sitl.stop()
    assert fly.returncode == 0, err[-3000:]
    assert f"live view: ws://127.0.0.1:{port}" in out
    assert set(received) == set(COMPANION_TOPICS)  # advertised: every topic but the truth's
    for topic, schema in COMPANION_TOPICS.items():
        got = received[topic]
        assert got.schema_name == schema, topic
        if topic != "/slz/events":  # events: only when something goes wrong (none in this flight)
            assert got.count >= 1, topic
    records = [json.loads(line) for line in (tmp_path / "flight" / "flight.jsonl").read_text().splitlines()]
    assert received["/slz/decisions"].count <= sum(1 for r in records if r["kind"] == "decision")
    assert received["/slz/phase"].count >= 3  # search ... land, seen live
    grid = received["/slz/map"].first
    assert grid is not None
    cells = np.frombuffer(base64.b64decode(grid["data"]), np.uint8)
    assert cells.size == grid["column_count"] * (cells.size // grid["column_count"]) > 0
    assert set(np.unique(cells)) <= {0, 1, 2}
    assert (cells == 2).any()
    image = received["/camera/image"]
    assert image.first is not None
    assert image.first["format"] == "jpeg"
    times_s = np.array(image.log_times_ns) / 1e9
    assert np.all(np.diff(times_s) >= 0.5 - 1e-6)  # camera_rate_hz 2 on the vehicle's clock


@pytest.mark.sitl
def test_the_sitl_serves_its_truth_live_beside_the_companions_view(tmp_path: Path, instance: int) -> None:
    # Issue 67: `slz sitl --live-view PORT`: every person where they really are, and the vehicle, in Foxglove.
    port = free_tcp_port()
    config = tmp_path / "sitl.yaml"
    config.write_text(f"sitl:\n  camera:\n    enabled: true\n  seed: 3\n  live_view_port: {port}\n")
    from sitl.harness.process import SitlProcess

    sitl = SitlProcess(["--config", str(config), "--speed", "1"], instance, tmp_path).start()
    client = None
    try:
        client = FoxgloveClient(f"ws://127.0.0.1:{port}", connect_timeout_s=30)
        wait_until(
            lambda: client.received().get("/truth/people") and client.received()["/truth/people"].count >= 3,
            30,
            "the truth",
        )
        wait_until(lambda: client.received().get("/tf") and client.received()["/tf"].count >= 2, 30, "the vehicle")
        received = client.received()
        state = sitl.state()
    finally:
        if client is not None:
            client.close()
        sitl.stop()
    people = received["/truth/people"]
    assert people.schema_name == "foxglove.SceneUpdate"
    assert people.first is not None
    assert len(people.first["entities"]) >= 80  # the scenario's crowd, 80-120 people
    assert received["/tf"].schema_name == "foxglove.FrameTransform"
    times_s = np.array(people.log_times_ns) / 1e9
    assert np.all(np.diff(times_s) >= 0.2 - 1e-6)  # 5 Hz of simulated time
    assert times_s[-1] <= state["t_s"] + 1e-6  # stamped with the vehicle's clock
