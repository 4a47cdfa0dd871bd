"""Meshes of people and park objects, with lighting baked into vertex colours (rendered with FLAT shading).

Mesh frame: ENU, metres (x east, y north, z up), z = 0 on the ground. Colours are RGB in [0, 255].
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import trimesh

from sitl.world.crowd import Appearance, BodyType
from sitl.world.park import BENCH_BACK_M, BENCH_SEAT_DEPTH_M, CAR_WIDTH_M, POLE_LAMP_RADIUS_M, ObjectKind, ParkObject

F64Array = npt.NDArray[np.float64]
RGB = tuple[int, int, int]
SHADOW_RGB = (28, 38, 30)


def _rgb(bgr: tuple[int, int, int]) -> RGB:
    return bgr[2], bgr[1], bgr[0]


def _part(mesh: trimesh.Trimesh, colour: RGB) -> trimesh.Trimesh:
    mesh.visual.vertex_colors = np.array([*colour, 255], dtype=np.uint8)
    return mesh


# trimesh's unit cylinder (6 sections) and unit box: a part is one of them scaled, which gives the very vertices
# (bit for bit) and faces trimesh.creation builds for that size without building them again (a scene has ~1,000
# parts; a person's mesh 4.2 -> 2.2 ms).
_UNIT_CYLINDER = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=6)
_UNIT_BOX = trimesh.creation.box(extents=(1.0, 1.0, 1.0))


def _scaled(unit: trimesh.Trimesh, scale: tuple[float, float, float]) -> trimesh.Trimesh:
    # trimesh.creation.box states its (axis-aligned) face normals and the cylinder leaves them to be computed: the
    # same here, so that every later step (concatenation, rotation, lighting) sees what it saw before.
    normals = unit.face_normals.copy() if unit is _UNIT_BOX else None
    return trimesh.Trimesh(
        vertices=unit.vertices * np.array(scale), faces=unit.faces.copy(), face_normals=normals, process=False
    )


def _cylinder(radius: float, height: float, z0: float, colour: RGB, x: float = 0.0, y: float = 0.0) -> trimesh.Trimesh:
    m = _scaled(_UNIT_CYLINDER, (radius, radius, height))
    m.apply_translation([x, y, z0 + height / 2])
    return _part(m, colour)


def _box(extents: tuple[float, float, float], centre: tuple[float, float, float], colour: RGB) -> trimesh.Trimesh:
    m = _scaled(_UNIT_BOX, extents)
    m.apply_translation(centre)
    return _part(m, colour)


def _sphere(radius: float, centre: tuple[float, float, float], colour: RGB, subdivisions: int = 0) -> trimesh.Trimesh:
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    m.apply_translation(centre)
    return _part(m, colour)


def head_height_m(a: Appearance) -> float:
    """Height of the centre of a person's head above the ground (the point a density model is trained to find)."""
    h = a.height_m
    sitting = a.body in (BodyType.ADULT_SITTING, BodyType.CHILD_SITTING)
    hip = 0.25 * h if sitting else 0.47 * h
    return hip + 0.3 * h + 0.065 * h * 1.1


