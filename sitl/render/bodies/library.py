"""The body library shipped with the SITL: MakeHuman's CC0 bodies, garments, hair, rig and poses, packed small.

:func:`load_library` reads the pack (``sitl/render/bodies/data/bodies.npz``, in the repository) at run time; the
packing itself, which reads the MakeHuman asset files, is build-time code beside the render
(:mod:`sitl.assets.makehuman_pack`, run once by ``scripts/pack_bodies.py``). The pack keeps only what a camera
10-60 m up can see:

- the base-mesh vertices something refers to, with the macro (sex x age x ancestry) and body-shape targets on them;
- each part (low-poly proxy body, suit, shoes, hair, hat) decimated by vertex clustering on the default body
  (cells of :data:`CELL_DM`, one representative vertex per cell that keeps its own fitting line), so that a
  dressed person is ~2,000 triangles;
- per part vertex its bone weights on the reduced rig (:mod:`sitl.render.bodies.rig`), the four largest, and a
  colour region (skin, top, bottom, feet) from the bone it follows most;
- the poses as per-bone rotations of the reduced rig.

Units and axes inside the pack are MakeHuman's (decimetres; see :mod:`sitl.assets.makehuman_files`).
"""

from __future__ import annotations

import enum
import functools
import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from companion.errors import SlzError
from sitl.render.bodies.rig import T_BVH_MAKEHUMAN, Rig

logger = logging.getLogger(__name__)

F64Array = npt.NDArray[np.float64]
I64Array = npt.NDArray[np.int64]

PACK_PATH = Path(__file__).resolve().parent / "data" / "bodies.npz"
CELL_DM = 0.75
"""Vertex-clustering cell (decimetres): 7.5 cm, a pixel at the SITL camera's 6 cm/px from 20 m, 2.5 at 3 cm/px (the
lowest a mission looks from). Finer cells cost the software rasterizer its frame budget (bench/render.py): a person
is ~880 triangles at 7.5 cm, 1,600 at 5.5 cm, 6,100 at 3 cm. From higher up a coarser level is clustered from the
pack at run time (:data:`sitl.render.bodies.figure.DETAIL_CELLS_M`)."""


class BodyLibraryError(SlzError):
    """The body library cannot be packed or loaded (what, and which file)."""


class PartKind(str, enum.Enum):
    """What a part of a person is."""

    BODY = "body"
    SUIT = "suit"
    SHOES = "shoes"
    HAIR = "hair"
    HAT = "hat"


class Region(enum.IntEnum):
    """The colour a part's vertex takes: skin, top or bottom garment, footwear (from the bone it follows)."""

    SKIN = 0
    TOP = 1
    BOTTOM = 2
    FEET = 3


SEXES = ("female", "male")
AGES = ("young", "old")
ANCESTRIES = ("african", "asian", "caucasian")


@dataclass(frozen=True)
class Fitting:
    """How a proxy body or garment follows the base mesh (a ``.proxy`` or ``.mhclo`` file).

    Attributes
    ----------
    refs : ndarray, shape (N, 3), int64
        Three base-mesh vertices per fitted vertex (a single-index line repeats its vertex).
    weights : ndarray, shape (N, 3), float64
        Their weights.
    offsets : ndarray, shape (N, 3), float64
        Offset per fitted vertex, in units of the scale axes.
    scale_refs : ndarray, shape (3, 2), int64
        Per axis x, y, z: the two base vertices whose distance along that axis measures the body.
    scale_ref_m : ndarray, shape (3,), float64
        Those distances on the body the garment was made for (MakeHuman units).
    delete_verts : ndarray, shape (D,), int64
        Base vertices the garment hides.
    obj_file : str
        The garment's mesh, beside the fitting file.
    """

    refs: I64Array
    weights: F64Array
    offsets: F64Array
    scale_refs: I64Array
    scale_ref_m: F64Array
    delete_verts: I64Array
    obj_file: str

    def fit(self, base_vertices: F64Array) -> F64Array:
        """Fitted vertex positions (N, 3) on a base mesh (V, 3) (shaped by targets or not)."""
        scale = np.abs(base_vertices[self.scale_refs[:, 0]] - base_vertices[self.scale_refs[:, 1]])
        scale = np.array([scale[0, 0], scale[1, 1], scale[2, 2]]) / self.scale_ref_m
        fitted = np.einsum("nk,nkd->nd", self.weights, base_vertices[self.refs])
        return np.asarray(fitted + self.offsets * scale, dtype=np.float64)


