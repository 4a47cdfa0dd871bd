"""A seeded planar scene and an exact pinhole renderer for it: ground texture plus people on the head plane.

This is the lightweight stand-in for the 3-D world: the ground is a textured plane (``down_m = 0``) and each
person is drawn as shoulders and head on the head plane (``down_m = -head_height_m``), each layer warped into the
camera with its plane's homography, so parallax between heads and ground is exact. It gives perception tests
and the demo frames with exact ground truth (people positions and a per-pixel person mask).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from companion.errors import SlzError
from companion.geometry import F64Array, PinholeCamera, Pose
from companion.perception.projection import plane_homography
from sitl.world.park import smooth_noise

U8Image = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class Person:
    """One person seen from above: head-plane position (world NED, m), body radius (m) and colours (BGR)."""

    north_m: float
    east_m: float
    radius_m: float
    clothing_bgr: tuple[int, int, int]
    hair_bgr: tuple[int, int, int]


@dataclass(frozen=True)
class RenderedFrame:
    """A rendered camera frame and its ground truth.

    Attributes
    ----------
    image_bgr : ndarray, shape (H, W, 3), uint8
        The camera image.
    person_mask : ndarray, shape (H, W), bool
        True where a person covers the pixel.
    """

    image_bgr: U8Image
    person_mask: npt.NDArray[np.bool_]


class SceneError(SlzError):
    """A scene cannot be generated as asked (e.g. more people than fit without overlap)."""


class FlatScene:
    """A park-like ground texture and people, all from one seed.

    Parameters
    ----------
    seed : int
        Fixes everything: texture, paths, people, colours.
    n_people : int
        People placed uniformly, without overlap, in the ROI.
    roi_half_m : float
        Half side of the square region of interest around the origin where people stand (paper: 30 m square).
    texture_half_m : float
        Half side of the textured ground square; beyond it the ground is plain.
    texture_res_m : float
        Metres per ground-texture pixel.
    head_height_m : float
        Height of the people's head plane above ground.
    min_gap_m : float
        Minimum free distance between two people's bodies.
    """

    def __init__(
        self,
        seed: int,
        n_people: int = 100,
        roi_half_m: float = 15.0,
        texture_half_m: float = 40.0,
        texture_res_m: float = 0.05,
        head_height_m: float = 1.7,
        min_gap_m: float = 0.1,
    ) -> None:
        if n_people < 0 or roi_half_m <= 0 or texture_half_m < roi_half_m or texture_res_m <= 0:
            raise SceneError(
                f"invalid scene: n_people={n_people} (>= 0), roi_half_m={roi_half_m} (> 0), "
                f"texture_half_m={texture_half_m} (>= roi_half_m), texture_res_m={texture_res_m} (> 0)"
            )
        self.seed = seed
        self.head_height_m = head_height_m
        self.texture_half_m = texture_half_m
        self.texture_res_m = texture_res_m
        rng = np.random.default_rng(seed)
        self.people = self._place_people(rng, n_people, roi_half_m, min_gap_m)
        self.ground_bgr = self._make_ground(rng)
        self._people_layer, self._people_alpha = self._draw_people()

    # -- generation -------------------------------------------------------------------------------------
    def _make_ground(self, rng: np.random.Generator) -> U8Image:
        size = round(2 * self.texture_half_m / self.texture_res_m)
        base = np.array(rng.choice([[60, 120, 70], [55, 105, 85], [70, 125, 95]]), dtype=np.float32)  # grass
        coarse = smooth_noise(rng, (size, size), 40.0)
        fine = smooth_noise(rng, (size, size), 1.0)
        shade = 1.0 + 0.12 * coarse + 0.05 * fine
        ground = base[None, None, :] * shade[:, :, None]
        # Paths: a few straight asphalt/paving strips crossing the park.
        yy, xx = np.mgrid[0:size, 0:size].astype(np.float32) - size / 2
        for _ in range(int(rng.integers(1, 4))):
            colour = np.array(rng.choice([[95, 95, 100], [150, 160, 170], [120, 150, 180]]), dtype=np.float32)
            width_px = rng.uniform(2.0, 5.0) / self.texture_res_m
            angle = rng.uniform(0, math.pi)
            offset = rng.uniform(-0.5, 0.5) * size
            dist = np.abs(xx * math.sin(angle) - yy * math.cos(angle) - offset)
            strip = (dist < width_px / 2)[:, :, None]
            ground = np.where(strip, colour[None, None, :] * (1.0 + 0.04 * fine[:, :, None]), ground)
        return np.clip(ground, 0, 255).astype(np.uint8)

    @staticmethod
    def _place_people(rng: np.random.Generator, n: int, roi_half_m: float, gap_m: float) -> list[Person]:
        people: list[Person] = []
        positions = np.zeros((0, 2))
        radii = np.zeros(0)
        attempts = 0
        while len(people) < n:
            attempts += 1
            if attempts > 200 * max(n, 1):
                raise SceneError(f"cannot place {n} people without overlap in a {2 * roi_half_m:.0f} m square")
            radius = float(rng.uniform(0.2, 0.3))
            pos = rng.uniform(-roi_half_m + radius, roi_half_m - radius, size=2)
            if len(people) and np.any(np.hypot(*(positions - pos).T) < radii + radius + gap_m):
                continue
            clothing = tuple(int(c) for c in rng.integers(20, 236, size=3))
            hair = tuple(int(c) for c in rng.choice([[20, 20, 25], [30, 50, 80], [60, 90, 140], [160, 200, 220]]))
            people.append(Person(float(pos[0]), float(pos[1]), radius, clothing, hair))  # type: ignore[arg-type]
            positions = np.vstack([positions, pos])
            radii = np.append(radii, radius)
        return people

    def _tex_to_world(self) -> F64Array:
        """Affine (3, 3) from texture pixel ``[col, row, 1]`` to ``[north_m, east_m, 1]`` (row 0 is north)."""
        res, half = self.texture_res_m, self.texture_half_m
        return np.array([[0.0, -res, half - 0.5 * res], [res, 0.0, -half + 0.5 * res], [0.0, 0.0, 1.0]])

    def _world_to_tex(self, north_m: float, east_m: float) -> tuple[float, float]:
        res, half = self.texture_res_m, self.texture_half_m
        return (east_m + half) / res - 0.5, (half - north_m) / res - 0.5

    def _draw_people(self) -> tuple[U8Image, U8Image]:
        size = self.ground_bgr.shape[0]
        layer = np.zeros((size, size, 3), dtype=np.uint8)
        alpha = np.zeros((size, size), dtype=np.uint8)
        shift = 4
        scale = 1 << shift
        for person in self.people:
            col, row = self._world_to_tex(person.north_m, person.east_m)
            centre = (round(col * scale), round(row * scale))
            body_px = person.radius_m / self.texture_res_m
            cv2.circle(layer, centre, round(body_px * scale), person.clothing_bgr, -1, cv2.LINE_AA, shift)
            cv2.circle(alpha, centre, round(body_px * scale), 255, -1, cv2.LINE_AA, shift)
            cv2.circle(layer, centre, round(0.45 * body_px * scale), person.hair_bgr, -1, cv2.LINE_AA, shift)
        return layer, alpha

    # -- ground truth -----------------------------------------------------------------------------------
    @property
    def positions_ne_m(self) -> F64Array:
        """People's head-plane positions (N, 2), north and east, metres."""
        return np.array([(p.north_m, p.east_m) for p in self.people]).reshape(-1, 2)

    @property
    def radii_m(self) -> F64Array:
        """People's body radii (N,), metres."""
        return np.array([p.radius_m for p in self.people])

    def clearance_m(self, north_m: float, east_m: float) -> float:
        """Horizontal distance from a point to the nearest person's body edge (negative inside a body)."""
        if not self.people:
            return math.inf
        d = np.hypot(self.positions_ne_m[:, 0] - north_m, self.positions_ne_m[:, 1] - east_m) - self.radii_m
        return float(d.min())

    # -- rendering --------------------------------------------------------------------------------------
    def render(self, camera: PinholeCamera, T_body_camera: F64Array, pose: Pose) -> RenderedFrame:
        """Render the camera's view from ``pose``.

        Parameters
        ----------
        camera : PinholeCamera
            Intrinsics; the frame has ``camera.height_px`` x ``camera.width_px`` pixels.
        T_body_camera : ndarray, shape (4, 4)
            Camera mounting on the body.
        pose : Pose
            Vehicle pose (world NED, body FRD).
        """
        size = (camera.width_px, camera.height_px)
        T_world_camera = pose.T_world_body @ T_body_camera
        tex_to_world = self._tex_to_world()
        H_ground = plane_homography(camera.K, T_world_camera, 0.0) @ tex_to_world
        H_heads = plane_homography(camera.K, T_world_camera, self.head_height_m) @ tex_to_world
        sky = (200, 200, 200)
        image = cv2.warpPerspective(
            self.ground_bgr,
            H_ground,
            size,
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=sky,
        )
        layer = cv2.warpPerspective(self._people_layer, H_heads, size, flags=cv2.INTER_LINEAR)
        alpha = cv2.warpPerspective(self._people_alpha, H_heads, size, flags=cv2.INTER_LINEAR)
        a = (alpha.astype(np.float32) / 255.0)[:, :, None]
        blended = (image.astype(np.float32) * (1.0 - a) + layer.astype(np.float32) * a).astype(np.uint8)
        return RenderedFrame(image_bgr=blended, person_mask=np.asarray(alpha >= 128, dtype=np.bool_))
