"""Installed copies find their shapes and configs, and the node scripts land where `ros2 run` looks.

A normal install is made the way colcon builds an ament_python package
(``setup.py install`` into a prefix, which setup.cfg points at lib/swarm_ros) from a
copy of the sources, then used from another directory with only AMENT_PREFIX_PATH
telling it where the prefix is, as a sourced ROS 2 workspace does.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SOURCES = ("setup.py", "setup.cfg", "package.xml", "pyproject.toml", "resource", "swarm_ros", "shapes", "config")


@pytest.fixture(scope="module")
def prefix(tmp_path_factory) -> Path:
    src, prefix = tmp_path_factory.mktemp("src"), tmp_path_factory.mktemp("install")
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(path, src / name)
    done = subprocess.run([sys.executable, "setup.py", "-q", "install", "--single-version-externally-managed",
                           "--root", "/", "--prefix", str(prefix), "--record", str(src / "files.txt")],
                          cwd=src, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return prefix


def test_node_scripts_and_data_land_where_ros2_run_and_the_ament_index_look(prefix):
    for exe in ("world", "robot_batch", "monitor", "swarm-ros"):
        assert os.access(prefix / "lib" / "swarm_ros" / exe, os.X_OK), exe
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "swarm_ros").is_file()
    share = prefix / "share" / "swarm_ros"
    assert (share / "package.xml").is_file() and (share / "config" / "swarm_ros.yaml").is_file()
    assert (share / "config" / "experiments" / "paper.yaml").is_file()
    assert sorted(p.stem for p in (share / "shapes").glob("*.txt")) == \
        sorted(p.stem for p in (ROOT / "shapes").glob("*.txt"))


def test_installed_copy_finds_its_shapes_and_config_through_the_ament_prefix(prefix, tmp_path):
    site = next(prefix.glob("lib/python3*/site-packages"))
    env = {**os.environ, "PYTHONPATH": str(site), "AMENT_PREFIX_PATH": str(prefix)}
    code = ("import swarm_ros; from swarm_ros.core.resources import data_dir; "
            "print(swarm_ros.__file__); print(data_dir('shapes')); print(data_dir('config'))")
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    module, shapes, config = done.stdout.split()
    assert module.startswith(str(site)), "the installed copy, not the source tree, must be imported"
    assert shapes == str(prefix / "share" / "swarm_ros" / "shapes")
    assert config == str(prefix / "share" / "swarm_ros" / "config")
    listed = subprocess.run([str(prefix / "lib" / "swarm_ros" / "swarm-ros"), "shapes"], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=60)
    assert listed.returncode == 0, listed.stderr
    assert "star" in listed.stdout and str(prefix / "share" / "swarm_ros" / "shapes" / "star.txt") in listed.stdout


def test_editable_install_reads_the_source_tree():
    from swarm_ros.core.resources import data_dir

    assert data_dir("shapes") == ROOT / "shapes"
    assert data_dir("config") == ROOT / "config"
