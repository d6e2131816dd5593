"""The package's layers import one way only: core <- protocol <- artifacts <- ros <- nodes, tools <- app.

docs/architecture.md draws the layers and says what each one holds. A module may import
modules of its own package and of lower layers, never of its own layer's other package or
of a higher one: a newcomer then finds a concern in one place, and the core and the
protocol run (and are tested) without rclpy.
"""

from __future__ import annotations

import pytest
from layering import layer_of, module_graph

pytestmark = pytest.mark.unit


def wrong_way(graph: dict[str, set[str]]) -> list[str]:
    """Every import from a module to one of its own layer's other package or of a higher layer."""
    found = []
    for module, imports in sorted(graph.items()):
        package, rank = layer_of(module)
        for target in sorted(imports):
            other, other_rank = layer_of(target)
            if other != package and other_rank >= rank:
                found.append(f"{module} -> {target}")
    return found


def test_every_module_lives_in_a_layer():
    top = ("swarm_ros", "swarm_ros.__main__")
    stray = [m for m in module_graph() if layer_of(m)[0] == "swarm_ros" and m not in top]
    assert stray == []


def test_imports_point_down_the_layers_only():
    graph = module_graph()
    assert "swarm_ros.core.params" in graph["swarm_ros.nodes.central.world"]  # sees imports
    assert wrong_way(graph) == []


def test_the_check_finds_an_import_pointing_up_or_sideways():
    assert wrong_way({"swarm_ros.core.a": {"swarm_ros.protocol.b"}}) == ["swarm_ros.core.a -> swarm_ros.protocol.b"]
    assert wrong_way({"swarm_ros.nodes.a": {"swarm_ros.tools.b"}}) == ["swarm_ros.nodes.a -> swarm_ros.tools.b"]
    assert wrong_way({"swarm_ros.app.a": {"swarm_ros.core.b", "swarm_ros.app.c"}}) == []


def test_no_two_modules_share_a_file_name_or_shadow_the_standard_library():
    """A name within its layer's folder is unique across the layers: ``checks`` is one module, ``rubenstein.checks``
    (an algorithm's folder in a layer) another."""
    import sys

    names: dict[str, list[str]] = {}
    modules = module_graph()
    packages = {m.rsplit(".", 1)[0] for m in modules}
    for module in modules:
        within = ".".join(module.split(".")[2:])  # the name below the layer
        if within and within != "__main__" and module not in packages:
            names.setdefault(within, []).append(module)
    assert {k: v for k, v in names.items() if len(v) > 1} == {}
    assert sorted({n.split(".")[0] for n in names} & set(sys.stdlib_module_names)) == []


#: Modules past the line cap because one concept needs the room, and why: a module is split by concept, never to
#: fit the cap (the study's earlier world lockstep was five base classes that redeclared each other's fields and
#: methods).
PAST_THE_CAP = {
    "core/darr_niazi/engine.py": "the study's run: one state (arrays, counts, metrics rows) that every path advances: "
    "in process, from batches, as a world shard",
}


def test_node_files_stay_thin_and_modules_small():
    """A node file routes callbacks into plain classes (at most 300 lines); no module passes 450 but those that name
    their one concept in PAST_THE_CAP, each of them past it."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "swarm_ros"
    sizes = {str(p.relative_to(root)): len(p.read_text().splitlines()) for p in root.rglob("*.py")}
    past = {p for p, n in sizes.items() if n > (300 if p.startswith("nodes/") else 450)}
    assert past == set(PAST_THE_CAP), "a module past the cap names its one concept here; one back under it leaves"


def test_a_test_module_imports_nothing_from_another_test_module():
    """What tests share is in modules by topic (runs.py, graph_runs.py, waiting.py, ...): a test module's private
    helper imported elsewhere breaks when that module changes, and loads its tests' fixtures twice."""
    import ast
    from pathlib import Path

    found = []
    for path in sorted(Path(__file__).parent.glob("test_*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            found += [f"{path.name}: {name}" for name in names if name.split(".")[0].startswith("test_")]
    assert not found, found
