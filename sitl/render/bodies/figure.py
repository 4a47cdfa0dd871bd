"""A seeded person built from the body library: body shape x clothes x colours x hair x pose.

:func:`draw_figure` turns a random stream into a :class:`Figure` (what the person is); :func:`figure_mesh` builds
its posed, coloured mesh. Output frame: ENU metres, the person facing north (+y) with the centre of the head above
the origin and the lowest point on z = 0.

Palettes: clothing from above is mostly muted (greys, navy, denim, olive, browns, black, white), a share bright;
skin tones span the library's three ancestries; hair black to blond and grey with age.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt
import trimesh

from sitl.render.bodies.library import (
    AGES,
    ANCESTRIES,
    CELL_DM,
    BodyLibrary,
    BodyPart,
    PartKind,
    Region,
    cluster_vertices,
    load_library,
    to_bvh_axes,
)
from sitl.render.bodies.rig import skin, walk_pose
from sitl.world.crowd import BodyType, Crowd, hue_range
from sitl.world.scenario import PeopleModel

F64Array = npt.NDArray[np.float64]
I64Array = npt.NDArray[np.int64]
U8Array = npt.NDArray[np.uint8]
RGB = tuple[int, int, int]

T_ENU_BVH = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
"""BVH axes (x the body's left, y backwards, z up) to ENU with the body facing north."""
STANDING_POSES = ("standing01", "standing02", "standing03", "standing04", "standing05", "standing06")
WALK_BASE_POSE = "standing02"
WALK_PHASES = 8
"""A walking person's cycle is drawn in this many poses (built once each, then reused)."""
DETAIL_CELLS_M = (CELL_DM / 10.0, 0.105)
"""Levels of detail: the vertex-clustering cell of each, metres (level 0 is the pack's own mesh; level 1 clusters
it again at run time, about half its triangles). A frame draws the coarsest level whose cell is at most
:data:`MAX_CELL_PX` of its pixels (:func:`detail_level`)."""
MAX_CELL_PX = 2.0
"""A level's cell may cover at most this many pixels on the ground: a representative vertex then lies within about a
pixel of the surface it stands for, and the software rasterizer does not pay for triangles far below a pixel."""

MUTED_RGB: tuple[RGB, ...] = (
    (40, 40, 45), (70, 70, 75), (110, 110, 115), (160, 160, 160), (215, 215, 210), (235, 235, 230),
    (35, 45, 80), (50, 70, 110), (75, 100, 140), (60, 80, 60), (95, 100, 70), (120, 95, 70),
    (90, 65, 45), (160, 140, 110), (190, 175, 150), (110, 40, 45), (80, 60, 80), (45, 60, 70),
)  # fmt: skip
"""Muted clothing colours (RGB): black, greys, white, navy, denim, olive, khaki, browns, beige, burgundy."""
SKIN_RGB: dict[str, tuple[RGB, ...]] = {
    "african": ((95, 60, 45), (120, 80, 60), (80, 50, 38), (140, 95, 70)),
    "asian": ((215, 175, 140), (195, 150, 115), (225, 190, 160), (175, 135, 100)),
    "caucasian": ((235, 195, 170), (220, 175, 150), (240, 210, 190), (200, 155, 125)),
}
HAIR_RGB: tuple[RGB, ...] = ((25, 20, 18), (45, 32, 25), (75, 55, 40), (115, 85, 55), (185, 150, 100), (90, 40, 25))
GREY_HAIR_RGB: tuple[RGB, ...] = ((150, 150, 150), (200, 200, 195), (110, 105, 100))


@dataclass(frozen=True)
class Figure:
    """What one person looks like and how they stand (a pure function of a random stream).

    Attributes
    ----------
    sex : str
        ``female`` or ``male`` (selects the proxy body and the garments).
    ancestry_weights : tuple of float
        Mix of :data:`ANCESTRIES` (sums to 1) for the macro targets.
    oldness : float
        0 (young) to 1 (old) between the macro targets.
    shape, shape_weight : str, float
        A body-shape target and how much of it.
    suit, shoes, hair, hat : str or None
        Library part names (hair and hat may be absent).
    pose : str
        A library pose (``standing01``, ``sit01``...); walking people start from it.
    height_m : float
        Standing height.
    skin_rgb, hair_rgb, top_rgb, bottom_rgb, shoes_rgb, hat_rgb : tuple of int
        Colours before lighting.
    """

    sex: str
    ancestry_weights: tuple[float, float, float]
    oldness: float
    shape: str
    shape_weight: float
    suit: str
    shoes: str
    hair: str | None
    hat: str | None
    pose: str
    height_m: float
    skin_rgb: RGB
    hair_rgb: RGB
    top_rgb: RGB
    bottom_rgb: RGB
    shoes_rgb: RGB
    hat_rgb: RGB


def _bright(rng: np.random.Generator, hue_range: tuple[int, int]) -> RGB:
    hsv = np.array(
        [[[int(rng.integers(*hue_range)), int(rng.integers(150, 256)), int(rng.integers(140, 240))]]], dtype=np.uint8
    )
    r, g, b = (int(v) for v in cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0, 0])
    return r, g, b


