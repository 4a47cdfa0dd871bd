"""Warm workers: ``slz serve`` runs commands one after another in one process, and a campaign worker's warm SITL
and companion fly mission after mission, a process that died replaced before the next.

That warm missions give the cold missions' results, metric for metric, is checked on the smoke campaign in
``tests/test_campaign.py``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from companion.tools.serve import watch_owner
from sitl.campaign.spec import load_campaign_spec
from sitl.campaign.worker import fly_one
from sitl.harness.instances import leased_instance
from sitl.harness.warm import ServeProcess, ServeProcessError, WarmWorker
from sitl.testing.helpers import wait_until

REPO_ROOT = Path(__file__).resolve().parent.parent
SMOKE = REPO_ROOT / "mission_configs" / "campaigns" / "smoke.yaml"
COMMAND_WALL_S = 60.0  # a config check loads the model: well under a second alone, longer beside a campaign


@pytest.fixture
def serve(tmp_path: Path):  # type: ignore[no-untyped-def]
    process = ServeProcess("companion", ("companion.app.mission",), tmp_path / "serve.log").start()
    yield process
    process.stop()


def run(process: ServeProcess, argv: list[str], log: Path) -> dict[str, object]:
    process.submit(argv, log)
    reply = process.result(COMMAND_WALL_S)
    assert reply is not None, f"{argv} did not finish in {COMMAND_WALL_S} s"
    return reply


@pytest.mark.unit
def test_serve_runs_commands_one_after_another_each_with_its_own_log(serve: ServeProcess, tmp_path: Path) -> None:
    pid = serve.pid
    config = str(REPO_ROOT / "mission_configs" / "sitl.yaml")
    assert run(serve, ["check-config", config], tmp_path / "a.log") == {"exit_code": 0}
    assert "valid for slz fly" in (tmp_path / "a.log").read_text()
    # A bad config: the command's own exit code and message, in its own log; the process serves on.
    assert run(serve, ["check-config", str(tmp_path / "missing.yaml")], tmp_path / "b.log") == {"exit_code": 2}
    assert "missing.yaml" in (tmp_path / "b.log").read_text()
    assert "valid for slz fly" not in (tmp_path / "b.log").read_text()
    # A usage error ends the command (argparse's exit 2), not the process.
    assert run(serve, ["no-such-command"], tmp_path / "c.log") == {"exit_code": 2}
    assert "invalid choice" in (tmp_path / "c.log").read_text()
    assert run(serve, ["check-config", config], tmp_path / "d.log") == {"exit_code": 0}
    assert serve.pid == pid
    assert serve.alive
    assert serve.commands == 4


@pytest.mark.unit
def test_serve_answers_a_malformed_request_and_ends_with_its_input(tmp_path: Path) -> None:
    command = [sys.executable, "-m", "companion.cli", "serve", "--preload", "tests.serve_probe"]
    requests = "not json\n" + json.dumps({"argv": [], "log": str(tmp_path / "x.log")}) + "\n"
    requests += json.dumps({"argv": ["--version"], "log": str(tmp_path / "v.log")}) + "\n"
    done = subprocess.run(
        command, input=requests, capture_output=True, text=True, cwd=REPO_ROOT, timeout=COMMAND_WALL_S
    )
    assert done.returncode == 0, done.stderr
    replies = [json.loads(line) for line in done.stdout.splitlines()]  # only replies reach standard output
    assert replies[0] == {"ready": replies[0]["ready"]}
    assert replies[1]["exit_code"] == 2
    assert "not JSON" in replies[1]["error"]
    assert replies[2] == {"exit_code": 2, "error": "'argv' must be a non-empty list of strings"}
    assert replies[3] == {"exit_code": 0}  # --version prints and exits 0: into its log, not the replies
    assert "slz-lander" in (tmp_path / "v.log").read_text()
    assert len(replies) == 4
    # Between and after commands, the process's own standard error is its own again.
    assert "serve probe: exiting" in done.stderr
    assert "serve probe" not in (tmp_path / "v.log").read_text()


@pytest.mark.unit
def test_one_command_at_a_time_and_a_dead_process_is_reported(serve: ServeProcess, tmp_path: Path) -> None:
    config = str(REPO_ROOT / "mission_configs" / "sitl.yaml")
    serve.submit(["check-config", config], tmp_path / "a.log")
    with pytest.raises(ServeProcessError, match="still running"):
        serve.submit(["check-config", config], tmp_path / "b.log")
    assert wait_until(lambda: serve.result(0.5), COMMAND_WALL_S, "the first command's reply") == {"exit_code": 0}
    os.kill(serve.pid, signal.SIGKILL)

    def next_command() -> None:  # the write fails (a closed pipe) or the reply never comes (the process is gone)
        serve.submit(["check-config", config], tmp_path / "c.log")
        wait_until(lambda: serve.result(0.5), COMMAND_WALL_S, "the process's end noticed")

    with pytest.raises(ServeProcessError, match=r"did not take the command|died"):
        next_command()
    assert not serve.alive
    assert not serve.busy


@pytest.mark.sitl
def test_a_warm_worker_flies_on_after_its_companion_process_is_killed_mid_mission(tmp_path: Path) -> None:
    spec = load_campaign_spec(SMOKE).model_dump(mode="json")
    with leased_instance() as lease:
        worker = WarmWorker(lease.instance, tmp_path / "warm")
        try:
            first = fly_one(spec, "static/oldest/0000", str(tmp_path), True, lease.instance, worker)
            assert "error" not in first, first
            sitl_pid, companion_pid = worker.sitl_process.pid, worker.companion_process.pid

            # Kill the companion process as soon as the second mission's companion has written its flight log.
            log = tmp_path / "missions" / "static" / "biggest" / "0000" / "flight" / "flight.jsonl"

            def kill_when_flying() -> None:
                wait_until(lambda: log.is_file() and log.stat().st_size > 0, 120.0, "the second mission flying")
                os.kill(companion_pid, signal.SIGKILL)

            killer = threading.Thread(target=kill_when_flying)
            killer.start()
            second = fly_one(spec, "static/biggest/0000", str(tmp_path), True, lease.instance, worker)
            killer.join(timeout=130.0)
            assert "error" in second
            assert "died" in second["error"]

            third = fly_one(spec, "moving_20/oldest/0000", str(tmp_path), True, lease.instance, worker)
            assert "error" not in third, third
            assert third["landed"]
            assert worker.companion_process.pid != companion_pid  # a new companion process
            assert worker.sitl_process.pid == sitl_pid  # the SITL's mission ended cleanly: it stayed warm
            assert worker.sitl_process.commands == 3
            # Between missions SIGTERM ends the SITL process as it ends a fresh one (the handler `slz sitl` installs
            # for its mission is put back when the mission ends).
            os.kill(worker.sitl_process.pid, signal.SIGTERM)
            wait_until(lambda: not worker.sitl_process.alive, 10.0, "the idle SITL process ended by SIGTERM")
        finally:
            worker.close()
    assert not worker.sitl_process.alive
    assert not worker.companion_process.alive


def owner_process() -> subprocess.Popen[bytes]:
    """A process that lives until its standard input ends: the owner a watch is given."""
    return subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)


def end(owner: subprocess.Popen[bytes]) -> None:
    assert owner.stdin is not None
    owner.stdin.close()
    owner.wait(timeout=30)


@pytest.mark.unit
def test_a_serve_process_whose_owner_is_gone_exits_after_the_grace() -> None:
    """The owner watch of ``slz serve``: once the process that started it has ended and the serve loop has not finished
    within the grace, the process exits with 1, whatever its command is doing."""
    exits: list[int] = []
    owner = owner_process()
    watch = threading.Thread(target=watch_owner, args=(owner.pid, threading.Event(), 0.05, exits.append), daemon=True)
    watch.start()
    assert exits == [], "the watch acted while its owner lived"
    end(owner)
    watch.join(timeout=10.0)
    assert not watch.is_alive(), "the watch did not act within 10 s of its owner's end"
    assert exits == [1]


@pytest.mark.unit
def test_a_serve_loop_that_ends_within_the_grace_is_not_cut_short() -> None:
    exits: list[int] = []
    finished = threading.Event()
    owner = owner_process()
    watch = threading.Thread(target=watch_owner, args=(owner.pid, finished, 30.0, exits.append), daemon=True)
    watch.start()
    finished.set()  # the loop read the end of its input and returned
    end(owner)
    watch.join(timeout=10.0)
    assert not watch.is_alive(), "the watch did not return within 10 s of its owner's end"
    assert exits == []
