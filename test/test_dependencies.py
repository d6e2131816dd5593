"""One dependency list: what the package imports is what it declares, and what it declares is pinned.

setup.py's ``install_requires`` is the list (``extras_require['test']`` for the tests), package.xml names the
ROS 2 packages colcon and rosdep resolve, and requirements.txt is the lock: the exact versions
scripts/setup.sh installs. An import the list does not name works here, where the lock installed it, and
fails for a user who installs the package with pip; these tests find it first.
"""

from __future__ import annotations

import ast
import re
import sys
import xml.etree.ElementTree as ET
from importlib.metadata import packages_distributions
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]


def _name(requirement: str) -> str:
    """A requirement's distribution name, normalized (PEP 503)."""
    return re.sub(r"[-_.]+", "-", re.match(r"[A-Za-z0-9_.-]+", requirement).group(0)).lower()


def _setup_keyword(keyword: str):
    tree = ast.parse((ROOT / "setup.py").read_text())
    call = next(n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "setup")
    return ast.literal_eval(next(k.value for k in call.keywords if k.arg == keyword))


def _declared() -> set[str]:
    return {_name(r) for r in _setup_keyword("install_requires")}


def _ros_packages() -> set[str]:
    root = ET.parse(ROOT / "package.xml").getroot()
    return {e.text.strip() for e in root if e.tag in ("depend", "exec_depend")}


def _imported() -> dict[str, set[str]]:
    """Top-level module -> files of the package importing it (lazy imports in functions included): its Python
    package and its launch file, which colcon installs beside it."""
    found: dict[str, set[str]] = {}
    for path in [*sorted((ROOT / "swarm_ros").rglob("*.py")), *sorted((ROOT / "launch").glob("*.py"))]:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module]
                if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module
                else []
            )
            for name in names:
                found.setdefault(name.split(".")[0], set()).add(str(path.relative_to(ROOT)))
    return found


def test_every_module_the_package_imports_is_declared():
    """Standard library, the package itself, a ROS 2 package named in package.xml, or a distribution named in
    setup.py's install_requires."""
    dists = packages_distributions()
    ros = _ros_packages()
    declared = _declared()
    missing = []
    for module, files in sorted(_imported().items()):
        if module in sys.stdlib_module_names or module in ("swarm_ros", "__future__") or module in ros:
            continue
        owners = {_name(d) for d in dists.get(module, [])}
        if not owners & declared:
            missing.append(f"{module} ({', '.join(sorted(owners)) or 'not installed'}; {', '.join(sorted(files))})")
    assert not missing, "imported but not in setup.py's install_requires: " + "; ".join(missing)


def test_every_declared_distribution_is_pinned_in_the_lock():
    pinned = {}
    for line in (ROOT / "requirements.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            assert "==" in line, f"requirements.txt pins exact versions, got '{line}'"
            pinned[_name(line)] = line
    wanted = _declared() | {_name(r) for r in _setup_keyword("extras_require")["test"]}
    assert not wanted - pinned.keys(), f"declared in setup.py, not pinned in requirements.txt: {wanted - pinned.keys()}"


def test_the_launch_files_imports_are_among_what_is_checked():
    """launch_ros is imported by the launch file only: the check reads launch/ too."""
    assert _imported()["launch_ros"] == {"launch/swarm.launch.py"}


def test_the_check_finds_an_undeclared_import(tmp_path, monkeypatch):
    """The first test is not vacuous: a declaration list without numba fails it."""
    monkeypatch.setattr(
        sys.modules[__name__], "_declared", lambda: {_name(r) for r in _setup_keyword("install_requires")} - {"numba"}
    )
    with pytest.raises(AssertionError, match="numba"):
        test_every_module_the_package_imports_is_declared()