def _clothing(rng: np.random.Generator, bright_share: float, hue_range: tuple[int, int]) -> RGB:
    if rng.random() < bright_share:
        return _bright(rng, hue_range)
    base = MUTED_RGB[int(rng.integers(len(MUTED_RGB)))]
    jitter = rng.normal(0.0, 8.0, size=3)
    r, g, b = (int(np.clip(c + j, 0, 255)) for c, j in zip(base, jitter, strict=True))
    return r, g, b


def draw_figure(
    rng: np.random.Generator,
    height_m: float,
    sitting: bool = False,
    bright_share: float = 0.25,
    hue_range: tuple[int, int] = (0, 180),
    library: BodyLibrary | None = None,
) -> Figure:
    """A person drawn from ``rng`` (every draw in a fixed order: the same stream gives the same person).

    ``bright_share`` of the garments take a bright colour with an OpenCV hue in ``hue_range``; the rest are muted.
    """
    lib = library or load_library()
    sex = ("female", "male")[int(rng.integers(2))]
    weights = rng.dirichlet((0.4, 0.4, 0.4))
    ancestry_weights = (float(weights[0]), float(weights[1]), float(weights[2]))
    oldness = float(rng.uniform(0.0, 1.0))
    shapes = [name for name in lib.shape_targets if name.startswith("fem" if sex == "female" else "man")]
    shape = shapes[int(rng.integers(len(shapes)))]
    shape_weight = float(rng.uniform(0.0, 0.8))

    def pick(kind: PartKind) -> str:
        options = lib.parts_of(kind, sex)
        return options[int(rng.integers(len(options)))].name

    suit, shoes = pick(PartKind.SUIT), pick(PartKind.SHOES)
    hair = pick(PartKind.HAIR) if rng.random() < 0.9 else None
    hat = pick(PartKind.HAT) if rng.random() < 0.08 else None
    pose = "sit01" if sitting else STANDING_POSES[int(rng.integers(len(STANDING_POSES)))]
    ancestry = ANCESTRIES[int(np.argmax(weights))]
    tones = SKIN_RGB[ancestry]
    skin_rgb = tones[int(rng.integers(len(tones)))]
    grey = oldness > 0.6 and rng.random() < 0.7
    hair_palette = GREY_HAIR_RGB if grey else HAIR_RGB
    hair_rgb = hair_palette[int(rng.integers(len(hair_palette)))]
    top = _clothing(rng, bright_share, hue_range)
    bottom = _clothing(rng, bright_share * 0.4, hue_range)
    shoes_rgb = _clothing(rng, 0.1, hue_range)
    hat_rgb = _clothing(rng, 0.3, hue_range)
    return Figure(
        sex=sex,
        ancestry_weights=ancestry_weights,
        oldness=oldness,
        shape=shape,
        shape_weight=shape_weight,
        suit=suit,
        shoes=shoes,
        hair=hair,
        hat=hat,
        pose=pose,
        height_m=height_m,
        skin_rgb=skin_rgb,
        hair_rgb=hair_rgb,
        top_rgb=top,
        bottom_rgb=bottom,
        shoes_rgb=shoes_rgb,
        hat_rgb=hat_rgb,
    )


