"""Measure two checkouts back to back, alternating, for the benches' ``--before DIR``.

Each measurement is a fresh process of the calling bench script (this tree's copy, so both trees are measured
by the same code), started from inside the tree it measures with that tree on ``PYTHONPATH``. It prints the path
of the ``swarm_ros`` it imported, then a JSON object of case -> rate; the path is checked against the tree, so a
tree can never be measured in place of the other (``python -m`` and a script's own directory both put another
``swarm_ros`` first on ``sys.path`` all too easily). Rounds alternate which tree goes first.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np


def child_report(rates: dict[str, float]) -> None:
    """What a measuring child prints: the ``swarm_ros`` it measured, then its rates."""
    import swarm_ros

    print(swarm_ros.__file__)
    print(json.dumps(rates))


def alternate(script: Path, args: list[str], trees: dict[str, Path], rounds: int) -> dict[str, list[dict]]:
    """Run ``script args`` (a bench in its measuring mode) ``rounds`` times in each of ``trees`` (name -> root),
    alternating; per tree, the rates of each round."""
    rates: dict[str, list[dict]] = {name: [] for name in trees}
    order = list(trees.items())
    for k in range(rounds):
        for name, tree in order if k % 2 == 0 else order[::-1]:
            done = subprocess.run(
                [sys.executable, str(script), *args],
                cwd=tree,
                env={**os.environ, "PYTHONPATH": str(tree)},
                capture_output=True,
                text=True,
            )
            if done.returncode:
                raise SystemExit(f"{script.name}: the {name} measurement failed:\n{done.stderr[-2000:]}")
            source, result = done.stdout.splitlines()[-2:]
            if not Path(source).resolve().is_relative_to(tree.resolve()):
                raise SystemExit(f"{script.name}: the {name} measurement imported {source}, not the tree {tree}")
            rates[name].append(json.loads(result))
            print(f"  round {k + 1} of {rounds}: {name} measured", file=sys.stderr, flush=True)
    return rates


def print_ratios(rates: dict[str, list[dict]], mine: str, theirs: str, unit: float = 1e6) -> None:
    """One line per case: each tree's median rate (in ``unit``) and the ratio ``mine`` / ``theirs``, median and
    range over the rounds (each round's two measurements paired)."""
    print(f"  {'case':<44} {mine:>10} {theirs:>10} {'ratio':>7}  range")
    for case in rates[mine][0]:
        new = [r[case] for r in rates[mine]]
        old = [r[case] for r in rates[theirs]]
        ratio = sorted(a / b for a, b in zip(new, old))
        print(
            f"  {case:<44} {np.median(new) / unit:10.2f} {np.median(old) / unit:10.2f} "
            f"{np.median(ratio):7.3f}  {ratio[0]:.3f}-{ratio[-1]:.3f}"
        )