@dataclass(frozen=True)
class BodyPart:
    """One decimated part, fitted to the base mesh.

    Attributes
    ----------
    name : str
        The asset's name (``male_casualsuit04``).
    kind : PartKind
    sexes : tuple of str
        Whom it is drawn for.
    fitting : Fitting
        Refs into the library's base vertices (not MakeHuman's numbering).
    faces : ndarray, shape (F, 3), int64
    region : ndarray, shape (N,), int64
        :class:`Region` per vertex.
    bone_ids, bone_weights : ndarray, shape (N, 4)
        The rig bones each vertex follows.
    """

    name: str
    kind: PartKind
    sexes: tuple[str, ...]
    fitting: Fitting
    faces: I64Array
    region: I64Array
    bone_ids: I64Array
    bone_weights: F64Array


@dataclass(frozen=True)
class BodyLibrary:
    """Everything a person is built from (see the module docstring).

    Attributes
    ----------
    base_vertices : ndarray, shape (S, 3)
        The base-mesh vertices the parts and the rig use (MakeHuman axes).
    macro_targets : dict of (ancestry, sex, age) to (indices (N,), offsets (N, 3))
    shape_targets : dict of name to (indices, offsets)
        Body shapes (``fem-apple``, ``man-trapezoid``...).
    head_groups, tail_groups : tuple of ndarray
        Per rig bone, the base vertices whose mean is its head (tail).
    rig : Rig
    parts : tuple of BodyPart
    poses : dict of str to ndarray, shape (B, 3, 3)
        Per pose, each rig bone's rotation relative to its parent (BVH axes).
    """

    base_vertices: F64Array
    macro_targets: dict[tuple[str, str, str], tuple[I64Array, F64Array]]
    shape_targets: dict[str, tuple[I64Array, F64Array]]
    head_groups: tuple[I64Array, ...]
    tail_groups: tuple[I64Array, ...]
    rig: Rig
    parts: tuple[BodyPart, ...]
    poses: dict[str, F64Array]

    def parts_of(self, kind: PartKind, sex: str) -> tuple[BodyPart, ...]:
        """The parts of a kind drawn for a sex, in library order."""
        return tuple(p for p in self.parts if p.kind is kind and sex in p.sexes)


def cluster_vertices(
    positions: F64Array, faces: I64Array, cell: F64Array, group: I64Array | None = None
) -> tuple[I64Array, I64Array]:
    """Vertex clustering: (representative vertex per kept vertex (K,), faces (F', 3) over kept vertices).

    ``cell`` (N,) is each vertex's cell size; vertices of different cell sizes, or of different ``group`` (N,) (the
    parts of a dressed body: skin, a garment, hair), never share a cell.
    """
    groups = np.zeros(len(positions), dtype=np.int64) if group is None else group
    keys = np.column_stack(
        [np.floor(positions / cell[:, None]).astype(np.int64), np.round(cell * 1000).astype(np.int64), groups]
    )
    _, cluster, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    cluster = cluster.ravel()
    n_clusters = len(counts)
    means = np.zeros((n_clusters, 3))
    np.add.at(means, cluster, positions)
    means /= counts[:, None]
    distance = np.linalg.norm(positions - means[cluster], axis=1)
    order = np.lexsort((np.arange(len(positions)), distance, cluster))  # nearest to the mean first, then lowest index
    first = np.ones(len(order), dtype=bool)
    first[1:] = cluster[order][1:] != cluster[order][:-1]
    representative = order[first]  # one per cluster, in cluster order
    new_faces = cluster[faces]
    keep = (
        (new_faces[:, 0] != new_faces[:, 1])
        & (new_faces[:, 1] != new_faces[:, 2])
        & (new_faces[:, 0] != new_faces[:, 2])
    )
    new_faces = new_faces[keep]
    # One triangle per set of corners, wound to face the way the surface it stands for faced (the renderer culls
    # back faces): its normal agrees with the mean original normal of the vertices it replaced.
    _, unique_rows = np.unique(np.sort(new_faces, axis=1), axis=0, return_index=True)
    new_faces = new_faces[np.sort(unique_rows)]
    corners = positions[faces]
    face_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    vertex_normals = np.zeros_like(positions)
    for k in range(3):
        np.add.at(vertex_normals, faces[:, k], face_normals)
    cluster_normals = np.zeros((n_clusters, 3))
    np.add.at(cluster_normals, cluster, vertex_normals)
    rep = positions[representative][new_faces]
    normals = np.cross(rep[:, 1] - rep[:, 0], rep[:, 2] - rep[:, 0])
    flip = np.einsum("fd,fd->f", normals, cluster_normals[new_faces].sum(axis=1)) < 0
    new_faces[flip] = new_faces[flip][:, ::-1]
    return representative.astype(np.int64), new_faces.astype(np.int64)