@dataclass(frozen=True)
class FigureMesh:
    """A posed, coloured person.

    Attributes
    ----------
    vertices_m : ndarray, shape (N, 3)
        ENU metres, facing north, head centre above the origin, lowest point at z = 0.
    faces : ndarray, shape (F, 3), int64
    colours_rgba : ndarray, shape (N, 4), uint8
        Before lighting.
    head_height_m : float
        Height of the centre of the head above the ground.
    """

    vertices_m: F64Array
    faces: I64Array
    colours_rgba: U8Array
    head_height_m: float


def _shaped_base(lib: BodyLibrary, figure: Figure) -> F64Array:
    base: F64Array = lib.base_vertices.copy()
    sex = figure.sex
    for a, ancestry in enumerate(ANCESTRIES):
        for g, age in enumerate(AGES):
            weight = figure.ancestry_weights[a] * (figure.oldness if g else 1.0 - figure.oldness)
            if weight > 1e-6:
                indices, offsets = lib.macro_targets[(ancestry, sex, age)]
                base[indices] += weight * offsets
    indices, offsets = lib.shape_targets[figure.shape]
    base[indices] += figure.shape_weight * offsets
    return base


def _part(lib: BodyLibrary, name: str) -> BodyPart:
    for p in lib.parts:
        if p.name == name:
            return p
    raise KeyError(name)


def _colours(part: BodyPart, figure: Figure) -> U8Array:
    if part.kind is PartKind.BODY:
        table = {r: figure.skin_rgb for r in Region}
    elif part.kind is PartKind.SUIT:
        table = {Region.SKIN: figure.top_rgb, Region.TOP: figure.top_rgb, Region.BOTTOM: figure.bottom_rgb}
        table[Region.FEET] = figure.bottom_rgb
    elif part.kind is PartKind.HAIR:
        table = {r: figure.hair_rgb for r in Region}
    elif part.kind is PartKind.HAT:
        table = {r: figure.hat_rgb for r in Region}
    else:
        raise ValueError(f"{part.name}: {part.kind.value} parts are not drawn (shoes are painted on the feet)")
    lut = np.array([table[Region(k)] for k in range(len(Region))], dtype=np.float64)
    rgb = lut[part.region]
    # Folds and seams: a fixed +-7 % shade per vertex (a function of the vertex, not of the draw).
    shade = 1.0 + 0.07 * np.sin(np.arange(len(rgb)) * 12.9898) * np.cos(np.arange(len(rgb)) * 4.1414)
    rgba = np.empty((len(rgb), 4), dtype=np.uint8)
    rgba[:, :3] = np.clip(rgb * shade[:, None], 0, 255).astype(np.uint8)
    rgba[:, 3] = 255
    return rgba


@dataclass(frozen=True)
class _Dressed:
    """A figure's dressed body at rest (BVH axes, decimetres), everything but the pose (built once per figure)."""

    heads_rest: F64Array  # (B, 3)
    crown_rest: F64Array  # (3,) the head bone's tail
    rest_height_dm: float
    vertices: F64Array  # (N, 3)
    bone_ids: I64Array  # (N, 4)
    bone_weights: F64Array  # (N, 4)
    faces: I64Array  # (F, 3)
    colours_rgba: U8Array  # (N, 4)
    surface: I64Array  # (N,) which surface a vertex is on: 0 skin, 1 shoes (the feet), 2... each garment


def detail_level(ground_m_per_px: float) -> int:
    """The level of detail (index into :data:`DETAIL_CELLS_M`) to draw people at this ground pixel footprint."""
    level = 0
    for k, cell_m in enumerate(DETAIL_CELLS_M):
        if cell_m <= MAX_CELL_PX * ground_m_per_px:
            level = k
    return level


