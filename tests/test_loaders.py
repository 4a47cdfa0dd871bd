"""Public-dataset loaders, on small files written here."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy import io

from models.data.loaders import (
    DatasetError,
    hit_uav_altitude_m,
    load_dronecrowd,
    load_real_set,
    load_sdd_reference,
    load_visdrone_det,
)

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


def test_sdd_reference_boxes_are_read_per_image(tmp_path: Path) -> None:
    write_image(tmp_path / "a_video1.jpg")
    write_image(tmp_path / "b_video2.jpg")
    (tmp_path / "boxes.json").write_text(
        json.dumps(
            {
                "source": "test",
                "images": {
                    "b_video2.jpg": {"frame": 3, "people_boxes_xyxy": []},
                    "a_video1.jpg": {"frame": 7, "people_boxes_xyxy": [[1, 2, 5, 9], [10, 0, 12, 4]]},
                },
            }
        ),
        encoding="utf-8",
    )
    frames = load_real_set(tmp_path)
    assert [f.image_path.name for f in frames] == ["a_video1.jpg", "b_video2.jpg"]
    np.testing.assert_array_equal(frames[0].boxes_xyxy, [[1, 2, 5, 9], [10, 0, 12, 4]])
    assert frames[1].boxes_xyxy.shape == (0, 4)
    assert frames[0].altitude_m is None


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"people_boxes_xyxy": [[5, 2, 1, 9]]}, "max >= min"),
        ({"people_boxes_xyxy": [[1, 2, "x", 9]]}, "numbers"),
        ({"people_boxes_xyxy": [[1, 2, float("nan"), 9]]}, "finite"),
        ({"boxes": []}, "people_boxes_xyxy"),
    ],
)
def test_bad_sdd_boxes_are_refused_by_name(tmp_path: Path, entry: dict[str, object], message: str) -> None:
    write_image(tmp_path / "a.jpg")
    (tmp_path / "boxes.json").write_text(json.dumps({"images": {"a.jpg": entry}}), encoding="utf-8")
    with pytest.raises(DatasetError, match=message):
        load_sdd_reference(tmp_path)


def test_hit_uav_coco_people_with_altitude_from_the_name(tmp_path: Path) -> None:
    write_image(tmp_path / "test" / "0_100_30_0_08100.jpg")
    write_image(tmp_path / "test" / "1_60_90_0_00001.jpg")
    (tmp_path / "annotations").mkdir()
    coco = {
        "images": [{"id": 1, "file_name": "0_100_30_0_08100.jpg"}, {"id": 2, "file_name": "1_60_90_0_00001.jpg"}],
        "categories": [{"id": 0, "name": "Person"}, {"id": 1, "name": "Car"}],
        "annotations": [
            {"image_id": 1, "category_id": 0, "bbox": [3, 4, 5, 6]},
            {"image_id": 1, "category_id": 1, "bbox": [0, 0, 10, 10]},  # a car: not a person
        ],
    }
    (tmp_path / "annotations" / "test.json").write_text(json.dumps(coco), encoding="utf-8")
    frames = load_real_set(tmp_path)
    assert [f.image_path.name for f in frames] == ["0_100_30_0_08100.jpg", "1_60_90_0_00001.jpg"]
    np.testing.assert_array_equal(frames[0].boxes_xyxy, [[3, 4, 8, 10]])
    assert frames[1].boxes_xyxy.shape == (0, 4)
    assert (frames[0].altitude_m, frames[1].altitude_m) == (100.0, 60.0)
    assert hit_uav_altitude_m("deathCircle_video2") is None


def test_yolo_people_are_scaled_to_pixels(tmp_path: Path) -> None:
    write_image(tmp_path / "images" / "f1.jpg")  # 30 x 20 px
    write_image(tmp_path / "images" / "f2.jpg")  # no label file: nobody
    (tmp_path / "labels").mkdir()
    (tmp_path / "labels" / "f1.txt").write_text("0 0.5 0.5 0.2 0.5\n2 0.1 0.1 0.1 0.1\n", encoding="utf-8")
    frames = load_real_set(tmp_path)
    np.testing.assert_allclose(frames[0].boxes_xyxy, [[12.0, 5.0, 18.0, 15.0]])
    assert frames[1].boxes_xyxy.shape == (0, 4)
    (tmp_path / "labels" / "f1.txt").write_text("0 0.5 nan 0.2 0.5\n", encoding="utf-8")
    with pytest.raises(DatasetError, match=r"f1\.txt: line 1"):
        load_real_set(tmp_path)


def test_an_unknown_layout_is_named(tmp_path: Path) -> None:
    write_image(tmp_path / "x.jpg")
    with pytest.raises(DatasetError, match="no known layout"):
        load_real_set(tmp_path)
