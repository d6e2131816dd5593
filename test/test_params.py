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