@functools.lru_cache(maxsize=2048)
def _dressed(figure: Figure, detail: int = 0) -> _Dressed:
    if detail:
        # The pack's mesh clustered again in rest pose, each surface on its own (a garment's cell never takes the
        # skin under it): every kept vertex keeps its own weights and colour. Vertices no triangle uses (skin under
        # a garment) take no part.
        fine = _dressed(figure, 0)
        used, used_faces = np.unique(fine.faces, return_inverse=True)
        cell_rest = DETAIL_CELLS_M[detail] * fine.rest_height_dm / figure.height_m  # metres -> this body's rest units
        keep, kept_faces = cluster_vertices(
            fine.vertices[used], used_faces.reshape(-1, 3), np.full(len(used), cell_rest), fine.surface[used]
        )
        keep = used[keep]
        return _Dressed(
            heads_rest=fine.heads_rest,
            crown_rest=fine.crown_rest,
            rest_height_dm=fine.rest_height_dm,
            vertices=fine.vertices[keep],
            bone_ids=fine.bone_ids[keep],
            bone_weights=fine.bone_weights[keep],
            faces=kept_faces,
            colours_rgba=fine.colours_rgba[keep],
            surface=fine.surface[keep],
        )
    lib = load_library()
    base = _shaped_base(lib, figure)
    heads_rest = to_bvh_axes(np.array([base[g].mean(axis=0) for g in lib.head_groups]))
    k = lib.rig.names.index("head")
    crown_rest = to_bvh_axes(base[lib.tail_groups[k]].mean(axis=0)[None, :])[0]
    # Shoes are drawn as the feet they hide, in the shoes' colour: from above a shoe is the foot's outline, and its
    # own mesh would cost a tenth of the person's triangles.
    shoes = _part(lib, figure.shoes)
    worn = [_part(lib, n) for n in (figure.suit, figure.hair, figure.hat) if n]
    body = lib.parts_of(PartKind.BODY, figure.sex)[0]
    hidden = np.zeros(len(lib.base_vertices), dtype=bool)
    for garment in worn:
        hidden[garment.fitting.delete_verts] = True
    shod = np.zeros(len(lib.base_vertices), dtype=bool)
    shod[shoes.fitting.delete_verts] = True
    vertices, faces, colours, ids, weights, surfaces = [], [], [], [], [], []
    offset = 0
    for n, part in enumerate((body, *worn)):
        surface = np.full(len(part.fitting.refs), n + 1)
        rest = to_bvh_axes(part.fitting.fit(base))
        part_faces = part.faces
        part_colours = _colours(part, figure)
        if part is body:
            covered = hidden[part.fitting.refs[:, 0]]
            part_faces = part_faces[~covered[part_faces].any(axis=1)]  # skin under a garment: not drawn
            part_colours[shod[part.fitting.refs[:, 0]], :3] = figure.shoes_rgb
            surface = shod[part.fitting.refs[:, 0]].astype(np.int64)
        vertices.append(rest)
        faces.append(part_faces + offset)
        colours.append(part_colours)
        ids.append(part.bone_ids)
        weights.append(part.bone_weights)
        surfaces.append(surface)
        offset += len(rest)
    return _Dressed(
        heads_rest=heads_rest,
        crown_rest=crown_rest,
        rest_height_dm=float(base[:, 1].max() - base[:, 1].min()),
        vertices=np.concatenate(vertices),
        bone_ids=np.concatenate(ids),
        bone_weights=np.concatenate(weights),
        faces=np.concatenate(faces),
        colours_rgba=np.concatenate(colours),
        surface=np.concatenate(surfaces),
    )


def figure_topology(figure: Figure, detail: int = 0) -> tuple[I64Array, int]:
    """The triangles (F, 3) of the figure's mesh and its vertex count: the same in every pose and step of the walk."""
    dressed = _dressed(figure, detail)
    return dressed.faces, len(dressed.vertices)


