"""What the companion tells the ground station: texts at their severity and in chunks, the target and the values,
marked in a dry run, at a bounded rate, and never an exception into the flight logic."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest

from companion.app.ground_report import GroundReport, landing_target
from companion.guidance.landing import LandingPhase
from companion.guidance.vehicle_state import VehicleState
from companion.perception.selection import Target
from companion.vehicle.ground_messages import GroundMessage, StatusText
from companion.vehicle.link import LinkResult, VehicleError
from companion.vehicle.statustext import statustext_chunks

pytestmark = pytest.mark.unit


class RecordingGround:
    """The vehicle link's ground part, recording each message as its name and its fields as they travel (JSON);
    refuses after ``fail_after`` messages."""

    def __init__(self, fail_after: int | None = None) -> None:
        self.sent: list[tuple[str, dict[str, Any]]] = []
        self.fail_after = fail_after

    async def send(self, message: GroundMessage) -> None:
        if self.fail_after is not None and len(self.sent) >= self.fail_after:
            raise VehicleError("fake", "link down", LinkResult.REFUSED)
        self.sent.append((message.message_name, json.loads(json.dumps(message.fields()))))


def report(dry_run: bool = False, fail_after: int | None = None) -> tuple[GroundReport, RecordingGround]:
    link = RecordingGround(fail_after)
    return GroundReport(link, dry_run), link


def test_long_texts_come_in_chunks_short_ones_whole() -> None:
    assert statustext_chunks("short", 6, 9) == [StatusText(severity=6, text="short", id=0, chunk_seq=0)]
    text = "x" * 120
    chunks = statustext_chunks(text, 2, 9)
    assert [len(c.text) for c in chunks] == [50, 50, 20]
    assert {c.id for c in chunks} == {9}
    assert [c.chunk_seq for c in chunks] == [0, 1, 2]
    assert [len(c.text) for c in statustext_chunks("y" * 100, 2, 9)] == [50, 50, 0]  # the empty terminator
    assert statustext_chunks("héllo", 6, 1)[0].text == "h?llo"
    assert sum(len(c.text) for c in statustext_chunks("z" * 1000, 6, 1)) == 200


@pytest.mark.parametrize(
    ("phase", "severity"),
    [
        (LandingPhase.FAILSAFE, 2),
        (LandingPhase.HOLD, 4),
        (LandingPhase.YIELDED, 4),
        (LandingPhase.LAND, 5),
        (LandingPhase.SEARCH, 6),
        (LandingPhase.APPROACH, 6),
    ],
)
async def test_phases_go_out_at_px4_like_severities(phase: LandingPhase, severity: int) -> None:
    ground, link = report()
    await ground.phase(phase, "because")
    ((name, fields),) = link.sent
    assert name == "STATUSTEXT"
    assert fields["severity"] == severity
    assert fields["text"] == f"SLZ {phase.value}: because"


async def test_a_dry_run_is_marked_everywhere() -> None:
    ground, link = report(dry_run=True)
    await ground.phase(LandingPhase.APPROACH, "zone 3")
    state = VehicleState(10.0, 0.0, 0.0, -20.0, 0.0)
    await ground.decision_values(10.0, 4, Target(3.0, 4.0, 2.5, 3), state)
    texts = [f["text"] for n, f in link.sent if n == "STATUSTEXT"]
    assert texts == ["[dry run] SLZ approach: zone 3"]
    values = {f["name"]: f["value"] for n, f in link.sent if n == "NAMED_VALUE_FLOAT"}
    assert values == {"SLZ_ZONES": 4.0, "SLZ_R_M": 2.5, "SLZ_DRY": 1.0}
    (target,) = [f for n, f in link.sent if n == "LANDING_TARGET"]
    assert target["position_valid"] == 0  # an autopilot doing precision landing never acts on a dry run's target


async def test_target_and_values_at_a_bounded_rate_of_vehicle_time() -> None:
    ground, link = report()
    state = VehicleState(0.0, 1.0, 2.0, -20.0, 90.0)
    for i in range(20):  # 20 frames over 2 s of vehicle time
        await ground.decision_values(i * 0.1, 2, Target(4.0, 2.0, 3.0, 1), state)
    targets = [f for n, f in link.sent if n == "LANDING_TARGET"]
    assert len(targets) == 4  # 2 Hz
    t = targets[0]
    assert (t["x"], t["y"], t["z"], t["frame"], t["position_valid"]) == (4.0, 2.0, 0.0, 1, 1)
    assert t["distance"] == pytest.approx(math.sqrt(9 + 400))
    assert t["angle_y"] == pytest.approx(math.atan2(3.0, 20.0))
    assert t["angle_x"] == pytest.approx(0.0)
    assert t["size_x"] == pytest.approx(2 * math.atan2(3.0, math.sqrt(409)))
    await ground.decision_values(5.0, 0, None, state)
    assert link.sent[-1] == ("NAMED_VALUE_FLOAT", {"time_boot_ms": 5000, "name": "SLZ_DRY", "value": 0.0})
    assert [f["value"] for n, f in link.sent[-3:] if f["name"] == "SLZ_R_M"] == [0.0]


async def test_a_refused_send_is_counted_never_raised() -> None:
    ground, link = report(fail_after=1)
    await ground.phase(LandingPhase.SEARCH, "start")
    assert len(link.sent) == 1
    await ground.phase(LandingPhase.FAILSAFE, "camera lost")  # refused by the link
    assert (ground.sent, ground.failed) == (1, 1)


def test_landing_target_names_its_frame_and_fields() -> None:
    message = landing_target(1.5, Target(0.0, 0.0, 1.0, None), VehicleState(1.5, 0.0, 0.0, -10.0, 0.0), False)
    fields = json.loads(json.dumps(message.fields()))  # as it travels
    assert message.message_name == "LANDING_TARGET"
    assert fields["time_usec"] == 1_500_000
    assert fields["type"] == 3
    assert fields["q"] == [1.0, 0.0, 0.0, 0.0]
