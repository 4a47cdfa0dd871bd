"""The body library shipped with the SITL: MakeHuman's CC0 bodies, garments, hair, rig and poses, packed small.

:func:`pack` reads the MakeHuman asset files (``scripts/pack_bodies.py`` runs it once; the result,
``sitl/render/bodies/data/bodies.npz``, is in the repository) and :func:`load_library` reads the pack at run time.
Packing keeps only what a camera 10-60 m up can see:

- the base-mesh vertices something refers to, with the macro (sex x age x ancestry) and body-shape targets on them;
- each part (low-poly proxy body, suit, shoes, hair, hat) decimated by vertex clustering on the default body
  (cells of :data:`CELL_DM`, one representative vertex per cell that keeps its own fitting line), so that a
  dressed person is ~2,000 triangles;
- per part vertex its bone weights on the reduced rig (:mod:`sitl.render.bodies.rig`), the four largest, and a
  colour region (skin, top, bottom, feet) from the bone it follows most;
- the poses as per-bone rotations of the reduced rig.

Units and axes inside the pack are MakeHuman's (decimetres; see :mod:`sitl.render.bodies.makehuman_files`).
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
from sitl.render.bodies.makehuman_files import (
    Fitting,
    read_bvh,
    read_fitting,
    read_obj,
    read_skeleton,
    read_target,
    read_weights,
)
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
BONES_PER_VERTEX = 4
LEG_CELL_FACTOR = 1.5
"""Garments below the waist are clustered in cells this much larger."""


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

# What the library packs, from the asset tree (kind, path under base/, sexes it suits).
PART_FILES: tuple[tuple[PartKind, str, tuple[str, ...]], ...] = (
    (PartKind.BODY, "proxymeshes/proxy741/proxy741.proxy", SEXES),
    *(
        (PartKind.SUIT, f"clothes/{name}/{name}.mhclo", ("female",))
        for name in ("female_casualsuit01", "female_casualsuit02", "female_elegantsuit01", "female_sportsuit01")
    ),
    *(
        (PartKind.SUIT, f"clothes/{name}/{name}.mhclo", ("male",))
        for name in (
            "male_casualsuit01",
            "male_casualsuit02",
            "male_casualsuit03",
            "male_casualsuit04",
            "male_casualsuit05",
            "male_casualsuit06",
            "male_elegantsuit01",
            "male_worksuit01",
        )
    ),
    *((PartKind.SHOES, f"clothes/shoes0{k}/shoes0{k}.mhclo", SEXES) for k in range(1, 7)),
    *(
        (PartKind.HAIR, f"hair/{name}/{name}.mhclo", ("female",))
        for name in ("bob01", "bob02", "braid01", "long01", "ponytail01", "short03")
    ),
    *((PartKind.HAIR, f"hair/{name}/{name}.mhclo", ("male",)) for name in ("short01", "short02", "short04")),
    (PartKind.HAIR, "hair/afro01/afro01.mhclo", SEXES),
    (PartKind.HAT, "clothes/fedora01/fedora.mhclo", SEXES),
)
POSE_FILES = ("standing01", "standing02", "standing03", "standing04", "standing05", "standing06", "sit01", "run01")


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


def _garment_regions(rest: F64Array, faces: I64Array, waist_dm: float) -> I64Array:
    """TOP or BOTTOM per vertex of a garment at rest (MakeHuman axes, y up).

    Garments are made of separate shells (a shirt, trousers, a skirt): a shell lies above or below the waist as a
    whole, by its mean height. A shell that runs far past the waist both ways (overalls, a dress) is split at it.
    """
    n = len(rest)
    parent = np.arange(n)

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = int(parent[i])
        return i

    for a, b, c in faces:
        ra, rb, rc = find(int(a)), find(int(b)), find(int(c))
        parent[rb] = ra
        parent[find(rc)] = ra
    roots = np.array([find(i) for i in range(n)])
    region = np.where(rest[:, 1] > waist_dm, int(Region.TOP), int(Region.BOTTOM)).astype(np.int64)
    for shell in np.unique(roots):
        members = roots == shell
        y = rest[members, 1]
        if y.min() < waist_dm - 1.5 and y.max() > waist_dm + 1.5 and len(y) > 200:
            continue  # one piece from the chest to the legs: split at the waist (set above)
        region[members] = int(Region.TOP) if y.mean() > waist_dm else int(Region.BOTTOM)
    return region


def pack(asset_root: Path, out: Path = PACK_PATH, cell_dm: float = CELL_DM) -> Path:
    """Read the MakeHuman assets under ``asset_root`` (``base/`` and ``data/``) and write the pack to ``out``."""
    data, base_dir = asset_root / "data", asset_root / "base"
    base = read_obj(data / "3dobjs" / "base.obj")
    skeleton = read_skeleton(data / "rigs" / "default.mhskel")
    weights = read_weights(data / "rigs" / "default_weights.mhw")
    rig = Rig.from_skeleton(skeleton.names, skeleton.parents)
    collapse = Rig.collapse(skeleton.names, skeleton.parents)
    n_base = len(base.vertices)
    # Dense base weights on the rig: (V, B) (163 bones collapsed onto 31).
    dense = np.zeros((n_base, len(rig.names)))
    for bone, (vertices, w) in weights.items():
        if bone in skeleton.names:
            np.add.at(dense, (vertices, collapse[skeleton.names.index(bone)]), w)
    total = dense.sum(axis=1, keepdims=True)
    dense = np.divide(dense, total, out=np.zeros_like(dense), where=total > 0)
    root = skeleton.names.index("root")
    waist_dm = float(base.vertices[skeleton.head_groups[root]].mean(axis=0)[1]) + 0.3

    arrays: dict[str, np.ndarray] = {}
    parts_meta: list[dict[str, object]] = []
    meta: dict[str, object] = {"cell_dm": cell_dm, "rig": list(rig.names), "parts": parts_meta}
    meta["poses"] = list(POSE_FILES)
    used: set[int] = set()
    parts_raw = []
    for kind, relative, sexes in PART_FILES:
        path = base_dir / relative
        fitting = read_fitting(path)
        obj = read_obj(path.parent / fitting.obj_file)
        if len(obj.vertices) != len(fitting.refs):
            raise BodyLibraryError(
                f"{path}: {len(fitting.refs)} fitted vertices for {len(obj.vertices)} in {fitting.obj_file}"
            )
        rest = fitting.fit(base.vertices)
        regions = _garment_regions(rest, obj.faces, waist_dm)
        # Below the waist a camera above sees less (the torso covers the legs near the nadir): coarser cells there.
        cells = np.where(regions == int(Region.BOTTOM), cell_dm * LEG_CELL_FACTOR, cell_dm)
        if kind is not PartKind.SUIT:
            cells = np.full(len(rest), cell_dm)
        keep, faces = cluster_vertices(rest, obj.faces, cells)
        refs = fitting.refs[keep]
        w = fitting.weights[keep]
        vertex_weights = np.einsum("nk,nkb->nb", w, dense[refs])  # (N, B)
        ids = np.argsort(-vertex_weights, axis=1)[:, :BONES_PER_VERTEX]
        top = np.take_along_axis(vertex_weights, ids, axis=1)
        top = top / np.maximum(top.sum(axis=1, keepdims=True), 1e-9)
        region = regions[keep]
        if kind is PartKind.BODY:
            region = np.full(len(keep), int(Region.SKIN), dtype=np.int64)
        elif kind is PartKind.SHOES:
            region = np.full(len(keep), int(Region.FEET), dtype=np.int64)
        elif kind in (PartKind.HAIR, PartKind.HAT):
            region = np.full(len(keep), int(Region.SKIN), dtype=np.int64)  # coloured by the figure as a whole
        used.update(refs.ravel().tolist())
        used.update(fitting.scale_refs.ravel().tolist())
        parts_raw.append((kind, path.stem, sexes, fitting, keep, faces, refs, w, ids, top, region))
        logger.info("%s: %d -> %d vertices, %d triangles", path.stem, len(rest), len(keep), len(faces))
    head_groups = [skeleton.head_groups[skeleton.names.index(n)] for n in rig.names]
    tail_groups = [skeleton.tail_groups[skeleton.names.index(n)] for n in rig.names]
    for group in (*head_groups, *tail_groups):
        used.update(group.tolist())
    subset = np.array(sorted(used), dtype=np.int64)
    remap = np.full(n_base, -1, dtype=np.int64)
    remap[subset] = np.arange(len(subset))
    arrays["base_vertices"] = base.vertices[subset].astype(np.float32)
    for k, group in enumerate(head_groups):
        arrays[f"head_group/{k}"] = remap[group].astype(np.int32)
        arrays[f"tail_group/{k}"] = remap[tail_groups[k]].astype(np.int32)
    for kind, name, sexes, fitting, keep, faces, refs, w, ids, top, region in parts_raw:
        hidden = remap[fitting.delete_verts[fitting.delete_verts < n_base]]
        prefix = f"part/{name}/"
        arrays[prefix + "refs"] = remap[refs].astype(np.int32)
        arrays[prefix + "weights"] = w.astype(np.float32)
        arrays[prefix + "offsets"] = fitting.offsets[keep].astype(np.float32)
        arrays[prefix + "scale_refs"] = remap[fitting.scale_refs].astype(np.int32)
        arrays[prefix + "scale_ref"] = fitting.scale_ref_m.astype(np.float32)
        arrays[prefix + "hides"] = hidden[hidden >= 0].astype(np.int32)
        arrays[prefix + "faces"] = faces.astype(np.int32)
        arrays[prefix + "region"] = region.astype(np.uint8)
        arrays[prefix + "bone_ids"] = ids.astype(np.uint8)
        arrays[prefix + "bone_weights"] = top.astype(np.float16)
        parts_meta.append({"name": name, "kind": kind.value, "sexes": list(sexes)})
    for ancestry in ANCESTRIES:
        for sex in SEXES:
            for age in AGES:
                indices, offsets = read_target(data / "targets" / "macrodetails" / f"{ancestry}-{sex}-{age}.target")
                mapped = remap[indices]
                arrays[f"macro/{ancestry}-{sex}-{age}/indices"] = mapped[mapped >= 0].astype(np.int32)
                arrays[f"macro/{ancestry}-{sex}-{age}/offsets"] = offsets[mapped >= 0].astype(np.float16)
    shapes = []
    for path in sorted((data / "targets" / "bodyshapes").glob("*.target")):
        name = path.stem.replace("bodyshapes-elvs-", "")
        indices, offsets = read_target(path)
        mapped = remap[indices]
        arrays[f"shape/{name}/indices"] = mapped[mapped >= 0].astype(np.int32)
        arrays[f"shape/{name}/offsets"] = offsets[mapped >= 0].astype(np.float16)
        shapes.append(name)
    meta["shapes"] = shapes
    for pose_name in POSE_FILES:
        bvh = read_bvh(base_dir / "poses" / f"{pose_name}.bvh")
        arrays[f"pose/{pose_name}"] = np.stack([bvh.rotations.get(name, np.eye(3)) for name in rig.names]).astype(
            np.float32
        )
    arrays["rig_parents"] = rig.parents.astype(np.int32)
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode("utf-8"), dtype=np.uint8)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out, **arrays)  # type: ignore[arg-type]
    return out


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
