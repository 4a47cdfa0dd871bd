"""The SITL's down-looking camera: pyrender, offscreen, on the fast path.

Fast path (the naive scene costs over 100 ms a frame on a 2-core CPU): static geometry merged into two meshes (the
textured ground, every park object), people who stand still merged into one mesh (one per level of detail of
MakeHuman people, the frame's drawn, the others hidden), the walking people into one mesh rewritten each frame from
cached vertices, indexed low-poly geometry, FLAT shading with the sun baked into vertex colours and blob shadows, a
nearest-texel ground texture, no MSAA, no depth read-back unless asked for.
A segmentation pass (people white, everything else black, depth-tested) gives the visible person mask.

Frames: the world is ENU inside the renderer (x east, y north, z up); poses come in as the companion's
``T_world_body`` (NED) and ``T_body_camera`` (OpenCV camera), converted here.
"""

from __future__ import annotations

import enum
import math
import os
import weakref
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import trimesh

from companion.cache import KeyedCache
from companion.errors import SlzError
from companion.geometry import F64Array, PinholeCamera, Pose
from companion.perception.config import ProjectionConfig
from companion.perception.projection import HeadPlaneProjector
from sitl.render.bodies.figure import (
    DETAIL_CELLS_M,
    crowd_figures,
    detail_level,
    figure_head_height_m,
    figure_trimesh,
)
from sitl.render.meshes import bake_lighting, head_height_m, object_mesh, person_mesh, shadow_mesh
from sitl.render.movers import WALK_MESHES as WALK_MESHES
from sitl.render.movers import MoverBodies, stacked_faces
from sitl.world.crowd import Crowd
from sitl.world.park import Park

U8Image = npt.NDArray[np.uint8]

