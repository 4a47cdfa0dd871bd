"""What a seed determines is kept across the missions of one SITL process, under keys made of everything that feeds
it: a scene built from the caches draws the pixels a scene built anew draws, and a different light or seed is a
different entry."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from sitl.render.camera import LIT_GROUNDS, OBJECT_MESHES, PERSON_MESHES, SHADOW_MESHES, Light, WorldRenderer
from sitl.render.meshes import _box, _cylinder
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import PeopleModel, ScenarioConfig

CAMERA = PinholeCamera.from_hfov(320, 240, 90.0)
NADIR = T_body_camera_from_mount()
POSE = Pose.from_ned_euler(2.0, -1.0, -16.0, 0.03, -0.02, 0.4)
CACHES = (LIT_GROUNDS, OBJECT_MESHES, PERSON_MESHES, SHADOW_MESHES)


def renderer(seed: int, light: Light, people: PeopleModel = PeopleModel.PROCEDURAL) -> WorldRenderer:
    scenario = ScenarioConfig(moving_fraction=0.3, people=people)
    return WorldRenderer(Park(seed), Crowd(scenario, seed), CAMERA, NADIR, light)


@pytest.mark.integration
def test_a_scene_of_makehuman_people_from_the_caches_draws_the_pixels_of_a_scene_built_anew() -> None:
    # The SITL's default people since issue 63: the second mission of a warm worker draws what the first drew.
    light = Light.from_angles(55.0, 200.0, 0.5)
    fresh = renderer(33, light, PeopleModel.MAKEHUMAN)
    cached = renderer(33, light, PeopleModel.MAKEHUMAN)
    try:
        for t_s in (0.0, 2.5):  # still people, and walkers that moved
            a, b = fresh.render(POSE, t_s), cached.render(POSE, t_s)
            np.testing.assert_array_equal(a.image_bgr, b.image_bgr)
            np.testing.assert_array_equal(a.person_mask, b.person_mask)
            assert a.person_mask.any()
    finally:
        fresh.close()
        cached.close()


@pytest.mark.integration
def test_a_scene_from_the_caches_draws_the_pixels_of_a_scene_built_anew() -> None:
    # Procedural people (an option): each person's mesh, and the shadows, come from the caches.
    light = Light.from_angles(55.0, 200.0, 0.5)
    for cache in CACHES:
        cache.clear()
    fresh = renderer(33, light)
    people = len(fresh.crowd)
    assert people > 0
    assert fresh.crowd.moving.any()
    assert not fresh.crowd.moving.all()  # still people and walkers: both kinds of mesh come from the cache
    first_fresh = fresh.render(POSE, 0.0)
    hits_before = [cache.hits for cache in CACHES]
    cached = renderer(33, light)
    first_cached = cached.render(POSE, 0.0)
    hits = [cache.hits - before for cache, before in zip(CACHES, hits_before, strict=True)]
    try:
        assert hits[0] == 1
        assert hits[1] == (1 if fresh.park.objects else 0)
        assert hits[2] == people
        assert hits[3] == people + 1  # and the walkers' shadow template
        np.testing.assert_array_equal(first_fresh.image_bgr, first_cached.image_bgr)
        np.testing.assert_array_equal(first_fresh.person_mask, first_cached.person_mask)
        a, b = fresh.render(POSE, 2.5), cached.render(POSE, 2.5)  # the walkers have moved
        np.testing.assert_array_equal(a.image_bgr, b.image_bgr)
        np.testing.assert_array_equal(a.person_mask, b.person_mask)
        assert a.person_mask.any()
        assert not np.array_equal(a.image_bgr, first_fresh.image_bgr)
        # Another light (the same seed): another entry, not the cached one.
        misses = PERSON_MESHES.misses
        other = renderer(33, Light.from_angles(30.0, 200.0, 0.5))
        try:
            assert not np.array_equal(other.render(POSE, 2.5).image_bgr, fresh.render(POSE, 2.5).image_bgr)
            assert PERSON_MESHES.misses - misses == people
        finally:
            other.close()
    finally:
        fresh.close()
        cached.close()


def test_people_are_built_from_unit_parts_to_the_bit() -> None:
    """Cylinders and boxes scaled from trimesh's unit ones: the very vertices, faces and normals trimesh.creation
    builds for each size, so a person's mesh (and its baked light) is what it was when every part was created."""
    rng = np.random.default_rng(7)
    for _ in range(50):
        radius, height, z0 = (float(v) for v in rng.uniform(0.01, 1.5, 3))
        ours = _cylinder(radius, height, z0, (10, 20, 30))
        theirs = trimesh.creation.cylinder(radius=radius, height=height, sections=6)
        theirs.apply_translation([0.0, 0.0, z0 + height / 2])
        np.testing.assert_array_equal(ours.vertices, theirs.vertices)
        np.testing.assert_array_equal(ours.faces, theirs.faces)
        np.testing.assert_array_equal(ours.vertex_normals, theirs.vertex_normals)
        extents = tuple(float(v) for v in rng.uniform(0.01, 1.5, 3))
        box = _box(extents, (0.1, -0.2, 0.3), (10, 20, 30))  # type: ignore[arg-type]
        reference = trimesh.creation.box(extents=extents)
        reference.apply_translation((0.1, -0.2, 0.3))
        np.testing.assert_array_equal(box.vertices, reference.vertices)
        np.testing.assert_array_equal(box.faces, reference.faces)
        np.testing.assert_array_equal(box.face_normals, reference.face_normals)
        np.testing.assert_array_equal(box.vertex_normals, reference.vertex_normals)
