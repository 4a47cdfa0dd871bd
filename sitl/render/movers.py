"""The bodies of the people who may move during a scene, as the renderer draws them each frame.

Movers are the walkers and, with people's reaction to the vehicle's warning on (``scenario.reaction``), those who
would step away from it. The renderer keeps them in one mesh per level of detail whose vertex buffer it rewrites each
frame; this module says what goes in it: every mover's vertices where they are now (ENU, m), their lit colours, and
the triangles, which never change. A MakeHuman walker steps through its walk cycle and faces its last step; someone
who stands until a warning moves them keeps the pose they stand in; a procedural person never changes shape.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt
import trimesh

from companion.cache import KeyedCache
from companion.geometry import F64Array
from sitl.render.bodies.figure import WALK_PHASES, Figure, figure_topology, figure_trimesh, walk_phase_at
from sitl.world.crowd import Crowd

U8Array = npt.NDArray[np.uint8]
I64Array = npt.NDArray[np.int64]

WALK_MESHES: KeyedCache[tuple[F64Array, F64Array, F64Array]] = KeyedCache("walking bodies", capacity=4096)
"""MakeHuman walkers: per figure, step of the walk cycle and level of detail, the body facing north (vertices, vertex
normals, RGB colours before light); each frame turns it to the walker's heading and lights it."""


def stacked_faces(parts: Sequence[tuple[I64Array, int]]) -> I64Array:
    """The faces of meshes concatenated in order: each (faces (F, 3), vertex count) offset by those before it."""
    starts = np.cumsum([0, *[count for _, count in parts[:-1]]])
    return np.concatenate([faces + start for (faces, _), start in zip(parts, starts, strict=True)])


