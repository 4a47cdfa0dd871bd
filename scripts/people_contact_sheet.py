"""A contact sheet of people seen from above: procedural and MakeHuman people at 0.03, 0.045 and 0.09 m/px.

Run: ``.venv/bin/python -m scripts.people_contact_sheet`` writes ``docs/images/people_contact_sheet.png`` (rendered
people only). ``--sdd ../shared/datasets/sdd-reference --out /tmp/sheet.png`` adds a row block of real people (SDD
crops at the same scale) to judge by; the SDD licence is non-commercial and its frames must not be copied into this
repository, so that sheet is refused inside it.

Each tile is a 1.6 m square around a person's head, resampled to the row's ground sample distance and then enlarged
(nearest neighbour) for viewing. SDD's altitude is not recorded: its scale is estimated from the annotated boxes
(the median short side of a box taken as 0.55 m, a person's shoulders and arms from above).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from sitl.render.camera import Light, WorldRenderer
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import PeopleModel, ScenarioConfig

REPO_ROOT = Path(__file__).resolve().parents[1]
GSDS_M_PER_PX = (0.03, 0.045, 0.09)
TILE_M = 1.6
TILE_PX = 96
PER_ROW = 8
SDD_BOX_SHORT_SIDE_M = 0.55

U8Image = npt.NDArray[np.uint8]


def _tile(crop: U8Image) -> U8Image:
    return np.asarray(cv2.resize(crop, (TILE_PX, TILE_PX), interpolation=cv2.INTER_NEAREST), dtype=np.uint8)


def rendered_tiles(model: PeopleModel, gsd_m_per_px: float, seed: int = 4) -> list[U8Image]:
    """Tiles of the people nearest the image centre, rendered from straight above at ``gsd_m_per_px``."""
    camera = PinholeCamera.from_hfov(640, 480, 90.0)
    altitude_m = gsd_m_per_px * camera.fx_px
    config = ScenarioConfig(people=model, moving_fraction=0.0, people_min=110, people_max=110)
    renderer = WorldRenderer(
        Park(seed), Crowd(config, seed), camera, T_body_camera_from_mount(), Light.from_angles(55, 140, 0.45)
    )
    try:
        pose = Pose.from_ned_euler(0.0, 0.0, -altitude_m, 0.0, 0.0, 0.0)
        image = renderer.render(pose, 0.0, with_mask=False, with_depth=False).image_bgr
        half = round(TILE_M / gsd_m_per_px / 2)
        found = []
        for (u_px, v_px), front in zip(*renderer.head_pixels(pose), strict=True):
            u, v = round(u_px), round(v_px)
            if front and half <= u < camera.width_px - half and half <= v < camera.height_px - half:
                found.append((abs(u - camera.cx_px) + abs(v - camera.cy_px), u, v))
        tiles = [_tile(image[v - half : v + half, u - half : u + half]) for _, u, v in sorted(found)[:PER_ROW]]
    finally:
        renderer.close()
    return tiles


def sdd_tiles(root: Path, gsd_m_per_px: float) -> list[U8Image]:
    """Tiles of annotated SDD people at ``gsd_m_per_px`` (scale estimated from the boxes; evaluation data only)."""
    images = json.loads((root / "boxes.json").read_text(encoding="utf-8"))["images"]
    tiles: list[U8Image] = []
    for name, entry in sorted(images.items()):
        boxes = np.array(entry["people_boxes_xyxy"], dtype=np.float64).reshape(-1, 4)
        if not len(boxes):
            continue
        image = cv2.imread(str(root / name))
        if image is None:
            continue
        short = np.minimum(boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1])
        sdd_gsd = SDD_BOX_SHORT_SIDE_M / float(np.median(short))
        half = round(TILE_M / sdd_gsd / 2)
        for x0, y0, x1, y1 in boxes[:2]:
            u, v = int((x0 + x1) / 2), int((y0 + y1) / 2)
            if half <= u < image.shape[1] - half and half <= v < image.shape[0] - half:
                crop = image[v - half : v + half, u - half : u + half]
                side = max(2, round(TILE_M / gsd_m_per_px))
                small = np.asarray(cv2.resize(crop, (side, side), interpolation=cv2.INTER_AREA), dtype=np.uint8)
                tiles.append(_tile(small))
        if len(tiles) >= PER_ROW:
            break
    return tiles[:PER_ROW]


def sheet(sdd_root: Path | None) -> U8Image:
    """The whole sheet: per scale, a row of procedural, a row of MakeHuman (and a row of SDD) people."""
    rows = []
    blank = np.full((TILE_PX, TILE_PX, 3), 255, dtype=np.uint8)
    for gsd in GSDS_M_PER_PX:
        blocks = [(f"procedural {gsd} m/px", rendered_tiles(PeopleModel.PROCEDURAL, gsd))]
        blocks.append((f"makehuman {gsd} m/px", rendered_tiles(PeopleModel.MAKEHUMAN, gsd)))
        if sdd_root is not None:
            blocks.append((f"SDD (real) ~{gsd} m/px", sdd_tiles(sdd_root, gsd)))
        for label, tiles in blocks:
            tiles = (tiles + [blank] * PER_ROW)[:PER_ROW]
            caption = np.full((TILE_PX + 4, 200, 3), 255, dtype=np.uint8)
            cv2.putText(caption, label, (6, TILE_PX // 2 + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1)
            framed = [np.pad(t, ((2, 2), (2, 2), (0, 0)), constant_values=255) for t in tiles]
            rows.append(np.hstack([caption, *framed]))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
    return np.vstack(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images" / "people_contact_sheet.png")
    parser.add_argument("--sdd", type=Path, default=None, help="sdd-reference folder: add real people (not in repo)")
    args = parser.parse_args(argv)
    if args.sdd is not None and args.out.resolve().is_relative_to(REPO_ROOT):
        sys.stderr.write("--sdd: SDD frames must not be copied into the repository; write --out outside it\n")
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out), sheet(args.sdd))
    sys.stdout.write(f"wrote {args.out}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
