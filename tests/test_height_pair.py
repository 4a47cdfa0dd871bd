"""``slz height-map``: what stands above the ground in two overlapping photographs (issue 64), on rendered photographs
whose truth is known, and its EXIF reading and errors."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from companion.tools.height_pair import HeightPairError, gps_baseline_m, photo_meta, run
from sitl.render.camera import Light, WorldRenderer
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import ScenarioConfig

REPO_ROOT = Path(__file__).resolve().parent.parent
CAMERA = PinholeCamera.from_hfov(640, 480, 90.0)


@pytest.fixture(scope="module")
def photographs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, np.ndarray]:
    """Two nadir frames 3 m apart at 20 m over a park with 60 people, and the first one's person mask."""
    folder = tmp_path_factory.mktemp("pair")
    renderer = WorldRenderer(
        Park(3),
        Crowd(ScenarioConfig(people_min=60, people_max=60), 3),
        CAMERA,
        T_body_camera_from_mount(),
        Light.from_angles(45.0, 80.0, 0.5),
    )
    try:
        a = renderer.render(Pose.from_ned_euler(-1.5, 1.0, -20.0, 0.0, 0.0, 0.4), 0.0)
        b = renderer.render(Pose.from_ned_euler(1.5, 1.0, -20.0, 0.0, 0.0, 0.4), 1.0)
    finally:
        renderer.close()
    cv2.imwrite(str(folder / "a.png"), a.image_bgr)
    cv2.imwrite(str(folder / "b.png"), b.image_bgr)
    return folder / "a.png", folder / "b.png", a.person_mask


@pytest.mark.integration
def test_a_pair_of_rendered_photographs_shows_people_above_flat_ground(
    photographs: tuple[Path, Path, np.ndarray], tmp_path: Path
) -> None:
    a, b, person_mask = photographs
    summary = run(a, b, tmp_path, altitude_m=20.0, hfov_deg=90.0, width_px=640)
    geometry = summary["geometry"]
    assert geometry["baseline_m"] == pytest.approx(3.0, rel=0.05)  # from the altitude and the ground's shift
    assert geometry["baseline_source"] == "from the altitude and the ground's shift"
    assert geometry["focal_px"] == pytest.approx(320.0)
    above = np.asarray(cv2.imread(str(tmp_path / "above_ground.png"), cv2.IMREAD_GRAYSCALE)) > 0
    people = np.asarray(person_mask.reshape(120, 4, 160, 4).any(axis=(1, 3)))
    assert float(above[~people].mean()) < 0.01  # the ground, flat
    assert float(above[people].mean()) > 10 * float(above[~people].mean())  # people stand out above it
    assert summary["share_of_frame_measured_flat"] > 0.5
    assert set(summary["share_of_frame_standing_by_height_band_m"]) == {"0.5-1", "1-2", "2-5", "5-10", ">10"}
    assert np.load(tmp_path / "height_m.npy").shape == (120, 160)
    assert np.asarray(cv2.imread(str(tmp_path / "overlay.png"))).shape == (480, 640, 3)
    assert json.loads((tmp_path / "summary.json").read_text())["geometry"] == geometry
    # The baseline given, the altitude follows from how far the ground moved.
    again = run(a, b, tmp_path / "again", baseline_m=3.0, hfov_deg=90.0, width_px=640)
    assert again["geometry"]["altitude_m"] == pytest.approx(20.0, rel=0.05)


@pytest.mark.integration
def test_without_a_focal_length_or_any_scale_the_tool_says_what_to_give(
    photographs: tuple[Path, Path, np.ndarray], tmp_path: Path
) -> None:
    a, b, _ = photographs
    with pytest.raises(HeightPairError, match="--hfov-deg"):
        run(a, b, tmp_path, altitude_m=20.0, width_px=640)  # PNGs carry no EXIF
    with pytest.raises(HeightPairError, match="--altitude-m or --baseline-m"):
        run(a, b, tmp_path, hfov_deg=90.0, width_px=640)
    elsewhere = tmp_path / "elsewhere.png"  # another scene altogether: nothing in common to match
    cv2.imwrite(str(elsewhere), np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8))
    with pytest.raises(HeightPairError, match=r"overlap|features|plane"):
        run(a, elsewhere, tmp_path, altitude_m=20.0, hfov_deg=90.0, width_px=640)
    with pytest.raises(HeightPairError, match="no baseline"):
        run(a, a, tmp_path, baseline_m=3.0, hfov_deg=90.0, width_px=640)  # the same shot twice: nothing moved


@pytest.mark.unit
def test_exif_gives_the_focal_length_in_pixels_and_the_gps_baseline(tmp_path: Path) -> None:
    from PIL import Image

    def photo(name: str, lat: float, lon: float) -> Path:
        image = Image.new("RGB", (4608, 3456), (90, 120, 80))
        exif = image.getexif()
        exif.get_ifd(0x8769).update({0x920A: 4.88, 0xA20E: 746.27, 0xA210: 4})  # mm, px per mm (unit 4: mm)
        exif.get_ifd(0x8825).update(
            {1: "N", 2: (lat, 0.0, 0.0), 3: "W", 4: (lon, 0.0, 0.0)}  # degrees, minutes, seconds
        )
        path = tmp_path / name
        image.save(path, exif=exif)
        return path

    a = photo("a.jpg", 41.0, 81.0)
    b = photo("b.jpg", 41.0005, 81.0)  # 0.0005 degrees north: 55.7 m
    meta_a, meta_b = photo_meta(a, 1280), photo_meta(b, 1280)
    assert meta_a.focal_px == pytest.approx(4.88 * 746.27 * 1280 / 4608, rel=1e-3)  # 1012 px at 1280 wide
    assert meta_a.focal_source == "EXIF focal length and focal plane resolution"
    assert meta_a.longitude_deg == pytest.approx(-81.0)  # west is negative
    baseline = gps_baseline_m(meta_a, meta_b)
    assert baseline is not None
    assert baseline == pytest.approx(0.0005 * 111_320.0, rel=1e-3)
    assert not math.isnan(baseline)


@pytest.mark.integration
def test_the_command_refuses_bad_numbers_and_names_the_flag(tmp_path: Path) -> None:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "companion.cli",
            "height-map",
            "a.jpg",
            "b.jpg",
            "--out",
            str(tmp_path),
            "--altitude-m",
            "-3",
        ],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2
    assert "--altitude-m must be a positive number" in done.stderr
    missing = subprocess.run(
        [sys.executable, "-m", "companion.cli", "height-map", "no.jpg", "nothing.jpg", "--out", str(tmp_path)],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert missing.returncode == 1
    assert "no.jpg: not a readable image" in missing.stderr
