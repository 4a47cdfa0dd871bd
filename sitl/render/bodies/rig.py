"""The body rig: a reduced MakeHuman skeleton, forward kinematics and linear-blend skinning.

A nadir camera at 3-9 cm a pixel sees no fingers, toes or faces, so the 163 bones of MakeHuman's default skeleton
are reduced to the 31 that move limbs, trunk and head (:data:`RIG_BONES`); every other bone's skin follows its nearest
kept ancestor. Poses follow the BVH convention MakeHuman's pose files use: the rest pose has no rotation, each
joint's rotation is relative to its parent, and a joint sits at its bone's head.

Frame: MakeHuman's BVH axes (x the body's left, y backwards, z up), decimetres, unless a name says otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

F64Array = npt.NDArray[np.float64]
I64Array = npt.NDArray[np.int64]

RIG_BONES: tuple[str, ...] = (
    "root",
    "spine05",
    "spine04",
    "spine03",
    "spine02",
    "spine01",
    "neck01",
    "neck02",
    "neck03",
    "head",
    *(f"{name}.{side}" for side in ("L", "R") for name in ("clavicle", "shoulder01", "upperarm01", "upperarm02")),
    *(f"{name}.{side}" for side in ("L", "R") for name in ("lowerarm01", "lowerarm02", "wrist")),
    *(
        f"{name}.{side}"
        for side in ("L", "R")
        for name in ("pelvis", "upperleg01", "upperleg02", "lowerleg01", "lowerleg02", "foot")
    ),
)
"""Kept bones, each after its parent in MakeHuman's default skeleton (checked when a rig is built)."""

T_BVH_MAKEHUMAN = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""MakeHuman's mesh axes (x left, y up, z forward) to its BVH axes (x left, y backwards, z up)."""


@dataclass(frozen=True)
class Rig:
    """Bones of the reduced skeleton.

    Attributes
    ----------
    names : tuple of str
        Kept bones, parents first (:data:`RIG_BONES`).
    parents : ndarray, shape (B,), int64
        Parent of each bone (-1 for the root).
    """

    names: tuple[str, ...]
    parents: I64Array

    @classmethod
    def from_skeleton(cls, names: Sequence[str], parents: Sequence[int], keep: Sequence[str] = RIG_BONES) -> Rig:
        """The rig of ``keep`` within a full skeleton (``names``, ``parents``: parents first)."""
        index = {name: i for i, name in enumerate(names)}
        kept_parents = []
        for bone in keep:
            parent = parents[index[bone]]
            while parent >= 0 and names[parent] not in keep:
                parent = parents[parent]
            kept_parents.append(list(keep).index(names[parent]) if parent >= 0 else -1)
        for i, parent in enumerate(kept_parents):
            if parent >= i:
                raise ValueError(f"bone {keep[i]} comes before its parent {keep[parent]}")
        return cls(names=tuple(keep), parents=np.array(kept_parents, dtype=np.int64))

    @staticmethod
    def collapse(names: Sequence[str], parents: Sequence[int], keep: Sequence[str] = RIG_BONES) -> I64Array:
        """For each bone of a full skeleton, the index in ``keep`` of itself or its nearest kept ancestor."""
        kept = {name: i for i, name in enumerate(keep)}
        out = np.zeros(len(names), dtype=np.int64)
        for i in range(len(names)):
            j = i
            while names[j] not in kept:
                j = parents[j]
                if j < 0:
                    raise ValueError(f"bone {names[i]} has no kept ancestor")
            out[i] = kept[names[j]]
        return out

    def pose(self, heads_rest: F64Array, rotations: Mapping[str, F64Array]) -> tuple[F64Array, F64Array]:
        """Forward kinematics: per bone its rotation (B, 3, 3) and head (B, 3) in the posed body.

        ``heads_rest`` (B, 3) are the bone heads at rest (BVH axes); ``rotations`` each bone's rotation relative to
        its parent (a missing bone does not turn).
        """
        n = len(self.names)
        rot = np.zeros((n, 3, 3))
        head = np.zeros((n, 3))
        for i, name in enumerate(self.names):
            local = rotations.get(name, np.eye(3))
            parent = int(self.parents[i])
            if parent < 0:
                rot[i], head[i] = local, heads_rest[i]
            else:
                rot[i] = rot[parent] @ local
                head[i] = head[parent] + rot[parent] @ (heads_rest[i] - heads_rest[parent])
        return rot, head


def skin(
    vertices_rest: F64Array,
    bone_ids: I64Array,
    bone_weights: F64Array,
    heads_rest: F64Array,
    rot: F64Array,
    head: F64Array,
) -> F64Array:
    """Linear-blend skinning.

    Parameters
    ----------
    vertices_rest : ndarray, shape (N, 3)
        Rest positions (BVH axes).
    bone_ids, bone_weights : ndarray, shape (N, K)
        Up to K bones per vertex and their weights (summing to 1).
    heads_rest : ndarray, shape (B, 3)
        Bone heads at rest.
    rot, head : ndarray, shapes (B, 3, 3), (B, 3)
        The posed bones (:meth:`Rig.pose`).

    Returns
    -------
    ndarray, shape (N, 3)
        Posed positions.
    """
    # Per bone: v -> rot (v - head_rest) + head.
    local = vertices_rest[:, None, :] - heads_rest[bone_ids]  # (N, K, 3)
    moved = np.einsum("nkij,nkj->nki", rot[bone_ids], local) + head[bone_ids]
    return np.asarray(np.einsum("nk,nki->ni", bone_weights, moved), dtype=np.float64)


def axis_rotation(axis: str, angle_deg: float) -> F64Array:
    """Rotation by ``angle_deg`` about the x, y or z axis (right-handed)."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    if axis == "x":
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    if axis == "y":
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def walk_pose(base: Mapping[str, F64Array], phase: float, stride: float) -> dict[str, F64Array]:
    """A walking step at ``phase`` (0-1 over one full cycle of two steps) on top of a standing pose.

    ``stride`` (0-1) scales the swing: hips +-25 degrees, knees up to 45, arms +-20 at a full stride. Legs and arms
    swing in counter-phase, as people walk.
    """
    swing = math.sin(2.0 * math.pi * phase)
    out = dict(base)
    for side, sign in (("L", 1.0), ("R", -1.0)):
        hip = -25.0 * stride * sign * swing  # negative about x: the thigh forward (towards -y)
        # The knee bends while its leg swings forward (the first half of that leg's cycle).
        knee = 45.0 * stride * max(0.0, math.sin(2.0 * math.pi * phase + (0.0 if sign > 0 else math.pi) + 0.6))
        out[f"upperleg01.{side}"] = axis_rotation("x", hip) @ base.get(f"upperleg01.{side}", np.eye(3))
        out[f"lowerleg01.{side}"] = axis_rotation("x", knee) @ base.get(f"lowerleg01.{side}", np.eye(3))
        arm = 20.0 * stride * sign * swing  # opposite to the leg of the same side
        out[f"shoulder01.{side}"] = axis_rotation("x", arm) @ base.get(f"shoulder01.{side}", np.eye(3))
    return out
