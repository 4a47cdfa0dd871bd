"""The ``slz`` command as a user runs it: a real process, real files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.integration


def slz(*args: str, cwd: Path = REPO_ROOT, timeout_s: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "companion.cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
    )


def test_check_config_accepts_the_shipped_config() -> None:
    result = slz("check-config", "mission_configs/perception.yaml", "--show")
    assert result.returncode == 0, result.stderr
    assert "valid" in result.stdout
    assert json.loads(result.stdout.split("\n", 1)[1])["zones"]["n_proposals"] == 10


def test_check_config_names_the_bad_field(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("perception:\n  tracking:\n    iou_threshold: 1.5\n")
    result = slz("check-config", str(bad))
    assert result.returncode == 2
    assert "perception.tracking.iou_threshold: Input should be less than or equal to 1 (got 1.5)" in result.stderr
    assert "Traceback" not in result.stderr


def test_demo_writes_an_annotated_image_and_lands_clear_of_people(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    result = slz("demo", "--seed", "3", "--out", str(out))
    assert result.returncode == 0, result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] >= 20
    assert summary["target_clearance_m"] >= summary["target_radius_m"] > 0
    png = (out / "perception.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(png) > 50_000
    assert "ground truth: nearest person" in result.stdout


def test_demo_with_a_missing_model_fails_clearly(tmp_path: Path) -> None:
    config = tmp_path / "c.yaml"
    config.write_text(f"perception:\n  model:\n    path: {tmp_path / 'none.onnx'}\n")
    result = slz("demo", "--config", str(config), "--out", str(tmp_path / "out"))
    assert result.returncode == 1
    assert "density.load: model file not found" in result.stderr
    assert not (tmp_path / "out").exists()


def test_sitl_snapshot_writes_a_contact_sheet(tmp_path: Path) -> None:
    out = tmp_path / "sheet.png"
    result = slz("sitl", "snapshot", "--seed", "2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    import cv2

    sheet = cv2.imread(str(out))
    assert sheet is not None
    assert sheet.shape == (6 * 244, 3 * (2 * 320 + 4), 3)  # six conditions x three altitudes, frame + mask each
    assert sheet[:, 320:640].max() == 255  # the first mask column shows people
