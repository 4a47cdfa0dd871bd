"""Readers for MakeHuman's plain-text asset formats (CC0 assets; this is our own reader, no MakeHuman code).

Formats read here, as the files in ``assets/makehuman`` write them:

- Wavefront ``.obj`` (base mesh, proxy bodies, clothes, hair): ``v``, ``vt``, ``f`` with ``v/vt`` corners, quads or
  triangles, ``g`` groups (the base mesh's first group ``body`` is the skin; the rest are helper geometry).
- ``.target``: sparse vertex offsets, one ``index dx dy dz`` line per moved vertex.
- ``.mhclo`` and ``.proxy`` (same fitting format): each fitted vertex is ``w0 v[i0] + w1 v[i1] + w2 v[i2] +
  offset * scale`` of base-mesh vertices, with the per-axis scale measured on the body (``x_scale a b d``: the
  distance along x between base vertices a and b, divided by ``d``); a single-index line copies one vertex;
  ``delete_verts`` lists base vertices the garment hides (ranges written ``a - b``).
- ``.mhskel`` (JSON): bones with parents; each bone's head and tail are the mean of a group of base vertices.
- ``.mhw`` (JSON): per bone, ``[vertex, weight]`` pairs on the base mesh.
- ``.bvh``: a joint hierarchy with offsets and one frame of Euler rotations per joint (MakeHuman's poses).

Units are MakeHuman's: decimetres, y up, the body facing +z, its left side towards +x.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from companion.errors import SlzError
from sitl.render.bodies.library import Fitting
from sitl.render.bodies.rig import axis_rotation

F64Array = npt.NDArray[np.float64]
I64Array = npt.NDArray[np.int64]


class AssetFormatError(SlzError):
    """A MakeHuman asset file cannot be read (the file, the line and what was wrong)."""

    def __init__(self, path: Path, what: str) -> None:
        super().__init__(f"{path}: {what}")
        self.path = path


@dataclass(frozen=True)
class ObjMesh:
    """A polygon mesh as an ``.obj`` file holds it, triangulated.

    Attributes
    ----------
    vertices : ndarray, shape (V, 3), float64
        Positions (MakeHuman units).
    faces : ndarray, shape (F, 3), int64
        Triangles (quads split along their first diagonal), indices into ``vertices``.
    face_groups : ndarray, shape (F,), int64
        Index into ``groups`` of the ``g`` group each triangle was written under.
    groups : tuple of str
        Group names in file order.
    """

    vertices: F64Array
    faces: I64Array
    face_groups: I64Array
    groups: tuple[str, ...]


def read_obj(path: Path) -> ObjMesh:
    """Read an ``.obj`` file (positions and faces; texture coordinates are skipped)."""
    vertices: list[tuple[float, float, float]] = []
    faces: list[tuple[int, int, int]] = []
    face_groups: list[int] = []
    groups: list[str] = []
    current = -1
    for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), start=1):
        parts = line.split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                vertices.append((float(parts[1]), float(parts[2]), float(parts[3])))
            elif parts[0] == "g":
                groups.append(parts[1] if len(parts) > 1 else "")
                current = len(groups) - 1
            elif parts[0] == "f":
                corners = [int(p.split("/")[0]) - 1 for p in parts[1:]]
                if len(corners) < 3:
                    raise ValueError(f"a face with {len(corners)} corners")
                for k in range(1, len(corners) - 1):
                    faces.append((corners[0], corners[k], corners[k + 1]))
                    face_groups.append(max(current, 0))
        except (ValueError, IndexError) as exc:
            raise AssetFormatError(path, f"line {number}: {exc}") from None
    if not groups:
        groups = [""]
    face_array = np.array(faces, dtype=np.int64).reshape(-1, 3)
    if len(face_array) and (face_array.min() < 0 or face_array.max() >= len(vertices)):
        raise AssetFormatError(path, f"a face refers to a vertex outside 1..{len(vertices)}")
    return ObjMesh(
        vertices=np.array(vertices, dtype=np.float64).reshape(-1, 3),
        faces=face_array,
        face_groups=np.array(face_groups, dtype=np.int64),
        groups=tuple(groups),
    )


def read_target(path: Path) -> tuple[I64Array, F64Array]:
    """Read a ``.target``: (vertex indices (N,), offsets (N, 3)) in MakeHuman units."""
    indices: list[int] = []
    offsets: list[tuple[float, float, float]] = []
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        try:
            indices.append(int(parts[0]))
            offsets.append((float(parts[1]), float(parts[2]), float(parts[3])))
        except (ValueError, IndexError) as exc:
            raise AssetFormatError(path, f"line {number}: {exc}") from None
    return np.array(indices, dtype=np.int64), np.array(offsets, dtype=np.float64).reshape(-1, 3)


def read_fitting(path: Path) -> Fitting:
    """Read a ``.mhclo`` or ``.proxy`` file."""
    refs: list[tuple[int, int, int]] = []
    weights: list[tuple[float, float, float]] = []
    offsets: list[tuple[float, float, float]] = []
    scale_refs = np.zeros((3, 2), dtype=np.int64)
    scale_ref = np.ones(3)
    deleted: list[int] = []
    obj_file = ""
    section = ""
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        try:
            key = parts[0]
            if key in ("x_scale", "y_scale", "z_scale"):
                axis = "xyz".index(key[0])
                scale_refs[axis] = (int(parts[1]), int(parts[2]))
                scale_ref[axis] = float(parts[3])
            elif key == "obj_file":
                obj_file = parts[1]
            elif key == "verts":
                section = "verts"
            elif key == "delete_verts":
                section = "delete"
            elif section == "verts" and key[0].isdigit():
                if len(parts) == 1:
                    i = int(parts[0])
                    refs.append((i, i, i))
                    weights.append((1.0, 0.0, 0.0))
                    offsets.append((0.0, 0.0, 0.0))
                else:
                    refs.append((int(parts[0]), int(parts[1]), int(parts[2])))
                    weights.append((float(parts[3]), float(parts[4]), float(parts[5])))
                    offsets.append((float(parts[6]), float(parts[7]), float(parts[8])))
            elif section == "delete" and (key[0].isdigit() or key == "-"):
                tokens = parts
                k = 0
                while k < len(tokens):
                    if k + 2 < len(tokens) and tokens[k + 1] == "-":
                        deleted.extend(range(int(tokens[k]), int(tokens[k + 2]) + 1))
                        k += 3
                    else:
                        deleted.append(int(tokens[k]))
                        k += 1
            # Any other keyword line (material, vertexboneweights_file...) leaves the section as it was.
        except (ValueError, IndexError) as exc:
            raise AssetFormatError(path, f"line {number}: {exc}") from None
    if not refs:
        raise AssetFormatError(path, "no fitted vertices (no 'verts' section)")
    if not obj_file:
        raise AssetFormatError(path, "no obj_file line")
    return Fitting(
        refs=np.array(refs, dtype=np.int64),
        weights=np.array(weights, dtype=np.float64),
        offsets=np.array(offsets, dtype=np.float64),
        scale_refs=scale_refs,
        scale_ref_m=scale_ref,
        delete_verts=np.array(sorted(set(deleted)), dtype=np.int64),
        obj_file=obj_file,
    )


@dataclass(frozen=True)
class Skeleton:
    """A ``.mhskel`` skeleton: bones in parent-before-child order.

    Attributes
    ----------
    names : tuple of str
        Bone names; ``parents[i]`` is the index of bone i's parent, -1 for the root.
    head_groups, tail_groups : tuple of ndarray of int64
        Per bone, the base vertices whose mean is its head (tail).
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    head_groups: tuple[I64Array, ...]
    tail_groups: tuple[I64Array, ...]

    def heads(self, base_vertices: F64Array) -> F64Array:
        """Bone heads (B, 3) on a base mesh (V, 3)."""
        return np.array([base_vertices[g].mean(axis=0) for g in self.head_groups])

    def tails(self, base_vertices: F64Array) -> F64Array:
        """Bone tails (B, 3) on a base mesh (V, 3)."""
        return np.array([base_vertices[g].mean(axis=0) for g in self.tail_groups])


