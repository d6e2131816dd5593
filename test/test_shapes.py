"""Shape files: the six built-ins, the text and PNG loaders, centring and validation errors."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from PIL import Image
from runs import STUDY_PATCHES, disc_shape
from scipy import ndimage

from swarm_ros.core import Shape, ShapeError, World, builtin_shapes
from swarm_ros.core.shapes import read_text_grid, regions, write_text_grid

pytestmark = pytest.mark.unit

BUILTINS = sorted(STUDY_PATCHES)


def test_the_six_builtin_shapes_ship():
    assert sorted(builtin_shapes()) == BUILTINS


@pytest.mark.parametrize("name", BUILTINS)
def test_builtin_patch_counts_are_within_3_percent_of_the_study(name):
    shape = Shape.load(name)
    assert abs(shape.patches - STUDY_PATCHES[name]) <= 0.03 * STUDY_PATCHES[name]


@pytest.mark.parametrize("name", BUILTINS)
def test_builtin_shapes_fit_inside_the_walls_of_the_default_world(name):
    shape = Shape.load(name)
    x0, y0, x1, y1 = shape.bbox
    assert -30 <= x0 <= x1 <= 30 and -30 <= y0 <= y1 <= 30
    assert not (shape.mask & World().wall_mask()).any()


@pytest.mark.parametrize("name,holes", [("tyre", 1), ("spinner", 4), ("star", 0), ("rectangle", 0)])
def test_tyre_and_spinner_have_holes(name, holes):
    assert Shape.load(name).holes == holes


@pytest.mark.parametrize("name", BUILTINS)
def test_seed_block_is_the_2x2_block_of_shape_patches_nearest_the_origin(name):
    shape = Shape.load(name)
    seeds = shape.seed_patches
    x0, y0 = seeds[0]
    assert seeds.tolist() == [[x0, y0], [x0 + 1, y0], [x0, y0 + 1], [x0 + 1, y0 + 1]]
    r = shape.world.radius
    assert shape.mask[seeds[:, 1] + r, seeds[:, 0] + r].all()
    # brute force: no full 2x2 block has its centre nearer the origin
    best = min(
        (2 * x + 1) ** 2 + (2 * y + 1) ** 2
        for y in range(-r, r)
        for x in range(-r, r)
        if shape.mask[y + r : y + r + 2, x + r : x + r + 2].all()
    )
    assert (2 * x0 + 1) ** 2 + (2 * y0 + 1) ** 2 == best


def test_tyre_seeds_stand_on_the_ring_not_in_the_hole():
    shape = Shape.load("tyre")
    assert not shape.mask[32, 32]  # the origin is in the hole
    assert np.hypot(*shape.seed_patches.T).min() > 5


def test_text_grid_round_trip(tmp_path):
    grid = np.array([[0, 1, 1], [1, 1, 0], [1, 1, 0]], dtype=bool)
    path = tmp_path / "s.txt"
    write_text_grid(grid, path, comments=["a comment"])
    assert path.read_text().startswith("; a comment\n")
    assert np.array_equal(read_text_grid(path), grid)


@pytest.mark.parametrize(
    "w,h,expected_x,expected_y",
    [
        (3, 3, (-1, 1), (-1, 1)),  # odd sizes: centre cell on the origin
        (4, 4, (-1, 2), (-1, 2)),  # even sizes: extra column right, extra row up
        (5, 2, (-2, 2), (0, 1)),
    ],
)
def test_grid_centre_lands_on_the_origin(w, h, expected_x, expected_y):
    world = World(radius=8)
    grid = np.ones((h, w), dtype=bool)
    grid[0, :] = True
    # a full rectangle needs a 2x2 block; use h >= 2, w >= 2
    shape = Shape.from_grid(grid, world, name="t", source="t")
    x0, y0, x1, y1 = shape.bbox
    assert (x0, x1) == expected_x and (y0, y1) == expected_y


def test_top_row_of_the_file_is_the_top_of_the_world(tmp_path):
    path = tmp_path / "l.txt"
    path.write_text("##.\n##.\n###\n")
    shape = Shape.load(path, World(radius=6))
    r = 6
    assert shape.mask[1 + r, 1 + r] == False  # noqa: E712  top-right cell of the file is free
    assert shape.mask[-1 + r, 1 + r] == True  # noqa: E712  bottom-right is shape


def test_png_and_text_give_the_same_shape(tmp_path):
    text = Shape.load("wrench")
    rows = Path(text.source).read_text().splitlines()
    grid = np.array([[c == "#" for c in line] for line in rows if not line.startswith(";")])
    pixels = np.where(grid, 0, 255).astype(np.uint8)
    png = tmp_path / "wrench.png"
    Image.fromarray(pixels, mode="L").save(png)
    assert np.array_equal(Shape.load(png).mask, text.mask)


def test_png_transparent_pixels_are_not_shape(tmp_path):
    rgba = np.zeros((6, 6, 4), dtype=np.uint8)  # black everywhere
    rgba[..., 3] = 0
    rgba[1:5, 1:5, 3] = 255  # opaque only in the middle
    path = tmp_path / "a.png"
    Image.fromarray(rgba, mode="RGBA").save(path)
    assert Shape.load(path, World(radius=6)).patches == 16


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text) if isinstance(text, str) else path.write_bytes(text)
    return path


BAD_FILES = [
    ("empty.txt", "; nothing here\n\n", "empty shape file"),
    ("dots.txt", "....\n....\n", "empty shape"),
    ("stray.txt", "##x\n###\n", "unexpected character 'x'"),
    ("ragged.txt", "###\n##\n", "row has 2 columns"),
    ("gap.txt", "##\n\n##\n", "blank line inside the grid"),
    ("two.txt", "##...\n##...\n.....\n...##\n...##\n", "2 separate parts"),
    ("thin.txt", "#.#\n.#.\n#.#\n", "no 2 x 2 block"),
    ("binary.txt", b"\xff\xfe\x00\x01", "not UTF-8"),
    ("broken.png", b"\x89PNG\r\n\x1a\n garbage", "cannot read shape image"),
]


@pytest.mark.parametrize("name,content,message", BAD_FILES, ids=[b[0] for b in BAD_FILES])
def test_bad_shape_files_get_an_error_naming_the_file(tmp_path, name, content, message):
    path = _write(tmp_path, name, content)
    with pytest.raises(ShapeError) as info:
        Shape.load(path, World(radius=8))
    text = str(info.value)
    assert message in text and str(path) in text and "\n" not in text


def test_shape_touching_the_wall_is_rejected(tmp_path):
    world = World(radius=4)
    path = _write(tmp_path, "big.txt", "\n".join(["#" * 7] * 7) + "\n")  # reaches |x| = 3 = R - 1
    with pytest.raises(ShapeError, match="touches the wall"):
        Shape.load(path, world)


def test_shape_beyond_the_world_is_rejected(tmp_path):
    path = _write(tmp_path, "huge.txt", "\n".join(["#" * 12] * 12) + "\n")
    with pytest.raises(ShapeError, match="beyond the walls"):
        Shape.load(path, World(radius=4))


def test_unknown_name_lists_the_builtins():
    with pytest.raises(ShapeError, match="no such shape file or built-in shape.*star"):
        Shape.load("no-such-shape")


def test_disc_helper_builds_a_valid_shape():
    shape = disc_shape(World(radius=10), 4.0)
    assert shape.patches == 49 and shape.holes == 0


def test_a_text_grid_may_start_with_a_utf8_byte_order_mark(tmp_path):
    plain, marked = tmp_path / "plain.txt", tmp_path / "marked.txt"
    grid = "......\n.####.\n.####.\n......\n"
    plain.write_text(grid, encoding="utf-8")
    marked.write_bytes(b"\xef\xbb\xbf" + grid.encode())
    world = World(5)
    assert np.array_equal(Shape.load(str(marked), world).mask, Shape.load(str(plain), world).mask)


def test_a_directory_given_as_a_shape_is_named_as_such(tmp_path):
    with pytest.raises(ShapeError, match="is a directory, not a shape file"):
        Shape.load(str(tmp_path), World())


@settings(max_examples=200, deadline=None)
@given(arrays(bool, st.tuples(st.integers(1, 24), st.integers(1, 24))), st.sampled_from([4, 8]))
def test_regions_label_grids_as_scipy_ndimage_does(mask, connectivity):
    """cc3d replaced ndimage.label (for its import time): the same regions, up to the labels' numbering."""
    structure = np.ones((3, 3), bool) if connectivity == 8 else None
    want, want_count = ndimage.label(mask, structure=structure)
    got, count = regions(mask, connectivity)
    assert count == want_count
    assert np.array_equal(got == 0, want == 0)
    pairs = {(int(a), int(b)) for a, b in zip(got[mask], want[mask])}
    assert len(pairs) == count  # one ndimage label per cc3d label, and the other way round


