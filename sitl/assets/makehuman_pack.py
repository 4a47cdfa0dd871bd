"""Packing MakeHuman's CC0 assets into the SITL's body library: build-time code, beside the render, not in it.

:func:`pack` reads the asset tree (``../shared/assets/makehuman``: ``base/`` and ``data/``) with
:mod:`sitl.assets.makehuman_files` and writes ``sitl/render/bodies/data/bodies.npz``, which the render reads at run
time (:func:`sitl.render.bodies.library.load_library`; what the pack keeps is said there). ``scripts/pack_bodies.py``
runs it once; the result is in the repository.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import numpy.typing as npt

from sitl.assets.makehuman_files import read_bvh, read_fitting, read_obj, read_skeleton, read_target, read_weights
from sitl.render.bodies.library import (
    AGES,
    ANCESTRIES,
    CELL_DM,
    PACK_PATH,
    SEXES,
    BodyLibraryError,
    PartKind,
    Region,
    cluster_vertices,
)
from sitl.render.bodies.rig import Rig

logger = logging.getLogger(__name__)

F64Array = npt.NDArray[np.float64]
I64Array = npt.NDArray[np.int64]

BONES_PER_VERTEX = 4
LEG_CELL_FACTOR = 1.5
"""Garments below the waist are clustered in cells this much larger."""

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