def person_mesh(a: Appearance, heading_rad: float) -> trimesh.Trimesh:
    """A person at the origin facing ``heading_rad`` (from north towards east), feet on z = 0.

    Each body type has its own silhouette: posture, limbs, and carried things (backpack, umbrella, cane, stroller).
    """
    h, r = a.height_m, a.radius_m
    top, bottom, hair = _rgb(a.top_bgr), _rgb(a.bottom_bgr), _rgb(a.hair_bgr)
    secondary: RGB = (int(top[0] * 0.6), int(top[1] * 0.6), int(top[2] * 0.6))  # patterns: a second tone
    sitting = a.body in (BodyType.ADULT_SITTING, BodyType.CHILD_SITTING)
    walking = a.body in (BodyType.ADULT_WALKING, BodyType.CHILD_WALKING, BodyType.PERSON_WITH_STROLLER)
    broad = 1.3 if a.body is BodyType.ADULT_BROAD else (0.8 if a.body is BodyType.ADULT_SLIM else 1.0)
    leg_h = 0.47 * h
    hip = 0.25 * h if sitting else leg_h
    parts: list[trimesh.Trimesh] = []
    # Legs (forward is +y in the local frame before rotation).
    if sitting:
        parts.append(_box((0.3 * r * 2, 0.45 * h * 0.6, 0.12), (0.0, 0.2 * h, hip), bottom))
        parts.append(_box((0.35 * r * 2, 0.35, hip), (0.0, 0.0, hip / 2), (70, 70, 70)))  # the seat
    else:
        stride = 0.12 * h if walking else 0.0
        for side, y in ((-1, stride), (1, -stride)):
            parts.append(_cylinder(0.07 * h / 1.75, leg_h, 0.0, bottom, x=side * 0.35 * r, y=y))
    torso_h = 0.3 * h
    parts.append(_cylinder(0.55 * r * broad, torso_h, hip, top))
    if a.pattern in ("striped", "checked", "two_tone"):
        parts.append(_cylinder(0.56 * r * broad, torso_h * 0.3, hip + torso_h * 0.35, secondary))
    # Arms.
    arm_len = 0.33 * h
    if a.body is BodyType.ADULT_ARMS_OUT:
        for side in (-1, 1):
            parts.append(
                _box((arm_len, 0.08, 0.08), (side * (0.55 * r * broad + arm_len / 2), 0.0, hip + 0.85 * torso_h), top)
            )
    else:
        for side in (-1, 1):
            parts.append(
                _box((0.08, 0.08, arm_len), (side * (0.55 * r * broad + 0.05), 0.0, hip + torso_h - arm_len / 2), top)
            )
    # Head, hair, hat.
    head_r = 0.065 * h
    head_z = hip + torso_h + head_r * 1.1
    parts.append(_sphere(head_r, (0.0, 0.0, head_z), (225, 185, 160)))
    parts.append(_sphere(head_r * 1.02, (0.0, -0.01, head_z + head_r * 0.35), hair))
    if a.hat_bgr is not None:
        parts.append(_cylinder(head_r * 1.6, 0.03, head_z + head_r * 0.7, _rgb(a.hat_bgr)))
        parts.append(_cylinder(head_r * 0.9, 0.1, head_z + head_r * 0.7, _rgb(a.hat_bgr)))
    # Carried things.
    if a.body is BodyType.ADULT_WITH_BACKPACK:
        parts.append(_box((0.3, 0.18, 0.4), (0.0, -0.55 * r - 0.09, hip + 0.5 * torso_h), (40, 50, 90)))
    if a.body is BodyType.ADULT_WITH_UMBRELLA:
        canopy = trimesh.creation.cone(radius=0.5, height=0.25, sections=10)
        canopy.apply_translation([0.15, 0.1, h + 0.2])
        parts.append(_part(canopy, _rgb(a.bottom_bgr)))
    if a.body is BodyType.ELDERLY_WITH_CANE:
        parts.append(_cylinder(0.015, 0.85, 0.0, (90, 60, 30), x=0.35, y=0.15))
    if a.body is BodyType.PERSON_WITH_STROLLER:
        parts.append(_box((0.5, 0.8, 0.5), (0.0, 0.75, 0.35), (30, 30, 40)))
    mesh = trimesh.util.concatenate(parts)
    # Heading from north towards east, in ENU: a rotation of -heading about z.
    mesh.apply_transform(trimesh.transformations.rotation_matrix(-heading_rad, [0, 0, 1]))
    return mesh


