"""Fuzzing (hypothesis) of what reads user files: shape images and bytes, parameter files, experiment files.

Any input either loads or gets a InputError whose message is one line naming the file;
never another exception. (Text shape grids are fuzzed in test_properties.py.)
"""

from __future__ import annotations

import io

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from swarm_ros.app.experiment_file import Experiment, load_experiment
from swarm_ros.app.param_file import load_params_file
from swarm_ros.core.errors import InputError
from swarm_ros.core.grid import World
from swarm_ros.core.params import Settings
from swarm_ros.core.shapes import Shape

pytestmark = pytest.mark.unit

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-(10**6), 10**6), st.floats(allow_nan=True), st.text(max_size=12)
)
keys = st.one_of(
    st.sampled_from(
        [
            "shape",
            "robots",
            "vision_radius",
            "seed",
            "max_ticks",
            "wiggle_deg",
            "world_radius",
            "ros__parameters",
            "/**",
            "/world",
            "/monitor",
            "name",
            "repetitions",
            "shapes",
            "star",
            "rectangle",
            "out_dir",
            "record_every",
        ]
    ),
    st.text(max_size=8),
)
documents = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(keys, inner, max_size=5)),
    max_leaves=12,
)


def _one_line_naming(exc: InputError, path) -> None:
    text = str(exc)
    assert "\n" not in text and str(path) in text, text


@FUZZ
@given(st.binary(max_size=300))
def test_png_loader_on_random_bytes(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("png") / "s.png"
    path.write_bytes(data)
    try:
        Shape.load(path, World(radius=8))
    except InputError as exc:
        _one_line_naming(exc, path)


@FUZZ
@given(st.integers(1, 20), st.integers(1, 20), st.integers(0, 2**32 - 1), st.sampled_from(["L", "RGB", "RGBA", "1"]))
def test_png_loader_on_random_images(tmp_path_factory, w, h, seed, mode):
    rng = np.random.default_rng(seed)
    channels = {"L": 1, "RGB": 3, "RGBA": 4, "1": 1}[mode]
    pixels = (rng.random((h, w, channels)) < 0.5).astype(np.uint8) * 255
    image = Image.fromarray(pixels[:, :, 0] if channels == 1 else pixels, "L" if channels == 1 else mode)
    path = tmp_path_factory.mktemp("png") / "s.png"
    image.convert(mode).save(path)
    try:
        shape = Shape.load(path, World(radius=8))
    except InputError as exc:
        _one_line_naming(exc, path)
    else:
        assert shape.patches >= 4


def _accepts_or_names(loader, tmp_path_factory, text: str, ok_type: type) -> None:
    path = tmp_path_factory.mktemp("cfg") / "f.yaml"
    path.write_text(text)
    try:
        result = loader(path)
    except InputError as exc:
        _one_line_naming(exc, path)
    else:
        assert isinstance(result, ok_type)


@FUZZ
@given(documents)
def test_parameter_file_parser_on_random_documents(tmp_path_factory, doc):
    _accepts_or_names(load_params_file, tmp_path_factory, yaml.safe_dump(doc), Settings)


@FUZZ
@given(
    st.dictionaries(
        st.sampled_from(["/**", "/world", "/monitor", "/robot_batch", "x"]),
        st.fixed_dictionaries({"ros__parameters": st.dictionaries(keys, scalars, max_size=4)}),
        max_size=3,
    )
)
def test_parameter_file_parser_on_near_valid_documents(tmp_path_factory, doc):
    _accepts_or_names(load_params_file, tmp_path_factory, yaml.safe_dump(doc), Settings)


@FUZZ
@given(st.text(max_size=200))
def test_parameter_file_parser_on_random_text(tmp_path_factory, text):
    _accepts_or_names(load_params_file, tmp_path_factory, text, Settings)


@FUZZ
@given(
    st.fixed_dictionaries(
        {"seed": scalars, "repetitions": scalars, "vision_radius": st.one_of(scalars, st.lists(scalars, max_size=3))},
        optional={
            "shapes": st.one_of(
                documents,
                st.dictionaries(
                    st.sampled_from(["rectangle", "star", "nope", "x.txt"]),
                    st.lists(st.one_of(st.integers(-5, 2000), st.just("patches"), scalars), max_size=3),
                    max_size=2,
                ),
            ),
            "max_ticks": scalars,
            "name": scalars,
            "extra": scalars,
        },
    )
)
def test_experiment_parser_on_random_documents(tmp_path_factory, doc):
    text = io.StringIO()
    yaml.safe_dump(doc, text)
    _accepts_or_names(load_experiment, tmp_path_factory, text.getvalue(), Experiment)
