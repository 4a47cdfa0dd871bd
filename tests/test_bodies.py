"""MakeHuman people: the asset readers, the rig, the packed library, seeded figures and their rendering."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from sitl.assets.makehuman_files import AssetFormatError, read_bvh, read_fitting
from sitl.assets.makehuman_pack import pack
from sitl.render import camera as camera_module
from sitl.render.bodies.figure import (
    DETAIL_CELLS_M,
    MAX_CELL_PX,
    MUTED_RGB,
    Figure,
    FigureMesh,
    crowd_figures,
    detail_level,
    draw_figure,
    figure_mesh,
    walk_phase_at,
)
from sitl.render.bodies.library import PACK_PATH, PartKind, load_library
from sitl.render.bodies.rig import Rig, axis_rotation, skin
from sitl.render.camera import Light, WorldRenderer
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import PeopleModel, ScenarioConfig, WalkerKind

ASSETS = Path(__file__).resolve().parents[2] / "shared" / "assets" / "makehuman"


# -- readers -------------------------------------------------------------------------------------------------------
@pytest.mark.unit
def test_a_fitting_file_reads_weighted_lines_single_indices_and_ranges(tmp_path: Path) -> None:
    path = tmp_path / "shirt.mhclo"
    path.write_text(
        "# comment\nname shirt\nobj_file shirt.obj\nx_scale 0 1 2.0\ny_scale 0 2 1.0\nz_scale 0 3 1.0\n"
        "verts 0\nmaterial shirt.mhmat\n 0 1 2 0.5 0.25 0.25 0.1 0.0 -0.1\n3\ndelete_verts\n1 - 3 5\n",
        encoding="utf-8",
    )
    fitting = read_fitting(path)
    assert fitting.obj_file == "shirt.obj"
    assert fitting.refs.tolist() == [[0, 1, 2], [3, 3, 3]]  # a keyword line inside 'verts' does not end it
    assert fitting.delete_verts.tolist() == [1, 2, 3, 5]
    base = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]])
    fitted = fitting.fit(base)
    # x scale: |x0 - x1| / 2.0 = 2: the offset 0.1 along x becomes 0.2.
    np.testing.assert_allclose(fitted[0], [0.5 * 0 + 0.25 * 4 + 0.2, 0.25 * 2.0, -0.1])
    np.testing.assert_allclose(fitted[1], base[3])


@pytest.mark.unit
def test_a_fitting_file_without_vertices_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "empty.mhclo"
    path.write_text("name empty\nobj_file empty.obj\n", encoding="utf-8")
    with pytest.raises(AssetFormatError, match=r"empty\.mhclo: no fitted vertices"):
        read_fitting(path)


@pytest.mark.unit
def test_a_bvh_frame_composes_each_joints_channels_in_the_order_written(tmp_path: Path) -> None:
    path = tmp_path / "pose.bvh"
    path.write_text(
        "HIERARCHY\nROOT root\n{\n OFFSET 0 0 1\n CHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation "
        "Zrotation\n JOINT arm\n {\n  OFFSET 1 0 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n"
        "   OFFSET 1 0 0\n  }\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.04\n0 0 2 0 0 0 90 0 0\n",
        encoding="utf-8",
    )
    pose = read_bvh(path)
    assert set(pose.rotations) == {"root", "arm"}
    np.testing.assert_allclose(pose.root_position, [0.0, 0.0, 2.0])
    np.testing.assert_allclose(pose.rotations["arm"], axis_rotation("z", 90.0), atol=1e-12)
    with pytest.raises(AssetFormatError, match="frame 3 of 1"):
        read_bvh(path, frame=3)


@pytest.mark.unit
def test_skinning_turns_a_child_bone_about_its_own_head() -> None:
    rig = Rig(names=("root", "arm"), parents=np.array([-1, 0]))
    heads_rest = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    rot, head = rig.pose(heads_rest, {"arm": axis_rotation("z", 90.0)})
    vertices = np.array([[2.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.5, 0.0, 0.0]])
    ids = np.array([[1, 0], [0, 1], [1, 0]])
    weights = np.array([[1.0, 0.0], [1.0, 0.0], [0.5, 0.5]])
    posed = skin(vertices, ids, weights, heads_rest, rot, head)
    np.testing.assert_allclose(posed[0], [1.0, 1.0, 0.0], atol=1e-12)  # turned 90 degrees about the arm's head
    np.testing.assert_allclose(posed[1], [0.5, 0.0, 0.0], atol=1e-12)  # the root's vertex stays
    np.testing.assert_allclose(posed[2], [1.25, 0.25, 0.0], atol=1e-12)  # half and half: linear blend


# -- the packed library --------------------------------------------------------------------------------------------
@pytest.mark.unit
def test_the_shipped_library_is_whole_and_small() -> None:
    assert PACK_PATH.stat().st_size < 2_000_000
    lib = load_library()
    n_base = len(lib.base_vertices)
    kinds = {p.kind for p in lib.parts}
    assert kinds == set(PartKind)
    for part in lib.parts:
        assert part.fitting.refs.max() < n_base, part.name
        assert part.faces.max() < len(part.fitting.refs), part.name
        np.testing.assert_allclose(part.bone_weights.sum(axis=1), 1.0, atol=2e-3, err_msg=part.name)
        assert part.bone_ids.max() < len(lib.rig.names)
    assert len(lib.parts_of(PartKind.SUIT, "female")) >= 4
    assert len(lib.parts_of(PartKind.SUIT, "male")) >= 6
    assert {"standing01", "sit01"} <= set(lib.poses)
    assert len(lib.macro_targets) == 12


@pytest.mark.unit
@pytest.mark.skipif(not ASSETS.is_dir(), reason="the MakeHuman asset tree (../shared/assets/makehuman) is not here")
def test_packing_the_assets_again_gives_the_shipped_library(tmp_path: Path) -> None:
    out = pack(ASSETS, tmp_path / "bodies.npz")
    with np.load(out) as fresh, np.load(PACK_PATH) as shipped:
        assert sorted(fresh.files) == sorted(shipped.files)
        for name in fresh.files:
            # The same library, not the same bytes: floats computed from the assets may take other SIMD paths on
            # another CPU (issue 65), so they agree to a few units in the last place; everything else exactly.
            if np.issubdtype(fresh[name].dtype, np.floating):
                np.testing.assert_allclose(fresh[name], shipped[name], rtol=1e-5, atol=1e-6, err_msg=name)
            else:
                np.testing.assert_array_equal(fresh[name], shipped[name], err_msg=name)


# -- figures -------------------------------------------------------------------------------------------------------
def _figure(seed: int, sitting: bool = False, height_m: float = 1.75) -> Figure:
    return draw_figure(np.random.default_rng(seed), height_m, sitting=sitting)


@pytest.mark.unit
def test_the_same_stream_draws_the_same_person() -> None:
    assert _figure(5) == _figure(5)
    assert len({_figure(s) for s in range(20)}) == 20


@pytest.mark.unit
@pytest.mark.parametrize("seed", range(6))
def test_a_standing_person_has_their_height_feet_on_the_ground_and_a_head_on_top(seed: int) -> None:
    figure = _figure(seed, height_m=1.7)
    mesh = figure_mesh(figure)
    top = mesh.vertices_m[:, 2].max()
    assert mesh.vertices_m[:, 2].min() == pytest.approx(0.0, abs=1e-9)
    assert 1.45 < top < 1.85  # 1.7 m standing, a pose may bend a little; hair and hats add some
    assert 0.82 * top < mesh.head_height_m < 0.97 * top
    # The head is above the origin, and the body stays within a person's reach of it.
    assert np.hypot(mesh.vertices_m[:, 0], mesh.vertices_m[:, 1]).max() < 1.2
    assert mesh.faces.max() < len(mesh.vertices_m)
    assert 400 < len(mesh.faces) < 2500  # the frame budget: ~880 triangles a person


@pytest.mark.unit
def test_a_sitting_person_keeps_their_head_low() -> None:
    sitting = figure_mesh(_figure(3, sitting=True))
    standing = figure_mesh(_figure(3))
    assert sitting.head_height_m < 0.6 * standing.head_height_m


@pytest.mark.unit
def test_a_coarser_level_is_drawn_only_where_its_cell_is_at_most_two_pixels() -> None:
    assert detail_level(0.03) == 0  # the lowest a mission looks from
    assert detail_level(DETAIL_CELLS_M[1] / MAX_CELL_PX - 1e-6) == 0
    assert detail_level(DETAIL_CELLS_M[1] / MAX_CELL_PX) == 1
    for m_per_px in (0.01, 0.045, 0.0625, 0.09, 0.5):
        level = detail_level(m_per_px)
        assert level == 0 or DETAIL_CELLS_M[level] <= MAX_CELL_PX * m_per_px
        assert level == len(DETAIL_CELLS_M) - 1 or DETAIL_CELLS_M[level + 1] > MAX_CELL_PX * m_per_px


@pytest.mark.unit
@pytest.mark.parametrize(("seed", "sitting", "walk_phase"), [(4, False, None), (5, True, None), (6, False, 0.375)])
def test_the_coarse_level_is_the_same_person_in_fewer_triangles(
    seed: int, sitting: bool, walk_phase: float | None
) -> None:
    figure = _figure(seed, sitting=sitting)
    fine = figure_mesh(figure, walk_phase=walk_phase)
    coarse = figure_mesh(figure, walk_phase=walk_phase, detail=1)
    assert len(coarse.faces) < 0.7 * len(fine.faces)
    assert coarse.faces.max() < len(coarse.vertices_m)
    # The same head over the same floor; the body within a cell of where the fine one reaches.
    assert coarse.head_height_m == pytest.approx(fine.head_height_m, abs=1e-9)
    cell_m = DETAIL_CELLS_M[1]
    assert coarse.vertices_m[:, 2].min() >= -1e-9
    assert coarse.vertices_m[:, 2].min() < cell_m
    np.testing.assert_array_less(fine.vertices_m.min(axis=0) - 1e-9, coarse.vertices_m.min(axis=0))
    np.testing.assert_array_less(coarse.vertices_m.max(axis=0), fine.vertices_m.max(axis=0) + 1e-9)
    np.testing.assert_array_less(coarse.vertices_m.min(axis=0), fine.vertices_m.min(axis=0) + cell_m)
    # Each kept vertex is one of the fine mesh's with its own colour: a garment's colour is never the skin under it.
    fine_rows = {tuple(np.round(v, 9)) + tuple(c) for v, c in zip(fine.vertices_m, fine.colours_rgba, strict=True)}
    for v, c in zip(coarse.vertices_m, coarse.colours_rgba, strict=True):
        assert tuple(np.round(v, 9)) + tuple(c) in fine_rows
    # The clothes stay the clothes: each colour covers about the share of the body seen from above it covered.
    for rgb in {figure.top_rgb, figure.bottom_rgb, figure.skin_rgb}:
        assert abs(_share_from_above(coarse, rgb) - _share_from_above(fine, rgb)) < 0.1


def _share_from_above(mesh: FigureMesh, rgb: tuple[int, int, int]) -> float:
    """Share of the mesh's area seen from straight above (triangles' ground-projected areas) coloured ``rgb``
    within the shading jitter (a triangle takes its first corner's colour)."""
    corners = mesh.vertices_m[mesh.faces][:, :, :2]
    edges = corners[:, 1:] - corners[:, :1]
    area = 0.5 * np.abs(edges[:, 0, 0] * edges[:, 1, 1] - edges[:, 0, 1] * edges[:, 1, 0])
    colour = mesh.colours_rgba[mesh.faces[:, 0], :3].astype(float)
    near = np.abs(colour - np.array(rgb)).max(axis=1) < 0.1 * max(rgb) + 3
    return float(area[near].sum() / area.sum())


@pytest.mark.unit
def test_a_walk_steps_its_legs_through_the_cycle_on_one_topology() -> None:
    figure = _figure(2)
    a = figure_mesh(figure, walk_phase=0.25)
    b = figure_mesh(figure, walk_phase=0.75)
    np.testing.assert_array_equal(a.faces, b.faces)
    low_a = a.vertices_m[a.vertices_m[:, 2] < 0.3]  # feet and ankles
    low_b = b.vertices_m[b.vertices_m[:, 2] < 0.3]
    # A quarter and three quarters through the cycle the feet are apart along the walk (north), the other way round.
    spread_a = np.ptp(low_a[:, 1])
    assert spread_a > 0.3
    assert np.ptp(low_b[:, 1]) > 0.3
    assert not np.allclose(a.vertices_m, b.vertices_m)
    assert walk_phase_at(0.0, 1.7) == 0.0
    assert walk_phase_at(0.8 * 1.7 * 0.5, 1.7) == pytest.approx(0.5)


@pytest.mark.unit
def test_clothing_from_above_is_mostly_muted() -> None:
    rng = np.random.default_rng(0)
    tops = [draw_figure(rng, 1.7, bright_share=0.25).top_rgb for _ in range(400)]

    def muted(rgb: tuple[int, int, int]) -> bool:
        return min(math.dist(rgb, m) for m in MUTED_RGB) < 40

    share = np.mean([muted(t) for t in tops])
    assert 0.65 < share < 0.85  # 75 % muted by design, a few bright ones may fall near a muted colour


# -- rendering -----------------------------------------------------------------------------------------------------
CAMERA = PinholeCamera.from_hfov(320, 240, 90.0)
NADIR = T_body_camera_from_mount()
POSE = Pose.from_ned_euler(1.0, -2.0, -14.0, 0.04, -0.03, 0.6)  # 8.8 cm per pixel below: the coarse level
LOW_POSE = Pose.from_ned_euler(1.0, -2.0, -6.0, 0.04, -0.03, 0.6)  # 3.8 cm per pixel: the fine level


def _world(seed: int, moving_fraction: float = 0.0, people: PeopleModel = PeopleModel.MAKEHUMAN) -> WorldRenderer:
    config = ScenarioConfig(moving_fraction=moving_fraction, people=people, walker=WalkerKind.PERSISTENT)
    return WorldRenderer(Park(seed), Crowd(config, seed), CAMERA, NADIR, Light.from_angles(50.0, 120.0, 0.45))


@pytest.mark.integration
def test_makehuman_people_stand_where_procedural_people_stood_and_their_heads_are_labelled_on_them() -> None:
    procedural, makehuman = _world(31, people=PeopleModel.PROCEDURAL), _world(31)
    try:
        np.testing.assert_array_equal(procedural.crowd.positions_ne_m, makehuman.crowd.positions_ne_m)
        assert procedural.figures is None
        assert makehuman.figures is not None
        view = makehuman.render(POSE, 0.0)
        assert 0.003 < view.person_mask.mean() < 0.2
        hits, checked = 0, 0
        for (u_px, v_px), front in zip(*makehuman.head_pixels(POSE), strict=True):
            u, v = round(u_px), round(v_px)
            if not front or not (3 <= u < 317 and 3 <= v < 237):
                continue
            checked += 1
            hits += bool(view.person_mask[v - 1 : v + 2, u - 1 : u + 2].any())
        assert checked > 30
        assert hits / checked > 0.85  # some heads are under tree crowns or another person's arm
    finally:
        procedural.close()
        makehuman.close()


@pytest.mark.integration
def test_the_same_seed_draws_the_same_pixels_cached_or_not() -> None:
    first = _world(32, moving_fraction=0.3)
    poses = (POSE, LOW_POSE, POSE)  # people at the coarse level, the fine one, the coarse one again
    assert [first.detail_at(p) for p in poses] == [1, 0, 1]
    try:
        frames_first = [first.render(pose, t) for pose, t in zip(poses, (0.0, 1.0, 2.5), strict=True)]
    finally:
        first.close()
    for cache in (
        camera_module.PERSON_MESHES,
        camera_module.SHADOW_MESHES,
        camera_module.WALK_MESHES,
        camera_module.LIT_GROUNDS,
        camera_module.OBJECT_MESHES,
    ):
        cache.clear()
    again = _world(32, moving_fraction=0.3)
    warm = _world(32, moving_fraction=0.3)  # built from the caches the second world filled
    try:
        for pose, t, expected in zip(poses, (0.0, 1.0, 2.5), frames_first, strict=True):
            for world in (again, warm):
                view = world.render(pose, t)
                np.testing.assert_array_equal(view.image_bgr, expected.image_bgr)
                np.testing.assert_array_equal(view.person_mask, expected.person_mask)
        # Walkers walked: the frames differ in time.
        assert not np.array_equal(frames_first[0].image_bgr, frames_first[2].image_bgr)
    finally:
        again.close()
        warm.close()


@pytest.mark.unit
def test_crowd_figures_follow_the_crowds_heights_and_sitters() -> None:
    crowd = Crowd(ScenarioConfig(people=PeopleModel.MAKEHUMAN), 33)
    figures = crowd_figures(crowd)
    assert figures is not None
    assert len(figures) == len(crowd)
    for a, f in zip(crowd.appearances, figures, strict=True):
        assert f.height_m == a.height_m
        assert (f.pose == "sit01") == ("sitting" in a.body.value)
    assert crowd_figures(Crowd(ScenarioConfig(people=PeopleModel.PROCEDURAL), 33)) is None  # the option


@pytest.mark.unit
def test_a_scenario_names_the_people_field_when_its_value_is_unknown() -> None:
    with pytest.raises(ValueError, match="people"):
        ScenarioConfig(people="clay")  # type: ignore[arg-type]


@pytest.mark.integration
def test_the_training_data_draws_makehuman_people_with_their_heads_labelled(tmp_path: Path) -> None:
    from models.data.generate import Split, generate

    written = generate(tmp_path, Split.TRAIN, frames=2, width_px=320, height_px=240, people=PeopleModel.MAKEHUMAN)
    assert sum(f.heads for f in written) > 5
    procedural = generate(tmp_path / "p", Split.TRAIN, frames=2, width_px=320, height_px=240)
    # The same scenes: as many people in view, the heads found at each body's own height.
    assert [f.people_in_view for f in written] == [f.people_in_view for f in procedural]
    image = (tmp_path / "train" / "000000.png").read_bytes()
    assert image != (tmp_path / "p" / "train" / "000000.png").read_bytes()
