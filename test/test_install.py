"""The package as colcon builds it: the install space has what `ros2 run` and `ros2 launch` look for, and
the installed nodes run a swarm to its end from there.

The sources are copied and built with the real colcon (``colcon build``, from
``.venv-colcon``, which scripts/setup.sh makes) in a temporary workspace, then used
from another directory with only the paths a sourced workspace sets (AMENT_PREFIX_PATH,
PYTHONPATH) telling them where the install is.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from graph_runs import assert_same_run
from ros2_tools import build_workspace
from runs import shape_file

from swarm_ros.app import cli
from swarm_ros.app.param_file import params_yaml
from swarm_ros.core.params import Settings

pytestmark = pytest.mark.process

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def prefix(tmp_path_factory) -> Path:
    """The package's prefix in a colcon install space (install/swarm_ros), built from a tree whose kernels' cache
    is filled, as scripts/setup.sh leaves it."""
    filled = subprocess.run([sys.executable, "-m", "swarm_ros.core.kernels"], cwd=ROOT, capture_output=True, text=True)
    assert filled.returncode == 0, filled.stderr
    install = build_workspace(tmp_path_factory.mktemp("ws"))
    assert (install / "setup.sh").is_file() and (install / "local_setup.bash").is_file()
    return install / "swarm_ros"


def _installed_env(prefix: Path, home: Path) -> dict[str, str]:
    """What sourcing install/setup.sh sets for this package (its hooks: AMENT_PREFIX_PATH, PYTHONPATH)."""
    site = next(prefix.glob("lib/python3*/site-packages"))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "AMENT_PREFIX_PATH")}
    hooks = (prefix / "share" / "swarm_ros" / "hook").iterdir()
    assert {"ament_prefix_path.dsv", "pythonpath.dsv"} <= {h.name for h in hooks}
    return {
        **env,
        "PYTHONPATH": str(site),
        "AMENT_PREFIX_PATH": str(prefix),
        "HOME": str(home),
        "ROS_LOG_DIR": str(home / "ros"),
        "PYTHONUNBUFFERED": "1",
    }


def test_node_scripts_and_data_land_where_ros2_run_and_the_ament_index_look(prefix):
    for exe in ("world", "robot_batch", "monitor", "swarm-ros"):
        assert os.access(prefix / "lib" / "swarm_ros" / exe, os.X_OK), exe
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "swarm_ros").is_file()
    share = prefix / "share" / "swarm_ros"
    assert (share / "package.xml").is_file() and (share / "config" / "swarm_ros.yaml").is_file()
    assert (share / "config" / "fastdds.xml").is_file() and (share / "config" / "experiments" / "paper.yaml").is_file()
    assert (share / "launch" / "swarm.launch.py").is_file() and (share / "rviz" / "swarm.rviz").is_file()
    assert sorted(p.stem for p in (share / "shapes").glob("*.txt")) == sorted(
        p.stem for p in (ROOT / "shapes").glob("*.txt")
    )


def test_installed_nodes_run_a_swarm_to_its_end_from_the_install_space(prefix, tmp_path):
    shape = shape_file(tmp_path / "ring.txt", outer=12.5, hole=5)
    flags = ["--shape", str(shape), "--world-radius", "16", "--seed", "3", "--robots", "430"]
    ref = tmp_path / "ref"
    assert cli.main(["simulate", *flags, "--out", str(ref), "--quiet"]) == 0
    run = tmp_path / "run"
    params = tmp_path / "params.yaml"
    params.write_text(
        params_yaml(Settings(shape=str(shape), robots=430, seed=3, world_radius=16), {"monitor": {"out_dir": str(run)}})
    )
    env = {
        **_installed_env(prefix, tmp_path),
        "ROS_DOMAIN_ID": str(150 + os.getpid() % 50),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "FASTRTPS_DEFAULT_PROFILES_FILE": str(prefix / "share" / "swarm_ros" / "config" / "fastdds.xml"),
    }
    # the install holds the cache setup.sh filled (setup.py's package_data): nothing to compile again
    warm = subprocess.run(
        [sys.executable, "-m", "swarm_ros.core.kernels"], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert warm.returncode == 0, warm.stderr
    assert warm.stdout.count("numba kernels are compiled and cached") == 2, warm.stdout  # both algorithms'
    procs = {}
    try:
        for name, extra in (("monitor", []), ("robot_batch", ["-p", "batch:=0", "-p", "batches:=1"]), ("world", [])):
            # what `ros2 run swarm_ros <name>` runs: the install's script, with this machine's Python
            exe = prefix / "lib" / "swarm_ros" / name
            procs[name] = subprocess.Popen(
                [sys.executable, str(exe), "--ros-args", "--params-file", str(params), *extra],
                cwd=tmp_path,
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
        outputs = {name: p.communicate(timeout=120)[0] for name, p in procs.items()}
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()
    assert {name: p.returncode for name, p in procs.items()} == dict.fromkeys(procs, 0), outputs
    assert re.search(r"the run ended at tick \d+: complete", outputs["world"]), outputs["world"]
    compiled = [
        int(n)
        for n in re.findall(
            r"ready, [\d.]+ s after the process started \([\d.]+ s of CPU, (\d+) kernels compiled\)",
            "".join(outputs.values()),
        )
    ]
    assert compiled == [0, 0, 0], outputs  # each loaded the install's cache (numba's own count of what it compiled)
    assert_same_run(ref, run, launched=False)


def test_installed_copy_finds_its_shapes_and_config_through_the_ament_prefix(prefix, tmp_path):
    site = next(prefix.glob("lib/python3*/site-packages"))
    env = {**os.environ, "PYTHONPATH": str(site), "AMENT_PREFIX_PATH": str(prefix)}
    code = (
        "import swarm_ros; from swarm_ros.core.resources import data_dir; "
        "print(swarm_ros.__file__); print(data_dir('shapes')); print(data_dir('config'))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    module, shapes, config = done.stdout.split()
    assert module.startswith(str(site)), "the installed copy, not the source tree, must be imported"
    assert shapes == str(prefix / "share" / "swarm_ros" / "shapes")
    assert config == str(prefix / "share" / "swarm_ros" / "config")
    # the script colcon installed, run by this machine's Python (its shebang is `/usr/bin/env python3`: setup.cfg)
    listed = subprocess.run(
        [sys.executable, str(prefix / "lib" / "swarm_ros" / "swarm-ros"), "shapes"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert listed.returncode == 0, listed.stderr
    assert "star" in listed.stdout and str(prefix / "share" / "swarm_ros" / "shapes" / "star.txt") in listed.stdout


def test_editable_install_reads_the_source_tree():
    from swarm_ros.core.resources import data_dir

    assert data_dir("shapes") == ROOT / "shapes"
    assert data_dir("config") == ROOT / "config"
