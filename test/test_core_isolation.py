"""The core never imports ROS or Rerun: import it and run a tick with those modules blocked."""

import subprocess
import sys
import textwrap

import pytest
from layering import module_graph

pytestmark = pytest.mark.process  # runs Python in subprocesses with modules blocked

BLOCKED = [
    "rclpy",
    "rerun",
    "std_msgs",
    "geometry_msgs",
    "nav_msgs",
    "rosgraph_msgs",
    "diagnostic_msgs",
    "sensor_msgs",
    "visualization_msgs",
    "builtin_interfaces",
    "rosidl_runtime_py",
]


def test_core_runs_with_ros_and_rerun_blocked():
    code = textwrap.dedent(f"""
        import sys
        BLOCKED = {BLOCKED!r}
        class Blocker:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in BLOCKED:
                    raise ImportError("blocked: " + name)
        sys.meta_path.insert(0, Blocker())
        import swarm_ros.core as core
        sim = core.Simulation(core.Shape.load("star"), core.RunParams(robots=300, max_ticks=5))
        sim.run()
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED)
        assert not loaded, loaded
        print("ok", sim.outcome)
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "ok timeout"


def test_blocker_really_blocks():
    code = (
        "import sys\nclass B:\n    def find_spec(self, n, p=None, t=None):\n"
        "        if n == 'json': raise ImportError('blocked')\nsys.modules.pop('json', None)\n"
        "sys.meta_path.insert(0, B())\nimport json\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode != 0 and "blocked" in result.stderr


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                cycles.append(sorted(part))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return cycles


def test_no_module_of_the_package_imports_itself_round_a_circle():
    graph = module_graph()
    assert (
        "swarm_ros.core.darr_niazi.run_result" in graph["swarm_ros.artifacts.darr_niazi.plots"]
    )  # the scan sees imports at all
    assert import_cycles(graph) == []


def test_the_cycle_finder_finds_a_circle():
    assert import_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []


def test_the_launcher_loads_none_of_the_nodes_heavy_libraries():
    """`swarm-ros run` starts its nodes sooner when it loads only what it needs: numba, scipy,
    matplotlib, Rerun and rosbags cost the launcher ~0.5 s of CPU on the 2 cores the nodes start on."""
    code = textwrap.dedent("""
        import sys
        import swarm_ros.app.cli, swarm_ros.app.launcher, swarm_ros.tools.progress, swarm_ros.ros.graph
        from swarm_ros.app.param_file import Settings
        shape, params = Settings(shape="star").resolve()
        heavy = ("numba", "scipy", "matplotlib", "rerun", "rosbags")
        print(sorted({m.split(".")[0] for m in sys.modules} & set(heavy)), shape.patches)
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["[]", "1036"]