@functools.cache
def load_library(path: Path = PACK_PATH) -> BodyLibrary:
    """The packed body library (read once per process)."""
    try:
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise BodyLibraryError(
            f"{path}: cannot read the body library: {exc} (scripts/pack_bodies.py makes it)"
        ) from None
    meta = json.loads(arrays["meta"].tobytes().decode("utf-8"))
    rig = Rig(names=tuple(meta["rig"]), parents=arrays["rig_parents"].astype(np.int64))
    parts = []
    for entry in meta["parts"]:
        prefix = f"part/{entry['name']}/"
        fitting = Fitting(
            refs=arrays[prefix + "refs"].astype(np.int64),
            weights=arrays[prefix + "weights"].astype(np.float64),
            offsets=arrays[prefix + "offsets"].astype(np.float64),
            scale_refs=arrays[prefix + "scale_refs"].astype(np.int64),
            scale_ref_m=arrays[prefix + "scale_ref"].astype(np.float64),
            delete_verts=arrays[prefix + "hides"].astype(np.int64),
            obj_file="",
        )
        parts.append(
            BodyPart(
                name=entry["name"],
                kind=PartKind(entry["kind"]),
                sexes=tuple(entry["sexes"]),
                fitting=fitting,
                faces=arrays[prefix + "faces"].astype(np.int64),
                region=arrays[prefix + "region"].astype(np.int64),
                bone_ids=arrays[prefix + "bone_ids"].astype(np.int64),
                bone_weights=arrays[prefix + "bone_weights"].astype(np.float64),
            )
        )

    def target(prefix: str) -> tuple[I64Array, F64Array]:
        return arrays[prefix + "/indices"].astype(np.int64), arrays[prefix + "/offsets"].astype(np.float64)

    return BodyLibrary(
        base_vertices=arrays["base_vertices"].astype(np.float64),
        macro_targets={(a, s, g): target(f"macro/{a}-{s}-{g}") for a in ANCESTRIES for s in SEXES for g in AGES},
        shape_targets={name: target(f"shape/{name}") for name in meta["shapes"]},
        head_groups=tuple(arrays[f"head_group/{k}"].astype(np.int64) for k in range(len(rig.names))),
        tail_groups=tuple(arrays[f"tail_group/{k}"].astype(np.int64) for k in range(len(rig.names))),
        rig=rig,
        parts=tuple(parts),
        poses={name: arrays[f"pose/{name}"].astype(np.float64) for name in meta["poses"]},
    )


def to_bvh_axes(vertices: F64Array) -> F64Array:
    """MakeHuman mesh axes to its BVH axes (N, 3)."""
    return np.asarray(vertices @ T_BVH_MAKEHUMAN.T, dtype=np.float64)