def read_skeleton(path: Path) -> Skeleton:
    """Read a ``.mhskel`` file, ordering bones so that every parent comes before its children."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        bones: dict[str, dict[str, object]] = data["bones"]
        joints: dict[str, list[int]] = data["joints"]
    except (ValueError, KeyError) as exc:
        raise AssetFormatError(path, f"not a MakeHuman skeleton: {exc}") from None
    order: list[str] = []
    placed: set[str] = set()
    pending = sorted(bones)
    while pending:
        progressed = False
        for name in list(pending):
            parent = bones[name].get("parent")
            if parent is None or parent in placed:
                order.append(name)
                placed.add(name)
                pending.remove(name)
                progressed = True
        if not progressed:
            raise AssetFormatError(path, f"bones whose parents never appear: {pending[:5]}")
    index = {name: i for i, name in enumerate(order)}
    try:
        return Skeleton(
            names=tuple(order),
            parents=tuple(index[str(bones[n]["parent"])] if bones[n].get("parent") else -1 for n in order),
            head_groups=tuple(np.array(joints[str(bones[n]["head"])], dtype=np.int64) for n in order),
            tail_groups=tuple(np.array(joints[str(bones[n]["tail"])], dtype=np.int64) for n in order),
        )
    except KeyError as exc:
        raise AssetFormatError(path, f"a bone names a joint that is not defined: {exc}") from None


def read_weights(path: Path) -> dict[str, tuple[I64Array, F64Array]]:
    """Read a ``.mhw`` file: per bone name, (base vertices, weights)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        weights: dict[str, list[list[float]]] = data["weights"]
    except (ValueError, KeyError) as exc:
        raise AssetFormatError(path, f"not a MakeHuman weights file: {exc}") from None
    out: dict[str, tuple[I64Array, F64Array]] = {}
    for bone, pairs in weights.items():
        array = np.array(pairs, dtype=np.float64).reshape(-1, 2)
        out[bone] = array[:, 0].astype(np.int64), array[:, 1]
    return out


