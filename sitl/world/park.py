"""A seeded city park around the region of interest: ground materials and objects a crowd detector can mistake for
people (benches, bins, bushes, trees whose crowns hide people, parked cars, poles, dark and bright blobs).

The ground is a texture over a square of ``2 * extent_m`` on a side, centred on the ROI, north up (row 0 is north).
Objects are described here and turned into meshes by :mod:`sitl.render`.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from sitl.world.ground import real_ground_texture
from sitl.world.scenario import GroundKind, RealSite, Style

U8Image = npt.NDArray[np.uint8]


class ObjectKind(enum.Enum):
    """Distractors in the park."""

    BENCH = "bench"
    BIN = "bin"
    BUSH = "bush"
    TREE = "tree"
    CAR = "car"
    POLE = "pole"
    DARK_BLOB = "dark_blob"
    BRIGHT_BLOB = "bright_blob"


FLAT_KINDS = frozenset({ObjectKind.DARK_BLOB, ObjectKind.BRIGHT_BLOB})
"""Marks painted on the ground: a vehicle can land on them."""

# Shapes seen from above, as :func:`sitl.render.meshes.object_mesh` builds them.
CAR_WIDTH_M = 1.8
BENCH_SEAT_DEPTH_M = 0.5
BENCH_BACK_M = 0.08  # the backrest's thickness, on the seat's back edge
POLE_LAMP_RADIUS_M = 0.25


@dataclass(frozen=True)
class ParkObject:
    """One object: kind, ground position (north_m, east_m), size (m) and heading (rad), colour (BGR).

    ``size_m`` is a diameter (tree crown, bush, bin, pole) or a length along the heading (car, bench); the heading is
    from north towards east.
    """

    kind: ObjectKind
    north_m: float
    east_m: float
    size_m: float
    height_m: float
    heading_rad: float
    colour_bgr: tuple[int, int, int]

    def footprint_distance_m(self, north_m: float, east_m: float) -> float:
        """Horizontal distance (m) from a point to the object's outline seen from above, 0 inside it.

        Trees count by their crowns, which hide what is under them. ``inf`` for flat marks on the ground
        (:data:`FLAT_KINDS`), which are no obstacle.
        """
        if self.kind in FLAT_KINDS:
            return math.inf
        d_north, d_east = north_m - self.north_m, east_m - self.east_m
        if self.kind in (ObjectKind.CAR, ObjectKind.BENCH):
            half_width = CAR_WIDTH_M / 2 if self.kind is ObjectKind.CAR else BENCH_SEAT_DEPTH_M / 2 + BENCH_BACK_M / 2
            cos_h, sin_h = math.cos(self.heading_rad), math.sin(self.heading_rad)
            along, across = d_north * cos_h + d_east * sin_h, -d_north * sin_h + d_east * cos_h
            return math.hypot(max(abs(along) - self.size_m / 2, 0.0), max(abs(across) - half_width, 0.0))
        radius = max(self.size_m / 2, POLE_LAMP_RADIUS_M) if self.kind is ObjectKind.POLE else self.size_m / 2
        return max(math.hypot(d_north, d_east) - radius, 0.0)


GRASS = ((60, 120, 70), (55, 105, 85), (70, 125, 95), (50, 110, 60))
ASPHALT = (95, 95, 100)
PAVING = ((150, 160, 170), (130, 140, 150))
SAND = (140, 180, 205)
COURT = ((70, 90, 160), (160, 100, 60), (60, 130, 60))


def _noise_shape(shape: tuple[int, int], blur_px: float) -> tuple[tuple[int, int], int]:
    """The shape :func:`smooth_noise` draws at, and its upsampling factor."""
    factor = max(1, int(blur_px // 4))
    return (max(1, shape[0] // factor), max(1, shape[1] // factor)), factor


def smooth_noise(rng: np.random.Generator, shape: tuple[int, int], blur_px: float) -> npt.NDArray[np.float32]:
    """Unit-variance Gaussian noise of correlation length ``blur_px``; smooth fields are made at low resolution."""
    small, factor = _noise_shape(shape, blur_px)
    field = rng.standard_normal(small).astype(np.float32)
    if blur_px > 0:
        field = np.asarray(cv2.GaussianBlur(field, (0, 0), blur_px / factor), dtype=np.float32)
    if factor > 1:
        field = np.asarray(cv2.resize(field, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC), dtype=np.float32)
    std = float(field.std())
    return field / std if std > 0 else field


class Park:
    """Ground texture and objects, from one seed.

    Parameters
    ----------
    seed : int
        Fixes materials, paths, courts and objects.
    roi_side_m : float
        The ROI, kept free of large objects so that people stand in the open (as in the paper's scenes).
    extent_m : float
        Half side of the textured ground.
    texture_res_m : float
        Metres per ground-texture pixel.
    style : Style
        Grass colours: all, or the training or held-out half (dataset style split).
    paint : bool
        False: the layout only (the same objects, from the same random draws, in about a tenth of the time); the
        ground texture is then a 1 x 1 placeholder. For ground-truth questions such as what lies under a touchdown.
    ground : GroundKind
        The texture: painted from the seed, or real photographs (``sitl/world/ground.py``). The objects are the same
        for both (the procedural texture's random draws are made either way).
    ground_site : RealSite
        Real ground: the site whose photographs paint it.
    clear_ne_m : sequence of (north_m, east_m, radius_m)
        Discs no object is placed on (an operator's surveyed sites): a position drawn there is drawn again. Empty,
        the draws (and so the park) are the same as without it.
    """

    def __init__(
        self,
        seed: int,
        roi_side_m: float = 30.0,
        extent_m: float = 45.0,
        texture_res_m: float = 0.05,
        style: Style = Style.ANY,
        paint: bool = True,
        ground: GroundKind = GroundKind.PROCEDURAL,
        ground_site: RealSite = RealSite.CALITERRA,
        clear_ne_m: Sequence[tuple[float, float, float]] = (),
    ) -> None:
        rng = np.random.default_rng([seed, 5])
        site = ground_site if ground is GroundKind.REAL else None
        self.clear_ne_m = tuple(tuple(float(v) for v in disc) for disc in clear_ne_m)
        self.key = (seed, roi_side_m, extent_m, texture_res_m, style, paint, ground, site, self.clear_ne_m)
        """Everything this park is made from (a cache key: two parks with one key are the same park)."""
        self.style = style
        self.extent_m = extent_m
        self.texture_res_m = texture_res_m
        self.painted = paint
        self.ground = ground
        self.ground_bgr = self._ground(rng, paint and ground is GroundKind.PROCEDURAL)
        if paint and ground is GroundKind.REAL:
            size = round(2 * extent_m / texture_res_m)
            rng_ground = np.random.default_rng([seed, 6])
            self.ground_bgr = real_ground_texture(rng_ground, size, texture_res_m, ground_site.value)
        self.objects = self._objects(rng, roi_side_m / 2)

    def _ground(self, rng: np.random.Generator, paint: bool) -> U8Image:
        """The texture; unpainted, every random draw is the same but the images are 1 x 1 (so are the objects)."""
        size = round(2 * self.extent_m / self.texture_res_m)

        def noise(blur_px: float) -> npt.NDArray[np.float32]:
            if paint:
                return smooth_noise(rng, (size, size), blur_px)
            rng.standard_normal(_noise_shape((size, size), blur_px)[0])
            return np.zeros((1, 1), np.float32)

        grasses: tuple[tuple[int, int, int], ...] = {Style.TRAIN: GRASS[:2], Style.HELDOUT: GRASS[2:]}.get(
            self.style, GRASS
        )
        base = np.array(grasses[int(rng.integers(len(grasses)))], dtype=np.float32)
        fine = noise(1.0)
        shade = 1.0 + 0.12 * noise(40.0) + 0.06 * fine
        ground = base[None, None, :] * shade[:, :, None]
        canvas = size if paint else 1
        yy, xx = np.mgrid[0:canvas, 0:canvas].astype(np.float32) - size / 2
        px_per_m = 1.0 / self.texture_res_m
        # Each feature paints the pixels of its mask, computing its colour there only (the colour of a pixel is the
        # same float32 arithmetic as over the whole texture: the same texture, without full-size temporaries).
        # Sand patches and a paved plaza.
        for _ in range(int(rng.integers(1, 3))):
            c = rng.uniform(-0.4, 0.4, size=2) * size
            r = rng.uniform(3.0, 8.0) * px_per_m
            patch = np.hypot(xx - c[0], yy - c[1]) < r * (1 + 0.15 * fine)
            ground[patch] = np.array(SAND, np.float32) * (1 + 0.05 * fine[patch][:, None])
        if rng.random() < 0.7:
            c = rng.uniform(-0.35, 0.35, size=2) * size
            half = rng.uniform(4.0, 9.0) * px_per_m
            plaza = (np.abs(xx - c[0]) < half) & (np.abs(yy - c[1]) < half)
            x_in, y_in = xx[plaza], yy[plaza]
            tiles = ((np.floor(x_in / (0.5 * px_per_m)) + np.floor(y_in / (0.5 * px_per_m))) % 2).astype(np.float32)
            ground[plaza] = np.array(PAVING[0], np.float32)[None, :] * (0.92 + 0.08 * tiles[:, None])
        # A sports court with white markings.
        if rng.random() < 0.6:
            c = rng.uniform(-0.3, 0.3, size=2) * size
            w, h = 14.0 * px_per_m, 26.0 * px_per_m
            court = (np.abs(xx - c[0]) < w / 2) & (np.abs(yy - c[1]) < h / 2)
            ground[court] = np.array(COURT[int(rng.integers(len(COURT)))], np.float32)
            line = 0.08 * px_per_m
            edge = court & (
                (np.abs(np.abs(xx - c[0]) - w / 2 + line) < line) | (np.abs(np.abs(yy - c[1]) - h / 2 + line) < line)
            )
            mid = court & (np.abs(yy - c[1]) < line)
            ground[edge | mid] = np.float32(235.0)
        # Asphalt and paved paths crossing the park.
        for _ in range(int(rng.integers(1, 4))):
            colour = np.array(ASPHALT if rng.random() < 0.5 else PAVING[1], dtype=np.float32)
            width = rng.uniform(2.0, 5.0) * px_per_m
            angle = rng.uniform(0, math.pi)
            offset = rng.uniform(-0.45, 0.45) * size
            path = np.abs(xx * math.sin(angle) - yy * math.cos(angle) - offset) < width / 2
            ground[path] = colour * (1 + 0.04 * fine[path][:, None])
        return np.clip(ground, 0, 255).astype(np.uint8)

    def _objects(self, rng: np.random.Generator, roi_half_m: float) -> list[ParkObject]:
        objects: list[ParkObject] = []

        def place(
            kind: ObjectKind, count: int, size: tuple[float, float], height: tuple[float, float], inside_roi: bool
        ) -> None:
            for _ in range(count):
                while True:
                    n, e = rng.uniform(-self.extent_m + 3, self.extent_m - 3, size=2)
                    clear = all(math.hypot(n - cn, e - ce) >= cr + size[1] / 2 for cn, ce, cr in self.clear_ne_m)
                    if (inside_roi or max(abs(n), abs(e)) > roi_half_m + 1.0) and clear:
                        break
                colour = tuple(int(v) for v in rng.integers(20, 235, size=3))
                objects.append(
                    ParkObject(
                        kind,
                        float(n),
                        float(e),
                        float(rng.uniform(*size)),
                        float(rng.uniform(*height)),
                        float(rng.uniform(-math.pi, math.pi)),
                        colour,  # type: ignore[arg-type]
                    )
                )

        place(ObjectKind.TREE, int(rng.integers(4, 12)), (3.0, 6.0), (4.0, 9.0), inside_roi=False)
        place(ObjectKind.CAR, int(rng.integers(2, 8)), (4.2, 4.8), (1.4, 1.6), inside_roi=False)
        place(ObjectKind.BENCH, int(rng.integers(4, 10)), (1.5, 2.0), (0.45, 0.5), inside_roi=True)
        place(ObjectKind.BIN, int(rng.integers(3, 8)), (0.35, 0.5), (0.8, 1.0), inside_roi=True)
        place(ObjectKind.BUSH, int(rng.integers(4, 12)), (0.6, 1.8), (0.5, 1.4), inside_roi=False)
        place(ObjectKind.POLE, int(rng.integers(3, 8)), (0.12, 0.2), (3.0, 6.0), inside_roi=True)
        place(ObjectKind.DARK_BLOB, int(rng.integers(4, 12)), (0.3, 0.9), (0.0, 0.0), inside_roi=True)
        place(ObjectKind.BRIGHT_BLOB, int(rng.integers(4, 12)), (0.3, 0.9), (0.0, 0.0), inside_roi=True)
        return objects
