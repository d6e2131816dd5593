"""The core never imports ROS or Rerun: import it and run a tick with those modules blocked."""

import subprocess
import sys
import textwrap

BLOCKED = ["rclpy", "rerun", "std_msgs", "geometry_msgs", "nav_msgs", "rosgraph_msgs", "diagnostic_msgs",
           "sensor_msgs", "visualization_msgs", "builtin_interfaces", "rosidl_runtime_py"]


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
    code = ("import sys\nclass B:\n    def find_spec(self, n, p=None, t=None):\n"
            "        if n == 'json': raise ImportError('blocked')\nsys.modules.pop('json', None)\n"
            "sys.meta_path.insert(0, B())\nimport json\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode != 0 and "blocked" in result.stderr