# -- shape_scale: an integer upscale of a 2D shape --------------------------------------------------------------------


@pytest.mark.parametrize("name", ["rectangle", "tyre"])
def test_shape_scale_makes_each_pixel_a_block_and_keeps_the_holes(name):
    """Each patch becomes a k x k block of patches, placed by the same centring rule; the hole count stays."""
    one, three = Shape.load(name), Shape.load(name, World(100), scale=3)
    assert three.patches == 9 * one.patches and three.scale == 3 and one.scale == 1
    assert three.label == f"{name}-x3" and one.label == name
    assert regions(~three.mask, 4)[1] == regions(~one.mask, 4)[1]  # the same number of holes (and outside)
    block = np.ones((3, 3), dtype=bool)  # the scaled grid is the file's grid with each pixel a block, re-centred
    x0, y0, x1, y1 = one.bbox
    r1, r3 = one.world.radius, three.world.radius
    small = one.mask[y0 + r1 : y1 + r1 + 1, x0 + r1 : x1 + r1 + 1]
    sx0, sy0, sx1, sy1 = three.bbox
    assert np.array_equal(three.mask[sy0 + r3 : sy1 + r3 + 1, sx0 + r3 : sx1 + r3 + 1], np.kron(small, block))


def test_a_3x3_square_at_scale_2_is_the_6x6_square(tmp_path):
    (tmp_path / "s3.txt").write_text("###\n" * 3)
    (tmp_path / "s6.txt").write_text("######\n" * 6)
    scaled, six = Shape.load(tmp_path / "s3.txt", scale=2), Shape.load(tmp_path / "s6.txt")
    assert np.array_equal(scaled.mask, six.mask) and np.array_equal(scaled.seed_patches, six.seed_patches)


def test_shape_scale_is_refused_where_it_cannot_apply(tmp_path):
    with pytest.raises(ShapeError, match=r"^torus: shape_scale applies to 2D shapes only, got 2 for a 3D grid$"):
        Shape.load("torus", scale=2)
    mesh = tmp_path / "m.stl"
    mesh.write_text("solid m\nendsolid m\n")  # refused before it is read
    with pytest.raises(ShapeError, match=r"shape_scale applies to 2D shapes only, got 2; a mesh scales with --mesh"):
        Shape.load(mesh, scale=2)
    with pytest.raises(ShapeError, match=r"the grid is 183 x 183 at shape_scale 3 \(--world-radius 81 or more holds"):
        Shape.load("star", scale=3)
    assert Shape.load("star", World(81), scale=3).patches == 9 * Shape.load("star").patches  # the radius it named