T_ENU_NED = np.array([[0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
T_CV_GL = np.diag([1.0, -1.0, -1.0, 1.0])


class RenderError(SlzError):
    """Rendering failed or cannot start (what, and where)."""

    def __init__(self, where: str, what: str) -> None:
        super().__init__(f"{where}: {what}")
        self.where = where


@dataclass(frozen=True)
class Light:
    """Sunlight baked into the scene."""

    sun_dir_enu: F64Array  # (3,) unit vector the light travels along (pointing down)
    ambient: float
    sun_rgb: F64Array  # (3,) relative colour of sunlight

    @property
    def key(self) -> tuple[float, ...]:
        """Everything this light is made of, as a cache key."""
        return (*(float(v) for v in self.sun_dir_enu), float(self.ambient), *(float(v) for v in self.sun_rgb))

    @property
    def elevation_deg(self) -> float:
        """The sun's elevation above the horizon (a person's shadow is ``height / tan(elevation)`` long)."""
        return math.degrees(math.asin(float(np.clip(-self.sun_dir_enu[2], -1.0, 1.0))))

    @classmethod
    def from_angles(cls, elevation_deg: float, azimuth_deg: float, ambient: float, warmth: float = 0.0) -> Light:
        """Sun at an elevation above the horizon and an azimuth from north towards east."""
        el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
        towards_sun = np.array([math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)])
        return cls(-towards_sun, ambient, np.array([1.0, 1.0 - 0.1 * warmth, 1.0 - 0.25 * warmth]))


@dataclass(frozen=True)
class RenderedView:
    """One camera frame and its ground truth.

    Attributes
    ----------
    image_bgr : ndarray, shape (H, W, 3), uint8
        What the camera sees (before weather effects).
    person_mask : ndarray, shape (H, W), bool
        Pixels where a person is visible.
    depth_m : ndarray, shape (H, W), float32
        Depth along the optical axis, metres (0 where nothing was hit).
    """

    image_bgr: U8Image
    person_mask: npt.NDArray[np.bool_]
    depth_m: npt.NDArray[np.float32]


_OFFSCREEN: dict[tuple[int, int], Any] = {}


class DrawSlot(enum.Enum):
    """Where a mesh of the scene is drawn among the others when pyrender's order ties (see :func:`_patch_pyrender`)."""

    GROUND = 0
    OBJECTS = 1
    STILL_PEOPLE = 2
    STILL_SHADOWS = 3
    WALKERS = 4
    WALKER_SHADOWS = 5


class _Bgr:
    """A colour image already in BGR order (the lean read-back), told apart from pyrender's RGB arrays."""

    def __init__(self, image: npt.NDArray[np.uint8]) -> None:
        self.image = image


_PATCHED: list[bool] = []
DRAW_ORDER: weakref.WeakKeyDictionary[Any, dict[Any, int]] = weakref.WeakKeyDictionary()
"""Per pyrender scene: its mesh nodes in the order they were added (see :func:`_patch_pyrender`)."""

# What the last scenes' seeds determined, kept across the missions of this process: the park's lit ground texture and
# its objects for two scenes, each person's lit mesh and shadow for a few hundred people. A campaign flies every scene
# once per strategy and a warm worker flies a scene's strategies in a row, so the second and third missions find the
# scene built. Each value is a pure function of its key, made of everything that feeds it (seed, scenario fields,
# light): the same mission draws the same pixels, cached or not.
LIT_GROUNDS: KeyedCache[npt.NDArray[np.uint8]] = KeyedCache("lit grounds", capacity=2)
OBJECT_MESHES: KeyedCache[trimesh.Trimesh] = KeyedCache("park objects", capacity=2)
PERSON_MESHES: KeyedCache[trimesh.Trimesh] = KeyedCache("person meshes", capacity=1024)
SHADOW_MESHES: KeyedCache[trimesh.Trimesh] = KeyedCache("shadow meshes", capacity=512)
SHADOW_SCALE_MAKEHUMAN = 0.6


def _patch_pyrender(pyrender: Any, GL: Any) -> None:
    """Once per process: MSAA off, a lean read-back when depth is not wanted, and a draw order that does not depend
    on memory addresses."""
    if _PATCHED:
        return
    _PATCHED.append(True)

    # pyrender draws a scene's meshes far to near by their nodes' positions and breaks ties in the order of
    # ``scene.mesh_nodes``, a set whose order follows the nodes' memory addresses. Our meshes are all at the origin
    # (their vertices are in world coordinates), so every one ties: their order, and with it the winner of a pixel
    # where two surfaces meet at one depth, changed from process to process. Measured: 1 or 2 pixels in some frames,
    # enough for two flights of one seed to land at different points. Ties now go by the order the nodes were
    # added (``DRAW_ORDER``).
    def sorted_mesh_nodes(self: Any, scene: Any) -> list[Any]:
        order = DRAW_ORDER.get(scene, {})
        camera_at = scene.get_pose(scene.main_camera_node)[:3, 3]

        def key(node: Any) -> tuple[float, int]:
            return -float(np.linalg.norm(scene.get_pose(node)[:3, 3] - camera_at)), order.get(node, len(order))

        nodes = sorted(scene.mesh_nodes, key=key)
        return [n for n in nodes if not n.mesh.is_transparent] + [n for n in nodes if n.mesh.is_transparent]

    pyrender.renderer.Renderer._sorted_mesh_nodes = sorted_mesh_nodes

    # pyrender 0.1.45 always allocates a 4x multisampled framebuffer; with 0 samples the same code path runs
    # without MSAA, which costs a third of the frame time on a software rasterizer.
    def storage_without_msaa(target: int, samples: int, fmt: int, width_: int, height_: int) -> None:
        GL.glRenderbufferStorageMultisample(target, 0, fmt, width_, height_)

    pyrender.renderer.glRenderbufferStorageMultisample = storage_without_msaa
    full_read = pyrender.renderer.Renderer._read_main_framebuffer

    def read_framebuffer(self: Any, scene: Any, flags: int) -> Any:
        """pyrender's read-back, or colour alone when depth is not wanted: no blit, no depth linearization, and
        read as BGRA (the fastest format for Mesa), so the frame comes back in OpenCV's BGR order."""
        if not getattr(self, "slz_skip_depth", False) or flags & (
            pyrender.RenderFlags.DEPTH_ONLY | pyrender.RenderFlags.RGBA
        ):
            return full_read(self, scene, flags)
        width, height = self._main_fb_dims
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb_ms)
        data = GL.glReadPixels(0, 0, width, height, GL.GL_BGRA, GL.GL_UNSIGNED_BYTE)
        bgra = np.frombuffer(data, dtype=np.uint8).reshape((height, width, 4))
        # OpenCV's SIMD copies: numpy's strided [::-1, :, :3] copy costs ~2 ms a frame here.
        bgr = cv2.flip(cv2.cvtColor(bgra, cv2.COLOR_BGRA2BGR), 0)
        return _Bgr(np.asarray(bgr, dtype=np.uint8)), None

    pyrender.renderer.Renderer._read_main_framebuffer = read_framebuffer


def _make_offscreen(width: int, height: int) -> Any:
    """The process's offscreen renderer for this size, created once and kept.

    pyrender's ``delete()`` terminates the EGL display that every context of the process shares, so contexts are
    never deleted while the process lives: scenes come and go, the renderer stays (as a campaign worker wants).
    """
    if (width, height) in _OFFSCREEN:
        return _OFFSCREEN[(width, height)]
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    try:
        import pyrender
        import pyrender.renderer
        from OpenGL import GL
    except Exception as exc:  # ImportError, or PyOpenGL failing to find libEGL
        raise RenderError("render.import", f"cannot import pyrender/OpenGL with EGL: {exc}") from None
    _patch_pyrender(pyrender, GL)
    try:
        renderer = pyrender.OffscreenRenderer(width, height)
    except Exception as exc:
        raise RenderError(
            "render.egl",
            f"cannot create an offscreen EGL context: {exc} (scripts/install-system-deps.sh installs Mesa)",
        ) from None
    _OFFSCREEN[(width, height)] = renderer
    return renderer


class WorldRenderer:
    """Renders a park and its crowd from the vehicle's camera.

    Parameters
    ----------
    park, crowd : Park, Crowd
        The world; the crowd is advanced to each frame's time.
    camera : PinholeCamera
        Intrinsics (the frame size is the camera's).
    T_body_camera : ndarray, shape (4, 4)
        Camera mounting (body FRD, OpenCV camera).
    light : Light
        Sun and ambient light.
    """

    def __init__(self, park: Park, crowd: Crowd, camera: PinholeCamera, T_body_camera: F64Array, light: Light) -> None:
        import pyrender

        self._pyrender = pyrender
        self.park, self.crowd, self.camera, self.light = park, crowd, camera, light
        self.T_body_camera = np.asarray(T_body_camera, dtype=np.float64)
        self._renderer = _make_offscreen(camera.width_px, camera.height_px)
        self.scene = pyrender.Scene(ambient_light=[1.0, 1.0, 1.0], bg_color=[0.78, 0.82, 0.86, 1.0])
        self._black: dict[Any, tuple[int, int, int]] = {}
        self._people_nodes: list[Any] = []
        self.figures = crowd_figures(crowd)
        self._build_static()
        self._build_people()
        cam = pyrender.IntrinsicsCamera(
            camera.fx_px, camera.fy_px, camera.cx_px + 0.5, camera.cy_px + 0.5, znear=0.3, zfar=1000.0
        )
        self._camera_node = self.scene.add(cam, pose=np.eye(4))

    def _add(self, mesh: Any, slot: DrawSlot, detail: int = 0) -> Any:
        """Add a mesh at the origin; at a tie of pyrender's order it is drawn by its slot, then its level of detail
        (the order does not depend on when a mesh was built: levels are built when first drawn)."""
        node = self.scene.add(mesh)
        DRAW_ORDER.setdefault(self.scene, {})[node] = slot.value * len(DETAIL_CELLS_M) + detail
        return node

    def _build_static(self) -> None:
        pr = self._pyrender
        e = self.park.extent_m
        corners = np.array([[-e, -e, 0.0], [e, -e, 0.0], [e, e, 0.0], [-e, e, 0.0]])  # ENU
        uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # texture row 0 is north: v = 1 at north
        ground = trimesh.Trimesh(vertices=corners, faces=[[0, 1, 2], [0, 2, 3]], process=False)
        lit = LIT_GROUNDS.get((self.park.key, self.light.key), self._lit_ground)
        from OpenGL import GL

        # Nearest texel, no mipmaps: trilinear sampling of the full-screen ground cost a software rasterizer ~6 ms,
        # bilinear ~1.5 ms more than nearest. Texels are 5 cm: about one per pixel at 20 m, under two at 10 m.
        sampler = pr.Sampler(magFilter=GL.GL_NEAREST, minFilter=GL.GL_NEAREST)
        texture = pr.Texture(source=np.ascontiguousarray(lit[::-1]), source_channels="RGB", sampler=sampler)
        material = pr.MetallicRoughnessMaterial(baseColorTexture=texture, metallicFactor=0.0)
        primitive = pr.Primitive(
            positions=ground.vertices, indices=ground.faces, texcoord_0=uv, material=material, mode=4
        )
        self._black[self._add(pr.Mesh([primitive]), DrawSlot.GROUND)] = (0, 0, 0)
        if self.park.objects:
            objects = OBJECT_MESHES.get((self.park.key, self.light.key), self._objects_mesh).copy()
            self._black[self._add(pr.Mesh.from_trimesh(objects, smooth=True), DrawSlot.OBJECTS)] = (0, 0, 0)

    def _lit_ground(self) -> npt.NDArray[np.uint8]:
        """The ground texture under this light, RGB (read-only: it is shared through LIT_GROUNDS)."""
        image = self.park.ground_bgr[:, :, ::-1]
        light = self.light.ambient + (1 - self.light.ambient) * max(0.0, -float(self.light.sun_dir_enu[2]))
        lit = np.clip(image.astype(np.float32) * light * self.light.sun_rgb[None, None, :], 0, 255).astype(np.uint8)
        lit.setflags(write=False)
        return lit

    def _objects_mesh(self) -> trimesh.Trimesh:
        """The park's objects in one mesh, lit."""
        objects = trimesh.util.concatenate([object_mesh(o) for o in self.park.objects])
        bake_lighting(objects, self.light.sun_dir_enu, self.light.ambient, self.light.sun_rgb)
        return objects

    def _person(self, index: int, detail: int = 0) -> trimesh.Trimesh:
        """Person ``index`` at the origin, lit (a copy: the caller moves it); MakeHuman people at a level of detail."""
        a = self.crowd.appearances[index]
        figure = self.figures[index] if self.figures is not None else None

        def build() -> trimesh.Trimesh:
            heading = float(np.random.default_rng([index, 6]).uniform(-math.pi, math.pi))
            mesh = person_mesh(a, heading) if figure is None else figure_trimesh(figure, heading, detail=detail)
            return bake_lighting(mesh, self.light.sun_dir_enu, self.light.ambient, self.light.sun_rgb)

        key = (a, index, self.light.key) if figure is None else (figure, index, self.light.key, detail)
        return PERSON_MESHES.get(key, build).copy()

    def detail_at(self, pose: Pose) -> int:
        """The level of detail people are drawn at from ``pose`` (:func:`detail_level` of the ground pixel footprint
        below the camera, metres per pixel; always 0 for procedural people, who have one)."""
        if self.figures is None:
            return 0
        height_m = -float((pose.T_world_body @ self.T_body_camera)[2, 3])  # NED: the camera's height over z = 0
        return detail_level(max(height_m, 0.0) / self.camera.fx_px)

    def _shadow(self, index: int, north_m: float, east_m: float) -> trimesh.Trimesh:
        """Person ``index``'s shadow on the ground at (``north_m``, ``east_m``), lit (shared: never modified)."""
        a = self.crowd.appearances[index]

        def build() -> trimesh.Trimesh:
            # A MakeHuman body is narrower than the procedural footprint radius (shoulders ~0.45 m across).
            radius_m = a.radius_m * (SHADOW_SCALE_MAKEHUMAN if self.figures is not None else 1.0)
            mesh = shadow_mesh(north_m, east_m, radius_m, self.light.sun_dir_enu, a.height_m)
            return bake_lighting(mesh, self.light.sun_dir_enu, self.light.ambient, self.light.sun_rgb)

        return SHADOW_MESHES.get((a, index, north_m, east_m, self.light.key, self.figures is not None), build)

    def _build_people(self) -> None:
        crowd = self.crowd
        # People who stand still: one mesh per level of detail, and one mesh of their shadows. Every level is built
        # here, with the scene, not at the first frame that draws it: a SITL's first frames must not wait on it (a
        # camera check times their age on the vehicle clock).
        mobile = crowd.mobile  # walkers, and those who would step away from the vehicle's warning
        self._still_ids = [i for i in range(len(crowd)) if not mobile[i]]
        self._still_nodes: dict[int, Any] = {}
        if self._still_ids:
            shadows = [self._shadow(i, *map(float, crowd.positions_ne_m[i])) for i in self._still_ids]
            shadows_mesh = self._pyrender.Mesh.from_trimesh(trimesh.util.concatenate(shadows), smooth=True)
            shadow_node = self._add(shadows_mesh, DrawSlot.STILL_SHADOWS)
            self._black[shadow_node] = (0, 0, 0)
            for detail in range(len(DETAIL_CELLS_M) if self.figures is not None else 1):
                self._still_people(detail).mesh.is_visible = False  # until a frame draws its level
        # Walking people: one mesh per level of detail (and one of their shadows) built at the first frame from
        # cached local vertices, then moved by rewriting its vertex buffer in place each frame (one draw call, no new
        # GL objects).
        self._mover_ids = [int(i) for i in np.nonzero(mobile)[0]]
        light = self.light
        self._movers = MoverBodies(
            crowd, self._mover_ids, self.figures, self._person, light.sun_dir_enu, light.ambient, light.sun_rgb
        )
        self._mover_shadows = [np.asarray(self._shadow(i, 0.0, 0.0).vertices) for i in self._mover_ids]
        self._mover_nodes: dict[int, Any] = {}
        self._mover_shadow_node: Any = None
        if self._mover_ids:
            template = self._shadow(self._mover_ids[0], 0.0, 0.0)  # every shadow is the same 10-sided disc mesh
            self._shadow_faces_all = stacked_faces([(np.asarray(template.faces), len(s)) for s in self._mover_shadows])
            shadow_count = sum(len(s) for s in self._mover_shadows)
            self._shadow_colours_all = np.tile(np.asarray(template.visual.vertex_colors[:1]), (shadow_count, 1))

    def _still_people(self, detail: int) -> Any:
        """The node of every person who stands still at level of ``detail`` (built once)."""
        node = self._still_nodes.get(detail)
        if node is None:
            parts = []
            for i in self._still_ids:
                north, east = self.crowd.positions_ne_m[i]
                m = self._person(i, detail)
                m.apply_translation([east, north, 0.0])
                parts.append(m)
            mesh = self._pyrender.Mesh.from_trimesh(trimesh.util.concatenate(parts), smooth=True)
            node = self._add(mesh, DrawSlot.STILL_PEOPLE, detail)
            self._still_nodes[detail] = node
        return node

    def head_height_m(self, index: int) -> float:
        """Height above the ground of the centre of person ``index``'s head (the point a density model finds)."""
        if self.figures is not None:
            return figure_head_height_m(self.figures[index])
        return head_height_m(self.crowd.appearances[index])

    def head_pixels(self, pose: Pose) -> tuple[F64Array, npt.NDArray[np.bool_]]:
        """Where each person's head centre projects from ``pose``, with the companion's own head-plane projector.

        Returns
        -------
        pixels : ndarray, shape (N, 2)
            (u, v) per person, in pixels.
        ok : ndarray, shape (N,), bool
            Whether the head is in front of the camera (``pixels`` is meaningless where not).
        """
        pixels = np.zeros((len(self.crowd), 2))
        ok = np.zeros(len(self.crowd), dtype=bool)
        for i in range(len(self.crowd)):
            config = ProjectionConfig(head_height_m=self.head_height_m(i))
            projector = HeadPlaneProjector(self.camera, self.T_body_camera, config)
            pixel, front = projector.plane_to_pixel(self.crowd.positions_ne_m[i : i + 1], pose)
            pixels[i], ok[i] = pixel[0], front[0]
        return pixels, ok

    def T_gl_camera(self, pose: Pose) -> F64Array:
        """The pyrender camera pose (ENU world, OpenGL camera axes) for a vehicle pose."""
        T_ned_camera = pose.T_world_body @ self.T_body_camera
        return np.asarray(T_ENU_NED @ T_ned_camera @ T_CV_GL, dtype=np.float64)

    def _update_movers(self, detail: int) -> Any:
        """Move the walkers to their places now, drawn at level of ``detail``; returns the node of their bodies."""
        pr = self._pyrender
        vertices, colours, shifts = self._movers.frame(detail)
        shadows = np.concatenate([shadow + shift for shadow, shift in zip(self._mover_shadows, shifts, strict=True)])
        node = self._mover_nodes.get(detail)
        if node is not None:
            # In place: rewrite the interleaved [x y z r g b a] float32 vertex buffers pyrender uploaded.
            body_primitive = node.mesh.primitives[0]
            if self.figures is not None:  # MakeHuman walkers are lit anew each frame; procedural colours never change
                body_primitive.color_0 = colours
            self._rewrite_positions(body_primitive, vertices)
            self._rewrite_positions(self._mover_shadow_node.mesh.primitives[0], shadows)
            return node
        faces = self._movers.faces(detail)  # the same at every step of a walk
        primitive = pr.Primitive(positions=vertices, indices=faces, color_0=colours, mode=4)
        node = self._add(pr.Mesh([primitive]), DrawSlot.WALKERS, detail)
        self._mover_nodes[detail] = node
        if self._mover_shadow_node is None:
            shadow_mesh_ = pr.Mesh(
                [
                    pr.Primitive(
                        positions=shadows,
                        indices=self._shadow_faces_all,
                        color_0=self._shadow_colours_all,
                        mode=4,
                    )
                ]
            )
            self._mover_shadow_node = self._add(shadow_mesh_, DrawSlot.WALKER_SHADOWS)
            self._black[self._mover_shadow_node] = (0, 0, 0)
        else:
            self._rewrite_positions(self._mover_shadow_node.mesh.primitives[0], shadows)
        return node

    def _rewrite_positions(self, primitive: Any, positions: F64Array) -> None:
        if primitive._vaid is None:  # not uploaded yet: pyrender will upload these on the next draw
            primitive.positions = positions
            return
        from OpenGL import GL

        data = np.ascontiguousarray(np.hstack([positions, primitive.color_0]).astype(np.float32).ravel())
        self._renderer._platform.make_current()
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, primitive._buffers[0])
        GL.glBufferSubData(GL.GL_ARRAY_BUFFER, 0, data.nbytes, data)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)

    def render(self, pose: Pose, t_s: float, with_mask: bool = True, with_depth: bool = True) -> RenderedView:
        """The camera frame at simulated time ``t_s`` from ``pose``, with (optionally) its depth and person mask.

        The mask costs a second render pass; without it ``person_mask`` is all False. Without depth (needed only for
        depth-aware fog) ``depth_m`` is all zeros and the read-back is cheaper.
        """
        pr = self._pyrender
        self.crowd.advance_to(t_s)
        detail = self.detail_at(pose)
        people = []  # the nodes drawn at this level; the other levels' stay hidden
        if self._still_ids:
            people.append(self._still_people(detail))
        if self._mover_ids:
            people.append(self._update_movers(detail))
        for node in [*self._still_nodes.values(), *self._mover_nodes.values()]:
            node.mesh.is_visible = node in people
        self.scene.set_pose(self._camera_node, self.T_gl_camera(pose))
        try:
            self._renderer._renderer.slz_skip_depth = not with_depth
            colour, depth = self._renderer.render(self.scene, flags=pr.RenderFlags.FLAT)
            image_bgr = np.ascontiguousarray(colour.image if isinstance(colour, _Bgr) else colour[:, :, ::-1])
            self._renderer._renderer.slz_skip_depth = True  # the mask pass never needs depth
            if depth is None:
                depth = np.zeros(image_bgr.shape[:2], dtype=np.float32)
            if with_mask:
                seg_map = {**self._black, **{node: (255, 255, 255) for node in people}}
                seg, _ = self._renderer.render(self.scene, flags=pr.RenderFlags.SEG, seg_node_map=seg_map)
                seg_image = seg.image if isinstance(seg, _Bgr) else seg  # people are white in any channel order
                mask = np.asarray(seg_image[:, :, 0] > 127)
            else:
                mask = np.zeros(depth.shape, dtype=bool)
        except Exception as exc:
            raise RenderError("render.frame", str(exc)) from None
        return RenderedView(
            image_bgr=image_bgr,
            person_mask=mask,
            depth_m=np.asarray(depth, dtype=np.float32),
        )

    def close(self) -> None:
        """Drop this world's scene; its GPU buffers are freed when the shared renderer draws another scene."""
        self.scene.clear()
