"""The run's parameters are declared once, as the fields of :class:`Settings` (swarm_ros.core.params): the table
every other place reads (RUN_PARAMETERS) is those fields, and RunParams, the model's resolved parameters, has
exactly the fields declared ``model``: the same declarations, inherited. Both are plain dataclasses that an editor
and a type checker can see, and that pickle by name (to experiment workers)."""

from __future__ import annotations

import dataclasses
import pickle

import pytest

from swarm_ros.core.errors import ParameterError
from swarm_ros.core.params import RUN_PARAMETER, RUN_PARAMETERS, RunParams, Settings

pytestmark = pytest.mark.unit


def test_the_table_of_run_parameters_is_the_settings_fields():
    fields = dataclasses.fields(Settings)
    assert [p.name for p in RUN_PARAMETERS] == [f.name for f in fields]
    for f in fields:
        p = RUN_PARAMETER[f.name]
        assert f.default == p.default and f.type == p.kind.__name__, f.name


def test_run_params_has_the_model_parameters_with_their_types_and_defaults():
    model = [p for p in RUN_PARAMETERS if p.model]
    fields = dataclasses.fields(RunParams)
    assert [f.name for f in fields] == [p.name for p in model]  # robots first, as declared
    for f, p in zip(fields, model):
        assert f.type == p.kind.__name__ and f.default == p.default, f.name  # the same declaration
    with pytest.raises(ParameterError, match="^robots must be an integer >= 4, got 0$"):  # resolved, or refused
        RunParams()


def test_settings_and_run_params_pickle_by_name_and_compare_equal():
    settings = Settings(shape="tyre", seed=5, rules="local")
    assert pickle.loads(pickle.dumps(settings)) == settings
    params = RunParams(robots=50, seed=3, vision_radius=2.0)
    assert pickle.loads(pickle.dumps(params)) == params
    assert type(settings).__module__ == type(params).__module__ == "swarm_ros.core.params"


def test_shape_scale_reaches_the_shape_every_engine_and_summary_takes():
    """Settings.resolve (what simulate, every node and an experiment's runs derive the run from) reads the shape at
    ``shape_scale``; both algorithms' summaries say it, only where it is not 1."""
    from swarm_ros.core.algorithm import algorithm_of

    for algorithm, robots in (("darr-niazi", 0), ("rubenstein", 60)):
        shape, params = Settings(
            shape="rectangle", shape_scale=2, world_radius=60, robots=robots, algorithm=algorithm, max_ticks=3
        ).resolve()
        assert shape.scale == 2 and shape.patches == 4 * 442
        assert params.robots == (4 * 442 if robots == 0 else robots)
        entry = algorithm_of(algorithm)
        run = entry.hook("engine")(shape, params)
        run.run()
        assert entry.hook("summary")(run, wall_seconds=0.0)["shape_scale"] == 2
        plain = Settings(shape="rectangle", robots=60, algorithm=algorithm, max_ticks=3).resolve()
        run = entry.hook("engine")(*plain)
        run.run()
        assert "shape_scale" not in entry.hook("summary")(run, wall_seconds=0.0)


def test_an_experiment_files_shape_scale_scales_every_shape_and_reaches_every_run(tmp_path):
    """``shape_scale`` is one value for a whole experiment: its shapes' patch counts ("patches" group sizes) are the
    scaled shapes', and each run (in-process here; a graph run takes the same settings) runs the scaled shape."""
    import yaml

    from swarm_ros.app.executors import run_inprocess
    from swarm_ros.app.experiment_file import load_experiment

    config = tmp_path / "scaled.yaml"
    data = {
        "name": "scaled",
        "seed": 1,
        "repetitions": 1,
        "vision_radius": 1,
        "shape_scale": 2,
        "world_radius": 60,
        "max_ticks": 2,
        "shapes": {"rectangle": ["patches"]},
    }
    config.write_text(yaml.safe_dump(data))
    (run,) = load_experiment(config).runs()
    assert run.shape_scale == 2 and run.settings.robots == 4 * 442
    assert run_inprocess(run)["shape_patches"] == 4 * 442
