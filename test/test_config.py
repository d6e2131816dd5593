"""ROS 2 style parameter files."""

from dataclasses import asdict

import pytest

from swarm_ros.app.param_file import load_params_file
from swarm_ros.core.errors import ConfigError
from swarm_ros.core.params import Settings
from swarm_ros.core.resources import data_dir

pytestmark = pytest.mark.unit


def test_shipped_parameter_file_holds_exactly_the_defaults():
    import yaml

    from swarm_ros.core.params import RUN_PARAMETERS

    path = data_dir("config") / "swarm_ros.yaml"
    assert load_params_file(path, Settings(shape="other")) == Settings()
    keys = list(yaml.safe_load(path.read_text())["/**"]["ros__parameters"])
    assert sorted(keys) == sorted(p.name for p in RUN_PARAMETERS), "every run parameter, each once"


def test_the_shipped_file_with_the_other_algorithm_is_taken(tmp_path):
    """Its study's-model parameters at their defaults do not stand in the way of algorithm: rubenstein."""
    from swarm_ros.app.param_file import read_params_file

    text = (data_dir("config") / "swarm_ros.yaml").read_text()
    assert "    algorithm: darr-niazi" in text
    path = tmp_path / "p.yaml"
    path.write_text(text.replace("    algorithm: darr-niazi", "    algorithm: rubenstein"))
    settings, _ = read_params_file(path)
    shape, params = settings.resolve()
    assert params.algorithm == "rubenstein" and params.robots == shape.patches


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


def _uncommented(tmp_path):
    """The shipped file with every node section's `# ` removed, as its comment tells a user to."""
    text = (data_dir("config") / "swarm_ros.yaml").read_text()
    head, sections = text[: text.index("# /world:")], text[text.index("# /world:") :]
    path = tmp_path / "uncommented.yaml"
    path.write_text(head + "\n".join(line[2:] for line in sections.splitlines()) + "\n")
    return path


def test_node_sections_of_the_shipped_file_hold_every_node_default(tmp_path):
    import yaml

    from swarm_ros.app.param_file import SECTIONS, read_params_file
    from swarm_ros.core.params import node_defaults

    text = (data_dir("config") / "swarm_ros.yaml").read_text()
    assert set(yaml.safe_load(text)) == {"/**"}, "a node section in force would shadow a node's -p arguments"
    data = yaml.safe_load(_uncommented(tmp_path).read_text())
    assert set(data) == {"/**", *(f"/{kind}" for kind in SECTIONS)}
    for kind in SECTIONS:
        assert data[f"/{kind}"]["ros__parameters"] == node_defaults(kind)
    settings, nodes = read_params_file(_uncommented(tmp_path))  # every section, uncommented, loads
    assert settings == Settings() and all(nodes[kind] == node_defaults(kind) for kind in SECTIONS)


def test_the_shipped_file_uncommented_is_taken_by_simulate_and_the_launch(tmp_path):
    """What the file's comment tells a user to do works in every command that reads it (test_ros_graph.py runs
    it under swarm-ros run)."""
    from swarm_ros.app import cli
    from swarm_ros.app.supervision import launch_setup
    from swarm_ros.core.params import RUN_PARAMETERS

    path = _uncommented(tmp_path)
    out = tmp_path / "sim"
    assert cli.main(["simulate", "--params-file", str(path), "--max-ticks", "3", "--quiet", "--out", str(out)]) == 0
    assert (out / "summary.json").is_file()
    setup = launch_setup(str(path), {p.name: "" for p in RUN_PARAMETERS}, str(tmp_path / "l"), tmp_path / "log", 2)
    assert setup.out == tmp_path / "l"


@pytest.mark.parametrize(
    "text,message",
    [
        ("/foo:\n  ros__parameters:\n    robots: 500\n", "unknown section '/foo' (a parameter file may hold '/**', "),
        ("/robot_batch_0:\n  ros__parameters:\n    seed: 9\n", "gives every robot batch the '/robot_batch' section"),
        ("/world_shard_0:\n  ros__parameters:\n    tick_rate: 5\n", "every world shard takes '/world'"),
        ("/world_shard:\n  ros__parameters:\n    shard: 1\n", "unknown section '/world_shard'"),
        ("3:\n  ros__parameters:\n    seed: 9\n", "unknown section '3'"),
        ("/world:\n  ros__parameters:\n    out_dir: x\n", "in '/world' (it may hold: monitor_window, start_timeout"),
        ("/**:\n  ros__parameters:\n    tick_rate: 5\n", "'tick_rate' in '/**': it is a node parameter, for /world"),
        ("/**:\n  ros__parameters:\n    record_every: 5\n", "node parameter, for /world or /monitor"),
    ],
)
def test_a_section_no_node_reads_or_a_key_its_node_lacks_is_refused(tmp_path, text, message):
    """A section of no node would be ignored, or taken as /**: both changed a run silently."""
    path = tmp_path / "p.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_params_file(path)
    assert message in str(info.value) and "\n" not in str(info.value)


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
