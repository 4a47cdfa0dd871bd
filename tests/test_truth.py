"""The SITL's ground-truth log read back typed: what the vehicle process writes is what a scorer reads, a log from
before the schema reads as version 1, and a broken one names its file and line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sitl.vehicle.truth import (
    TRUTH_SCHEMA_VERSION,
    TruthError,
    TruthHeader,
    TruthRecord,
    body_edges_m,
    clearance_m,
    people_at,
    read_truth,
    touchdown,
)

pytestmark = pytest.mark.unit


def write(path: Path, lines: list[dict[str, object]]) -> Path:
    path.write_text("".join(json.dumps(line) + "\n" for line in lines))
    return path


def test_what_the_writer_writes_reads_back_and_scores(tmp_path: Path) -> None:
    header = TruthHeader(7, 0.0, np.array([[2.0, 0.0], [9.0, 9.0]]), np.array([0.25, 0.3]), (True, False))
    flying = TruthRecord(1.0, (0.0, 0.0, -5.0), True, "OFFBOARD", "IN_AIR", False, np.array([[1.5, 0.0], [9.0, 9.0]]))
    down = TruthRecord(2.0, (0.123456, 0.0, 0.0), True, "AUTO.LAND", "ON_GROUND", True, np.array([[1.0, 0.0], [9, 9]]))
    path = write(tmp_path / "truth.jsonl", [header.to_json(), flying.to_json(), down.to_json()])
    read_header, records = read_truth(path)
    assert read_header.version == TRUTH_SCHEMA_VERSION
    assert read_header.seed == 7
    assert read_header.moving == (True, False)
    assert records[0].to_json() == flying.to_json()
    assert records[1].position_ned_m == (0.1235, 0.0, 0.0)  # written to 0.1 mm
    assert touchdown(records) is records[1]
    # Distances to body edges use the record's walkers when some walk, the header's otherwise.
    edges = body_edges_m(read_header, records[1], 0.0, 0.0)
    assert edges == pytest.approx([1.0 - 0.25, np.hypot(9.0, 9.0) - 0.3])
    assert body_edges_m(read_header, None, 0.0, 0.0)[0] == pytest.approx(2.0 - 0.25)


def test_a_log_from_before_the_schema_reads_as_version_1(tmp_path: Path) -> None:
    old_header = {"kind": "header", "seed": 3, "t_s": 0.0, "positions_ne_m": [], "radii_m": [], "moving": []}
    record = {"kind": "truth", "t_s": 0.1, "position_ned_m": [0, 0, 0], "armed": False, "mode": "AUTO.LOITER",
              "landed_state": "ON_GROUND", "on_ground": True}  # fmt: skip
    header, records = read_truth(write(tmp_path / "truth.jsonl", [old_header, record]))
    assert header.version == 1
    assert records[0].t_s == pytest.approx(0.1)
    assert body_edges_m(header, records[0], 0.0, 0.0).tolist() == [np.inf]  # nobody in the scene


def test_a_broken_log_names_its_file_and_line(tmp_path: Path) -> None:
    header = {"kind": "header", "seed": 3, "positions_ne_m": [], "radii_m": [], "moving": []}
    with pytest.raises(TruthError, match="no ground-truth header"):
        read_truth(write(tmp_path / "a.jsonl", [{"kind": "truth", "t_s": 0.0}]))
    with pytest.raises(TruthError, match=r"b\.jsonl: line 2: missing or bad field 'on_ground'"):
        read_truth(write(tmp_path / "b.jsonl", [header, {"t_s": 0.0, "position_ned_m": [0, 0, 0], "armed": True,
                                                         "mode": "POSCTL", "landed_state": "IN_AIR"}]))  # fmt: skip
    with pytest.raises(TruthError, match="schema version 99"):
        read_truth(write(tmp_path / "c.jsonl", [{**header, "schema_version": 99}]))


def test_the_clearance_of_many_points_is_the_nearest_body_edge_of_each() -> None:
    header = TruthHeader(1, 0.0, np.array([[0.0, 0.0], [4.0, 0.0]]), np.array([0.3, 0.2]), (False, True))
    north, east = np.meshgrid(np.linspace(-2.0, 6.0, 9), np.linspace(-3.0, 3.0, 7), indexing="ij")
    clear = clearance_m(*people_at(header, None), north, east)
    assert clear.shape == (9, 7)
    expected = [
        [body_edges_m(header, None, n, e).min() for n, e in zip(row_n, row_e, strict=True)]
        for row_n, row_e in zip(north, east, strict=True)
    ]
    np.testing.assert_allclose(clear, expected)
    assert clearance_m(np.zeros((0, 2)), np.zeros(0), [1.0], [2.0]).tolist() == [np.inf]