@dataclass(frozen=True)
class BvhPose:
    """One frame of a ``.bvh`` file.

    Attributes
    ----------
    rotations : dict of str to ndarray, shape (3, 3)
        Per joint, its rotation relative to its parent (the product of its Euler channels in the order written).
    root_offset : ndarray, shape (3,)
        The root's rest offset; ``root_position`` its position in the frame (BVH axes and units).
    """

    rotations: dict[str, F64Array] = field(default_factory=dict)
    root_offset: F64Array = field(default_factory=lambda: np.zeros(3))
    root_position: F64Array = field(default_factory=lambda: np.zeros(3))


def read_bvh(path: Path, frame: int = 0) -> BvhPose:
    """Read one frame of a ``.bvh`` file."""
    tokens = path.read_text(encoding="utf-8").split()
    joints: list[tuple[str, list[str], F64Array]] = []
    k = 0
    pending_name: str | None = None
    try:
        motion = tokens.index("MOTION")
        while k < motion:
            token = tokens[k]
            if token in ("ROOT", "JOINT"):
                pending_name = tokens[k + 1]
                k += 2
            elif token == "End":
                pending_name = None
                k += 2
            elif token == "OFFSET":
                offset = np.array([float(t) for t in tokens[k + 1 : k + 4]])
                if pending_name is not None:
                    joints.append((pending_name, [], offset))
                k += 4
            elif token == "CHANNELS":
                count = int(tokens[k + 1])
                if pending_name is not None and joints and joints[-1][0] == pending_name:
                    joints[-1][1].extend(tokens[k + 2 : k + 2 + count])
                k += 2 + count
            else:
                k += 1
        n_frames = int(tokens[motion + 2])
        # "Frames: N" "Frame Time: t": values start after the frame time.
        start = motion + 6
        width = sum(len(channels) for _, channels, _ in joints)
        if not 0 <= frame < n_frames:
            raise ValueError(f"frame {frame} of {n_frames}")
        values = [float(t) for t in tokens[start + frame * width : start + (frame + 1) * width]]
        if len(values) != width:
            raise ValueError(f"a frame holds {len(values)} values, the channels ask for {width}")
    except (ValueError, IndexError) as exc:
        raise AssetFormatError(path, f"not a readable BVH file: {exc}") from None
    pose = BvhPose(root_offset=joints[0][2] if joints else np.zeros(3))
    cursor = 0
    for index, (name, channels, _) in enumerate(joints):
        rotation = np.eye(3)
        position = np.zeros(3)
        for channel in channels:
            value = values[cursor]
            cursor += 1
            if channel.endswith("rotation"):
                rotation = rotation @ axis_rotation(channel[0].lower(), value)
            elif channel.endswith("position"):
                position["XYZ".index(channel[0])] = value
        pose.rotations[name] = rotation
        if index == 0:
            pose.root_position[:] = position
    return pose