class MoverBodies:
    """What the renderer's mesh of movers holds at each frame.

    Parameters
    ----------
    crowd : Crowd
        The scene's people (their positions, walks and reaction).
    ids : sequence of int
        The movers, in the mesh's order.
    figures : list of Figure, or None
        MakeHuman people (None: procedural people).
    person : callable (index, detail) -> trimesh.Trimesh
        Person ``index`` at the origin, lit, as they stand, at a level of detail (a copy).
    sun_dir_enu : ndarray, shape (3,)
        The direction the sunlight travels.
    ambient : float
        Ambient light fraction.
    sun_rgb : ndarray, shape (3,)
        The sun's colour.
    """

    def __init__(
        self,
        crowd: Crowd,
        ids: Sequence[int],
        figures: list[Figure] | None,
        person: Callable[[int, int], trimesh.Trimesh],
        sun_dir_enu: F64Array,
        ambient: float,
        sun_rgb: F64Array,
    ) -> None:
        self.crowd, self.ids, self.figures, self._person = crowd, list(ids), figures, person
        self.sun_dir_enu, self.ambient, self.sun_rgb = sun_dir_enu, ambient, sun_rgb
        self._standing: dict[tuple[int, int], tuple[F64Array, U8Array, I64Array]] = {}
        # A procedural person never changes shape: their vertices at the origin, and the colours of them all.
        self._rest: list[F64Array] = []
        self._rest_colours: U8Array | None = None
        self._rest_faces: I64Array | None = None
        if figures is None and self.ids:
            bodies = [person(i, 0) for i in self.ids]
            self._rest = [np.asarray(b.vertices) for b in bodies]
            self._rest_colours = np.concatenate([np.asarray(b.visual.vertex_colors) for b in bodies])
            self._rest_faces = stacked_faces([(np.asarray(b.faces), len(b.vertices)) for b in bodies])

    def faces(self, detail: int) -> I64Array:
        """The triangles (F, 3) of every mover at level of ``detail``, in the order of :meth:`frame`'s vertices."""
        if self.figures is None:
            assert self._rest_faces is not None
            return self._rest_faces
        return stacked_faces([self._topology(i, detail) for i in self.ids])

    def frame(self, detail: int) -> tuple[F64Array, U8Array, F64Array]:
        """Every mover now at level of ``detail``: vertices (V, 3) ENU m, lit RGBA (V, 4), and each mover's place
        (M, 3) ENU m (their shadows go there)."""
        crowd, figures = self.crowd, self.figures
        bodies, shifts, walk_normals, walk_rgb = [], [], [], []
        own_colours: list[U8Array | None] = []  # per mover: their own lit colours, or None (a walker's, lit below)
        for k, i in enumerate(self.ids):
            north, east = crowd.positions_ne_m[i]
            shift = np.array([east, north, 0.0])
            if figures is not None and crowd.moving[i]:  # a MakeHuman walker: its step, facing its last step
                body, normals, rgb = self._walking_body(i, detail)
                walk_normals.append(normals)
                walk_rgb.append(rgb)
                own_colours.append(None)
            elif figures is not None:  # someone who may step away from a warning: in the pose they stand in
                body, own, _ = self._standing_body(i, detail)
                own_colours.append(own)
            else:
                body = self._rest[k]
            bodies.append(body + shift)
            shifts.append(shift)
        if figures is None:
            assert self._rest_colours is not None
            colours = self._rest_colours
        else:
            lit = self._light(np.concatenate(walk_normals), np.concatenate(walk_rgb)) if walk_rgb else None
            if lit is not None and all(c is None for c in own_colours):
                colours = lit
            else:
                parts, start = [], 0
                for given, body in zip(own_colours, bodies, strict=True):
                    if given is None:
                        assert lit is not None
                        parts.append(lit[start : start + len(body)])
                        start += len(body)
                    else:
                        parts.append(given)
                colours = np.concatenate(parts)
        return np.concatenate(bodies), colours, np.array(shifts)

    def _topology(self, index: int, detail: int) -> tuple[I64Array, int]:
        """A MakeHuman mover's faces and vertex count at ``detail``: a walker's walk, or the pose they stand in."""
        assert self.figures is not None
        if self.crowd.moving[index]:
            return figure_topology(self.figures[index], detail)
        vertices, _, faces = self._standing_body(index, detail)
        return faces, len(vertices)

    def _standing_body(self, index: int, detail: int) -> tuple[F64Array, U8Array, I64Array]:
        """Person ``index``, who stands until a warning moves them, at the origin: vertices (N, 3), lit RGBA (N, 4)
        and faces (F, 3) at ``detail`` (built once per level)."""
        key = (index, detail)
        rest = self._standing.get(key)
        if rest is None:
            still = self._person(index, detail)
            rest = (
                np.asarray(still.vertices, dtype=np.float64),
                np.asarray(still.visual.vertex_colors, dtype=np.uint8),
                np.asarray(still.faces, dtype=np.int64),
            )
            self._standing[key] = rest
        return rest

    def _walking_body(self, index: int, detail: int) -> tuple[F64Array, F64Array, F64Array]:
        """MakeHuman walker ``index`` at the origin now: vertices, vertex normals and RGB before light, each (N, 3).

        The step of the walk cycle follows the distance walked and the body faces its last step; each step of the
        cycle is built once, then turned per frame (and lit with the other walkers, :meth:`_light`).
        """
        assert self.figures is not None
        figure = self.figures[index]
        phase = walk_phase_at(float(self.crowd.walked_m[index]), figure.height_m)

        def build() -> tuple[F64Array, F64Array, F64Array]:
            mesh = figure_trimesh(figure, 0.0, walk_phase=phase, detail=detail)
            rgb = np.asarray(mesh.visual.vertex_colors[:, :3], dtype=np.float64)
            return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.vertex_normals, dtype=np.float64), rgb

        vertices, normals, rgb = WALK_MESHES.get((figure, round(phase * WALK_PHASES), detail), build)
        heading = float(self.crowd.step_heading_rad[index])
        c, s = math.cos(heading), math.sin(heading)
        turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # (row vectors) about z by -heading, ENU
        return vertices @ turn, normals @ turn, rgb

    def _light(self, normals: F64Array, rgb: F64Array) -> U8Array:
        """RGBA (N, 4) of walking bodies: Lambert on their normals (N, 3), as ``bake_lighting`` bakes the rest."""
        diffuse = np.maximum(normals @ (-self.sun_dir_enu), 0.0)[:, None]
        lit = rgb * (self.ambient + (1.0 - self.ambient) * diffuse * self.sun_rgb[None, :])
        colours = np.full((len(rgb), 4), 255, dtype=np.uint8)
        colours[:, :3] = np.minimum(lit, 255.0)
        return colours
