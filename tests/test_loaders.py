"""Public-dataset loaders, on small files written here."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy import io

from models.data.loaders import DatasetError, load_dronecrowd, load_visdrone_det

pytestmark = pytest.mark.unit


def write_image(path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.zeros((20, 30, 3), np.uint8))


def test_dronecrowd_heads_are_box_centres_of_the_right_frame(tmp_path: Path) -> None:
    write_image(tmp_path / "train_data/images/img011001.jpg")
    write_image(tmp_path / "train_data/images/img011002.jpg")
    (tmp_path / "annotations").mkdir()
    anno = np.array(
        [
            [1, 7, 10, 20, 14, 24],  # frame 1, head around (12, 22)
            [1, 8, 0, 0, 2, 2],  # frame 1, (1, 1)
            [2, 7, 11, 20, 15, 24],  # frame 2, (13, 22)
        ],
        dtype=float,
    )
    io.savemat(str(tmp_path / "annotations/00011.mat"), {"anno": anno})
    images = load_dronecrowd(tmp_path, "train")
    assert [i.image_path.name for i in images] == ["img011001.jpg", "img011002.jpg"]
    np.testing.assert_allclose(images[0].heads_uv, [[12, 22], [1, 1]])
    np.testing.assert_allclose(images[1].heads_uv, [[13, 22]])


def test_dronecrowd_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="train_data/images: no such directory"):
        load_dronecrowd(tmp_path, "train")
    write_image(tmp_path / "train_data/images/img012001.jpg")
    with pytest.raises(DatasetError, match=r"00012\.mat: annotation file missing"):
        load_dronecrowd(tmp_path, "train")
    (tmp_path / "annotations").mkdir()
    io.savemat(str(tmp_path / "annotations/00012.mat"), {"other": np.zeros((2, 6))})
    with pytest.raises(DatasetError, match="cannot read variable 'anno'"):
        load_dronecrowd(tmp_path, "train")


def test_visdrone_keeps_people_and_skips_ignored_regions_and_vehicles(tmp_path: Path) -> None:
    write_image(tmp_path / "images/0000001_00000_d_0000001.jpg")
    (tmp_path / "annotations").mkdir()
    (tmp_path / "annotations/0000001_00000_d_0000001.txt").write_text(
        "100,50,10,30,1,1,0,0\n"  # pedestrian: head at (105, 55)
        "200,60,12,12,1,2,0,1\n"  # people (seen from above): (206, 66)
        "300,70,40,20,1,4,0,0\n"  # car
        "10,10,50,50,0,0,0,0,\n"  # ignored region (score 0)
    )
    (image,) = load_visdrone_det(tmp_path)
    np.testing.assert_allclose(image.heads_uv, [[105, 55], [206, 66]])


def test_visdrone_malformed_line(tmp_path: Path) -> None:
    write_image(tmp_path / "images/a.jpg")
    (tmp_path / "annotations").mkdir()
    (tmp_path / "annotations/a.txt").write_text("100,50,ten,30,1,1,0,0\n")
    with pytest.raises(DatasetError, match="line 1: expected numbers"):
        load_visdrone_det(tmp_path)
