"""The benchmark scripts that issue targets are measured with still run and print what their docs quote."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.process

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"


def test_bench_scale_prints_each_engine_and_the_projection_on_k_hosts():
    """A tiny disc, K = 1 and 2, no recording: the table, the K ratios and a projection row per K whose
    projected tick is what it is built from: the world's CPU plus the slowest batch's plus the transport's,
    or the monitor's if longer."""
    done = subprocess.run([sys.executable, str(SCRIPTS / "bench_scale.py"), "--robots", "300", "--ticks", "5",
                           "--processes", "1", "2", "--bare", "--projection"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    out = done.stdout
    assert re.search(r"^in-process\s+\d", out, re.M), out
    for k in (1, 2):
        assert re.search(rf"^ROS 2 graph, K = {k}\s+\d.*world \d", out, re.M), out
    assert re.search(r"^K = 2 against K = 1: run time \d+\.\d\dx, .* largest CPU per tick of a process \d", out,
                     re.M), out
    rows = re.findall(r"^\s+300\s+(\d)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+"
                      r"([\d.]+)x$", out, re.M)
    assert [int(r[0]) for r in rows] == [1, 2], out
    for _, world, batch, monitor, transport, tick, sim_tick, ratio in rows:
        assert float(transport) > 0 and float(sim_tick) > 0
        # the printed figures are rounded to 0.1 ms
        assert float(tick) >= max(float(world) + float(batch) + float(transport), float(monitor)) - 0.2
        assert abs(float(ratio) - float(tick) / float(sim_tick)) <= 0.05 * float(ratio) + 0.1