def figure_mesh(figure: Figure, walk_phase: float | None = None, stride: float = 1.0, detail: int = 0) -> FigureMesh:
    """The person's mesh, posed (``walk_phase`` in [0, 1): a step of a walk on top of the figure's pose).

    ``detail`` is a level of :data:`DETAIL_CELLS_M`; every level stands on the same floor (level 0's lowest point in
    this pose) under the same head.
    """
    lib = load_library()
    dressed = _dressed(figure, detail)
    pose_array = lib.poses[WALK_BASE_POSE if walk_phase is not None else figure.pose]
    rotations = {name: pose_array[i] for i, name in enumerate(lib.rig.names)}
    if walk_phase is not None:
        rotations = walk_pose(rotations, walk_phase, stride)
    rot, head = lib.rig.pose(dressed.heads_rest, rotations)
    posed = skin(dressed.vertices, dressed.bone_ids, dressed.bone_weights, dressed.heads_rest, rot, head)
    scale = figure.height_m / dressed.rest_height_dm  # decimetres of this body -> metres of the wanted height
    v = posed @ T_ENU_BVH.T * scale
    # The centre of the head: half way along the head bone (skull base to crown), posed.
    k = lib.rig.names.index("head")
    crown = head[k] + rot[k] @ (dressed.crown_rest - dressed.heads_rest[k])
    head_centre = (0.5 * (head[k] + crown) @ T_ENU_BVH.T) * scale
    if detail:
        floor = float(head_centre[2]) - figure_mesh(figure, walk_phase, stride).head_height_m
    else:
        floor = float(v[:, 2].min())
    v = v - np.array([head_centre[0], head_centre[1], floor])
    return FigureMesh(
        vertices_m=np.asarray(v, dtype=np.float64),
        faces=dressed.faces,
        colours_rgba=dressed.colours_rgba.copy(),
        head_height_m=float(head_centre[2] - floor),
    )


def walk_phase_at(distance_m: float, height_m: float) -> float:
    """Where in the walk cycle a person is after walking ``distance_m`` (a cycle of two steps is ~0.8 x height)."""
    cycle_m = 0.8 * height_m
    phase = (distance_m / cycle_m) % 1.0
    return math.floor(phase * WALK_PHASES) / WALK_PHASES


def crowd_figures(crowd: Crowd) -> list[Figure] | None:
    """The MakeHuman figure of each person of a crowd whose scenario asks for them (None otherwise).

    Drawn from a stream of their own (``[seed, 7]``): positions, appearances and walks stay those of the seed, so a
    scene with procedural and with MakeHuman people is the same scene. Heights and sitting come from the crowd's
    appearances; bright clothing hues from the scenario's style.
    """
    if crowd.config.people is not PeopleModel.MAKEHUMAN:
        return None
    rng = np.random.default_rng([crowd.seed, 7])
    sitting_types = (BodyType.ADULT_SITTING, BodyType.CHILD_SITTING)
    return [
        draw_figure(
            rng,
            a.height_m,
            sitting=a.body in sitting_types,
            bright_share=crowd.config.bright_clothing_share,
            hue_range=hue_range(crowd.config.style),
        )
        for a in crowd.appearances
    ]


@functools.lru_cache(maxsize=4096)
def figure_head_height_m(figure: Figure) -> float:
    """Height of the centre of the figure's head above the ground, standing or sitting as drawn."""
    return figure_mesh(figure).head_height_m


def figure_trimesh(
    figure: Figure, heading_rad: float, walk_phase: float | None = None, detail: int = 0
) -> trimesh.Trimesh:
    """The figure as a vertex-coloured mesh facing ``heading_rad`` (from north towards east), head above the origin."""
    built = figure_mesh(figure, walk_phase=walk_phase, detail=detail)
    mesh = trimesh.Trimesh(vertices=built.vertices_m, faces=built.faces, process=False)
    mesh.visual.vertex_colors = built.colours_rgba
    mesh.apply_transform(trimesh.transformations.rotation_matrix(-heading_rad, [0, 0, 1]))
    return mesh
