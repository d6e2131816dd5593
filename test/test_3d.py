"""The model in three dimensions: the voxel world, 3D shapes (built in, layered text, meshes), the 3D rule,
the engines' agreement and the Z-spec invariants in 3D (docs/model.md, "Three dimensions")."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from runs import run_checked, run_in_batches

from swarm_ros.core import RunParams, Shape, ShapeError, Simulation, World
from swarm_ros.core.darr_niazi.invariants import nearest_frontier_patch
from swarm_ros.core.darr_niazi.legality import illegal
from swarm_ros.core.darr_niazi.rules3d import direction, nearest_frontier3, random_direction, wiggled
from swarm_ros.core.darr_niazi.state import FRONTIER_BLOCK, FRONTIER_SUPER, RobotState, frontier_blocks_of, near_any
from swarm_ros.core.darr_niazi.swarm_view import SwarmView
from swarm_ros.core.errors import ContractError, ParameterError
from swarm_ros.core.shapes import builtin_shapes_3d, read_text_grid, write_text_grid

pytestmark = pytest.mark.unit

BUILTINS_3D = ["box", "jack", "k-block", "pyramid", "shell", "torus"]
RULES = ["paper", "local", "literal"]


def _blob(world: World, radius: float, hole: float = -1.0) -> Shape:
    """A ball (a shell, with ``hole`` >= 0) of voxels centred on the origin."""
    c = np.arange(-world.radius, world.radius + 1)
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    d = np.sqrt(x * x + y * y + z * z)
    return Shape(name="blob", mask=(d <= radius) & (d > hole), world=World(world.radius, 3), source="test blob")


# -- the world ---------------------------------------------------------------------------------------------
def test_a_3d_world_is_a_cube_walled_on_its_outer_shell():
    w = World(4, 3)
    wall = w.wall_mask()
    assert wall.shape == (9, 9, 9) and w.patch_count == 729
    assert wall.sum() == 9**3 - 7**3
    assert not wall[1:-1, 1:-1, 1:-1].any()


def test_flat_indices_and_coordinates_are_inverse_and_a_2d_world_is_the_bottom_layer_order():
    w3 = World(5, 3)
    flat = np.arange(w3.patch_count)
    x, y, z = w3.patch_coords(flat)
    assert np.array_equal(w3.flat_of(x, y, z), flat)
    assert (x.min(), x.max(), z.min(), z.max()) == (-5, 5, -5, 5)
    w2 = World(5)
    assert np.array_equal(w2.flat_of(*w2.patch_coords(np.arange(121))), np.arange(121))
    assert np.array_equal(w2.flat_of(x[:121], y[:121]), flat[:121])


@pytest.mark.parametrize("dims,count", [(2, 8), (3, 26)])
def test_neighbour_offsets_are_the_8_or_26_around_a_patch(dims, count):
    w = World(4, dims)
    offsets = w.neighbour_offsets()
    centre = w.flat_of(*([0] * dims))
    around = np.stack(w.patch_coords(centre + offsets), axis=1)
    assert offsets.size == count and 0 not in offsets
    assert np.abs(around).max() == 1 and len({tuple(p) for p in around}) == count


def test_the_3d_dilation_equals_scipys():
    from scipy.ndimage import binary_dilation

    grid = np.random.default_rng(2).random((9, 10, 11)) < 0.05
    assert np.array_equal(near_any(grid), binary_dilation(grid, structure=np.ones((3, 3, 3), dtype=bool)))


def test_frontier_blocks_count_the_frontier_per_cube_of_voxels():
    size, b, s = 141, FRONTIER_BLOCK, FRONTIER_SUPER
    frontier = np.random.default_rng(3).random(size**3) < 0.1
    blocks = frontier_blocks_of(frontier, size, 3)
    nb, ns = -(-size // b), -(-size // (b * s))
    z, y, x = np.unravel_index(np.flatnonzero(frontier), (size,) * 3)
    expect = np.bincount(((z // b) * nb + y // b) * nb + x // b, minlength=nb**3)
    supers = np.bincount(((z // (b * s)) * ns + y // (b * s)) * ns + x // (b * s), minlength=ns**3)
    assert ns == 3 and blocks.size == nb**3 + ns**3 + 1
    assert np.array_equal(blocks[: nb**3], expect) and np.array_equal(blocks[nb**3 : -1], supers)
    assert blocks[-1] == frontier.sum()


# -- shapes ------------------------------------------------------------------------------------------------
def test_six_builtin_3d_shapes_ship_and_fit_the_default_world():
    assert sorted(builtin_shapes_3d()) == BUILTINS_3D
    for name in BUILTINS_3D:
        shape = Shape.load(name)
        assert shape.dims == 3 and shape.world == World(32, 3)
        assert 500 <= shape.patches <= 2000


def test_the_torus_has_a_tunnel_and_the_shell_a_cavity_and_the_solids_neither():
    topology = {name: (Shape.load(name).tunnels, Shape.load(name).cavities) for name in BUILTINS_3D}
    assert topology["torus"] == (1, 0)
    assert topology["shell"] == (0, 1)
    for name in ("box", "pyramid", "jack", "k-block"):
        assert topology[name] == (0, 0), name


def test_the_seeds_are_a_corner_of_four_voxels_nearest_the_origin():
    shape = Shape.load("box")
    seeds = shape.seed_patches
    assert seeds.shape == (4, 3)
    assert np.array_equal(seeds[1:] - seeds[0], np.eye(3, dtype=np.int64))  # +x, +y, +z from the corner
    flat = shape.world.flat_of(*seeds.T)
    assert shape.mask.ravel()[flat].all()
    assert np.abs(seeds[0] + 0.25).max() <= 1.0  # the box holds the origin's corner


def test_a_layered_text_grid_round_trips_and_places_the_top_layer_highest(tmp_path):
    grid = np.zeros((3, 4, 5), dtype=bool)
    grid[0, 0, 0] = True  # top layer, top row, first column: x = -2, y = 2 (of rows 4: (3 - 0) - 1), z = 1
    grid[:, 1:3, 1:4] = True
    path = tmp_path / "blocky.txt"
    write_text_grid(grid, path, comments=("a test",))
    assert "---" in path.read_text()
    assert np.array_equal(read_text_grid(path), grid)
    shape = Shape.load(path, World(6))
    assert shape.dims == 3 and shape.patches == grid.sum()
    assert shape.mask[1 + 6, 2 + 6, -2 + 6]  # [iz, iy, ix] of (x, y, z) = (-2, 2, 1)


@pytest.mark.parametrize(
    "text,error",
    [
        ("###\n###\n---\n##\n##\n", "layer 2 is 2 x 2, the first layer is 3 x 2"),
        ("#..\n...\n---\n...\n..#\n", r"separate parts \(26-connected\)"),
        ("##\n##\n---\n##\n#.\n", "no corner of four voxels"),
    ],
)
def test_bad_layered_grids_say_what_is_wrong_in_one_line(tmp_path, text, error):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(ShapeError, match=error) as info:
        Shape.load(path, World(6))
    assert "\n" not in str(info.value)


def test_a_3d_shape_must_keep_off_the_walls():
    with pytest.raises(ShapeError, match=r"touches the wall of the 11 x 11 x 11 world .*\|z\| <= 3"):
        _blob(World(5), 4.5)


def test_corner_only_contact_is_connected_in_3d():
    grid = np.zeros((2, 2, 4), dtype=bool)
    grid[1, 1, 0:2] = grid[1, 0, 0] = grid[0, 1, 0] = True  # a seed corner: [layer, row, col], top first
    grid[0, 0, 2:4] = True  # touches it at one corner only: 26-connected
    assert Shape.from_grid(grid, World(6), name="c", source="test").patches == 6


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    import trimesh

    d = tmp_path_factory.mktemp("meshes")
    trimesh.creation.torus(major_radius=8, minor_radius=3).export(d / "ring.stl")
    trimesh.creation.box(extents=(10, 8, 6)).export(d / "brick.obj")
    trimesh.creation.icosphere(subdivisions=2, radius=5).export(d / "ball.ply")
    open_box = trimesh.creation.box(extents=(10, 8, 6))
    open_box.update_faces(np.arange(1, len(open_box.faces)))
    open_box.export(d / "open.stl")
    (d / "junk.stl").write_text("not a mesh")
    return d


def test_meshes_voxelize_one_voxel_per_mesh_unit(meshes):
    ring = Shape.load(meshes / "ring.stl")
    assert (ring.dims, ring.tunnels, ring.cavities) == (3, 1, 0)
    assert ring.bbox == (-11, -11, -3, 11, 11, 3)  # ring radius 8 + tube 3, each side
    brick = Shape.load(meshes / "brick.obj")
    assert brick.bbox == (-5, -4, -3, 5, 4, 3)  # every voxel the surface passes through, and the inside
    assert brick.patches == 11 * 9 * 7
    assert Shape.load(meshes / "ball.ply").tunnels == 0


def test_mesh_scale_scales_the_voxelization(meshes):
    big = Shape.load(meshes / "brick.obj", mesh_scale=2.0)
    assert big.bbox == (-10, -8, -6, 10, 8, 6)
    assert big.mesh_scale == 2.0


@pytest.mark.parametrize(
    "name,scale,error",
    [
        ("open.stl", 1.0, r"the mesh does not close \(\d+ edges belong to one triangle only\)"),
        ("junk.stl", 1.0, "the mesh has no triangles|cannot read the mesh"),
        (
            "ring.stl",
            5.0,
            r"reaches beyond the walls of the 65 x 65 x 65 world .*\(at mesh_scale 5; --mesh-scale sets ",
        ),
        ("ring.stl", 10000.0, "lower mesh_scale"),
    ],
)
def test_bad_meshes_say_what_is_wrong_in_one_line(meshes, name, scale, error):
    with pytest.raises(ShapeError, match=error) as info:
        Shape.load(meshes / name, mesh_scale=scale)
    assert "\n" not in str(info.value)


def test_mesh_scale_makes_no_sense_for_a_grid_shape():
    with pytest.raises(ShapeError, match="mesh_scale applies to mesh shapes"):
        Shape.load("star", mesh_scale=2.0)
    with pytest.raises(ShapeError, match="mesh_scale applies to mesh shapes"):
        Shape.load("torus", mesh_scale=0.5)


def test_robots_beyond_the_free_voxels_are_refused():
    shape = _blob(World(4), 1.8)
    with pytest.raises(ParameterError, match="do not fit on the 343 free patches of the 9 x 9 x 9 world"):
        Simulation(shape, RunParams(robots=344))


# -- the rule ----------------------------------------------------------------------------------------------
def _angle(a, b) -> float:
    return math.acos(max(-1.0, min(1.0, sum(u * v for u, v in zip(a, b)))))


@settings(max_examples=300, deadline=None)
@given(
    h=st.floats(0, 2 * math.pi, exclude_max=True),
    p=st.floats(-math.pi / 2, math.pi / 2),
    w=st.floats(0, math.pi),
    u=st.floats(0, 1, exclude_max=True),
    v=st.floats(0, 1, exclude_max=True),
)
def test_a_wiggle_turns_the_heading_by_at_most_the_wiggle_angle(h, p, w, u, v):
    h2, p2 = wiggled(h, p, w, u, v)
    assert 0 <= h2 < 2 * math.pi and -math.pi / 2 <= p2 <= math.pi / 2
    assert _angle(direction(h, p), direction(h2, p2)) <= w + 1e-7  # acos near 1 loses half the digits


def test_a_wiggle_is_uniform_on_its_cap():
    """The cosine of the turn is uniform on [cos w, 1] (Archimedes: equal-height bands of a cap have
    equal area), and the direction it turns towards is uniform about the heading."""
    rng = np.random.default_rng(1)
    w, h, p = math.radians(45), 1.0, 0.3
    d = direction(h, p)
    turns = [_angle(d, direction(*wiggled(h, p, w, u, v))) for u, v in rng.random((4000, 2))]
    cosines = np.cos(turns)
    counts = np.histogram(cosines, bins=4, range=(math.cos(w), 1.0))[0]
    assert counts.min() > 0.85 * 1000 and counts.max() < 1.15 * 1000


def test_a_random_turn_is_uniform_on_the_sphere():
    rng = np.random.default_rng(2)
    z = np.array([direction(*random_direction(u, v))[2] for u, v in rng.random((4000, 2))])
    counts = np.histogram(z, bins=4, range=(-1, 1))[0]  # Archimedes again: z uniform in [-1, 1]
    assert counts.min() > 850 and counts.max() < 1150


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), density=st.floats(0.0005, 0.05), radius=st.sampled_from([12, 40]))
def test_the_block_search_finds_the_brute_force_nearest_frontier_voxel(seed, density, radius):
    world = World(radius, 3)  # 40: two super-blocks a side, the last one cut short
    rng = np.random.default_rng(seed)
    frontier = rng.random(world.patch_count) < density / (radius / 12) ** 3  # as many voxels: far ones too
    blocks = frontier_blocks_of(frontier, world.size, 3)
    for x, y, z in rng.uniform(-radius + 0.6, radius - 0.6, (20, 3)):
        assert nearest_frontier3(x, y, z, frontier, blocks, world.radius, world.size) == nearest_frontier_patch(
            frontier, x, y, world, z
        )


# -- runs --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("rules", RULES)
@pytest.mark.parametrize("name", ["torus", "shell", "jack"])
def test_every_invariant_holds_in_3d_under_every_rule_set(name, rules):
    shape = Shape.load(name, World(16))
    sim = run_checked(
        Simulation(
            shape,
            RunParams(
                robots=shape.patches + 30,
                seed=5,
                rules=rules,
                max_ticks=250,
                vision_radius=2.0,
                fail_fraction=0.05,
                fail_tick=120,
            ),
        )
    )
    assert sim.removed > 0 and sim.metrics.localized > 4


def test_a_small_ball_completes_and_separates_the_extras_with_every_invariant():
    shape = _blob(World(6), 2.5)
    sim = run_checked(Simulation(shape, RunParams(robots=shape.patches + 10, seed=2)))
    assert str(sim.outcome) == "complete_with_extras"
    assert (sim.state.state == RobotState.SEPARATED).sum() == 10


def test_the_paper_rules_complete_every_builtin_3d_shape():
    for name in BUILTINS_3D:
        shape = Shape.load(name)
        sim = Simulation(shape, RunParams(robots=shape.patches, seed=1))
        assert str(sim.run()) == "complete", name


def _final(sim: Simulation) -> tuple:
    s = sim.state
    return (
        sim.tick,
        str(sim.outcome),
        s.x.tobytes(),
        s.y.tobytes(),
        s.z.tobytes(),
        s.heading.tobytes(),
        s.pitch.tobytes(),
        s.state.tobytes(),
        s.occupancy.tobytes(),
        sim.history.tobytes(),
    )


@pytest.mark.parametrize("rules", RULES)
@pytest.mark.parametrize("batches", [1, 2, 4])
def test_batched_decide_and_apply_equal_the_fused_engine_in_3d(batches, rules):
    shape = Shape.load("k-block", World(14))
    p = RunParams(robots=shape.patches + 20, seed=7, vision_radius=1.5, rules=rules, max_ticks=1500)
    fused = Simulation(shape, p)
    fused.run()
    assert _final(run_in_batches(shape, p, batches, seed=batches)) == _final(fused)


def test_a_view_fed_the_changed_rows_equals_the_world_in_3d():
    shape = Shape.load("torus", World(16))
    sim = Simulation(shape, RunParams(robots=shape.patches, seed=3, max_ticks=400, fail_fraction=0.02, fail_tick=200))
    s = sim.state
    view = SwarmView(shape, s.robots)
    view.load(0, np.arange(s.robots), s.state, s.x, s.y, s.heading, s.z, s.pitch)
    while not sim.done:
        sim.step()
        ids = np.union1d(sim.last_joins()[0], sim.last_removed)
        view.update(sim.tick, ids, s.state[ids], s.x[ids], s.y[ids], s.heading[ids], s.z[ids], s.pitch[ids])
    r = view.state
    for name in ("x", "y", "z", "heading", "pitch", "state", "occupancy", "frontier", "frontier_blocks"):
        assert np.array_equal(getattr(r, name), getattr(s, name)), name


def test_a_3d_view_refuses_rows_without_z():
    shape = Shape.load("box", World(12))
    view = SwarmView(shape, 10)
    with pytest.raises(ContractError, match="need z and pitch"):
        view.load(0, np.arange(10), np.zeros(10, dtype=np.int8), np.zeros(10), np.zeros(10), np.zeros(10))


def test_the_legality_bounds_hold_for_3d_decisions_and_catch_a_jump_in_z():
    shape = Shape.load("box", World(12))
    p = RunParams(robots=shape.patches, seed=4)
    sim = Simulation(shape, p)
    for _ in range(30):
        before = sim.state.copy()
        sim.step()
        d = sim.last_decisions()
        ids = d.ids
        args = (p, 12, before.frontier, before.x[ids], before.y[ids], d.claim, d.x, d.y, d.heading)
        assert not illegal(*args, z0=before.z[ids], z=d.z, pitch=d.pitch).any()
    jumped = d.z + 2.5
    assert illegal(*args, z0=before.z[ids], z=jumped, pitch=d.pitch).all()
    tilted = np.full(ids.size, 2.0)
    assert illegal(*args, z0=before.z[ids], z=d.z, pitch=tilted).all()


@pytest.mark.parametrize("name", ["box", "k-block"])
def test_the_3d_final_png_legend_sits_below_every_view_and_no_label_is_cut(tmp_path, monkeypatch, name):
    import matplotlib.figure

    from swarm_ros.artifacts.darr_niazi.plots import save_final_png
    from swarm_ros.core.darr_niazi.run_result import RunRecord

    shape = Shape.load(name)
    sim = Simulation(shape, RunParams(robots=shape.patches, max_ticks=300))  # robots left all round the shape
    sim.run()
    saved = []
    real = matplotlib.figure.Figure.savefig
    monkeypatch.setattr(
        matplotlib.figure.Figure, "savefig", lambda fig, *a, **k: (saved.append(fig), real(fig, *a, **k))[1]
    )
    save_final_png(RunRecord.of(sim, wall_seconds=0.0), tmp_path / "final.png")
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = saved[0]
    canvas = FigureCanvasAgg(fig)
    canvas.draw()  # the constrained layout, as the saved file has it
    renderer = canvas.get_renderer()
    legend = fig.legends[0].get_window_extent(renderer)
    whole = fig.bbox
    for ax in fig.axes:
        box = ax.get_tightbbox(renderer)  # the axes with its ticks, labels and title
        assert legend.y1 <= box.y0, f"{ax.get_title() or ax.get_ylabel()}: the legend has no row of its own"
        assert not box.overlaps(fig._suptitle.get_window_extent(renderer)), ax.get_title() or ax.get_ylabel()
        assert whole.x0 <= box.x0 and box.x1 <= whole.x1 and whole.y0 <= box.y0 and box.y1 <= whole.y1, (
            f"{ax.get_title() or ax.get_ylabel()} is cut"
        )