def object_mesh(o: ParkObject) -> trimesh.Trimesh:
    """A park object on the ground at its position."""
    colour = _rgb(o.colour_bgr)
    parts: list[trimesh.Trimesh]
    if o.kind is ObjectKind.TREE:
        trunk = _cylinder(0.15, o.height_m * 0.6, 0.0, (80, 60, 40))
        crown_colour = (40 + colour[0] % 30, 90 + colour[1] % 50, 40 + colour[2] % 30)
        parts = [trunk, _sphere(o.size_m / 2, (0.0, 0.0, o.height_m - o.size_m / 3), crown_colour, subdivisions=1)]
    elif o.kind is ObjectKind.CAR:
        body = _box((CAR_WIDTH_M, o.size_m, 0.8), (0.0, 0.0, 0.55), colour)
        cabin = _box((1.6, o.size_m * 0.5, 0.6), (0.0, -0.2, 1.2), (50, 60, 70))
        parts = [body, cabin]
    elif o.kind is ObjectKind.BENCH:
        parts = [
            _box((BENCH_SEAT_DEPTH_M, o.size_m, 0.06), (0.0, 0.0, o.height_m), (120, 80, 50)),
            _box((BENCH_BACK_M, o.size_m, 0.4), (-BENCH_SEAT_DEPTH_M / 2, 0.0, o.height_m + 0.2), (120, 80, 50)),
        ]
    elif o.kind is ObjectKind.BIN:
        parts = [_cylinder(o.size_m / 2, o.height_m, 0.0, colour)]
    elif o.kind is ObjectKind.BUSH:
        parts = [_sphere(o.size_m / 2, (0.0, 0.0, o.height_m / 2), (45, 100 + colour[1] % 40, 45))]
    elif o.kind is ObjectKind.POLE:
        parts = [
            _cylinder(o.size_m / 2, o.height_m, 0.0, (110, 110, 115)),
            _sphere(POLE_LAMP_RADIUS_M, (0.0, 0.0, o.height_m), (240, 240, 210)),
        ]
    else:  # flat blobs on the ground: stains, manhole covers, litter, light patches
        tone = (25, 25, 30) if o.kind is ObjectKind.DARK_BLOB else (235, 235, 225)
        disc = trimesh.creation.cylinder(radius=o.size_m / 2, height=0.01, sections=12)
        disc.apply_translation([0, 0, 0.01])
        parts = [_part(disc, tone)]
    mesh = trimesh.util.concatenate(parts)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(-o.heading_rad, [0, 0, 1]))
    mesh.apply_translation([o.east_m, o.north_m, 0.0])
    return mesh


def shadow_mesh(
    north_m: float, east_m: float, radius_m: float, sun_dir_enu: F64Array, height_m: float
) -> trimesh.Trimesh:
    """A dark blob on the ground, stretched away from the sun (a cheap stand-in for shadow mapping)."""
    disc = trimesh.creation.cylinder(radius=radius_m * 1.2, height=0.005, sections=10)
    horizontal = sun_dir_enu[:2]
    elevation = math.atan2(-sun_dir_enu[2], float(np.hypot(*horizontal)) + 1e-9)
    length = min(height_m / max(math.tan(elevation), 0.2), 4.0)
    scale = np.eye(4)
    scale[0, 0] = 1.0 + length / (2 * radius_m * 1.2)
    disc.apply_transform(scale)
    angle = math.atan2(-horizontal[1], -horizontal[0])
    disc.apply_transform(trimesh.transformations.rotation_matrix(angle, [0, 0, 1]))
    offset = -horizontal / (np.linalg.norm(horizontal) + 1e-9) * length / 2
    disc.apply_translation([east_m + offset[0], north_m + offset[1], 0.006])
    return _part(disc, (0, 0, 0))


def bake_lighting(mesh: trimesh.Trimesh, sun_dir_enu: F64Array, ambient: float, sun_rgb: F64Array) -> trimesh.Trimesh:
    """Multiply vertex colours by ambient + diffuse sunlight (Lambert on vertex normals); shadows stay black-ish."""
    normals = mesh.vertex_normals
    diffuse = np.clip(normals @ (-sun_dir_enu), 0.0, 1.0)[:, None]
    light = ambient + (1.0 - ambient) * diffuse * sun_rgb[None, :]
    colours = mesh.visual.vertex_colors.astype(np.float64)
    is_shadow = np.all(colours[:, :3] == 0, axis=1)
    colours[:, :3] = np.clip(colours[:, :3] * light, 0, 255)
    mesh.visual.vertex_colors = colours.astype(np.uint8)
    mesh.visual.vertex_colors[is_shadow] = np.array([*SHADOW_RGB, 255], dtype=np.uint8)
    return mesh
