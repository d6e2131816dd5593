"""ROS 2 style parameter files."""

from dataclasses import asdict

import pytest

from swarm_ros.app.param_file import load_params_file
from swarm_ros.core.errors import ConfigError
from swarm_ros.core.params import Settings
from swarm_ros.core.resources import data_dir

pytestmark = pytest.mark.unit


def test_shipped_parameter_file_holds_exactly_the_defaults():
    assert load_params_file(data_dir("config") / "swarm_ros.yaml", Settings(shape="other")) == Settings()


def test_sections_apply_in_order_and_override_the_base(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text(
        "/**:\n  ros__parameters:\n    robots: 500\n    vision_radius: 2\n'**':\n  ros__parameters:\n    robots: 600\n"
    )  # two spellings of every node
    s = load_params_file(path, Settings(seed=9))
    assert asdict(s) == {**asdict(Settings()), "robots": 600, "vision_radius": 2.0, "seed": 9}


@pytest.mark.parametrize("node", ["world", "robot_batch", "monitor"])
def test_a_run_parameter_in_a_node_section_is_refused(tmp_path, node):
    """Nodes that read different run parameters would not run the same swarm: run parameters go in /**."""
    path = tmp_path / "p.yaml"
    path.write_text(f"/**:\n  ros__parameters:\n    robots: 500\n/{node}:\n  ros__parameters:\n    seed: 3\n")
    with pytest.raises(ConfigError, match=f"'/{node}' sets the run parameter 'seed'; run parameters go in '/\\*\\*'"):
        load_params_file(path)


@pytest.mark.parametrize(
    "text,message",
    [
        ("/**:\n  ros__parameters:\n    robtos: 5\n", "unknown parameter 'robtos'"),
        ("/**:\n  ros__parameters:\n    robots: many\n", "robots must be an integer"),
        ("/**:\n  ros__parameters:\n    robots: 5.5\n", "robots must be an integer"),
        ("/**:\n  ros__parameters:\n    vision_radius: true\n", "vision_radius must be a number"),
        ("/**:\n  ros__parameters:\n    shape: 3\n", "shape must be a string"),
        ("robots: 5\n", "section 'robots' must hold exactly one 'ros__parameters'"),
        ("", "expected '/node_name: ros__parameters"),
        ("/**: [unclosed\n", "not valid YAML"),
    ],
)
def test_bad_parameter_files_name_the_file_and_the_key(tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_params_file(path)
    assert message in str(info.value) and str(path) in str(info.value)


def test_missing_parameter_file(tmp_path):
    with pytest.raises(ConfigError, match="no such parameter file"):
        load_params_file(tmp_path / "nope.yaml")


def test_node_sections_of_the_shipped_file_hold_every_node_default():
    import yaml

    from swarm_ros.core.params import NODE_PARAMETERS, node_defaults

    text = (data_dir("config") / "swarm_ros.yaml").read_text()
    # the node sections are commented out (a node's own section outranks -p): uncommented, they are the defaults
    sections = text[text.index("# /world:") :]
    uncommented = "\n".join(line[2:] for line in sections.splitlines())
    data = yaml.safe_load(uncommented)
    for node in NODE_PARAMETERS:  # a world shard's nodes are named world_shard_<i>
        name = "world_shard_0" if node == "world_shard" else node
        assert data[f"/{name}"]["ros__parameters"] == node_defaults(node)
    assert set(yaml.safe_load(text)) == {"/**"}, "a node section in force would shadow a node's -p arguments"


@pytest.mark.parametrize(
    "text,message",
    [
        ("/world:\n  ros__parameters:\n    monitor_window: fast\n", "monitor_window must be an integer"),
        ("/monitor:\n  ros__parameters:\n    overwrite: 1\n", "overwrite must be a boolean"),
        ("/**:\n  ros__parameters:\n    out_dir: x\n", "unknown parameter 'out_dir'"),
    ],
)
def test_node_sections_are_checked_too(tmp_path, text, message):
    path = tmp_path / "p.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_params_file(path)
