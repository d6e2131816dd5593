"""A third algorithm plugged in from a folder of the tests (test/random_walk, a random walk that stops next to a
stopped robot), with no edit to swarm_ros: one folder of at most 200 lines, and its robot batches, fed the central
world's messages, decide as its in-process engine does (its commands and graph runs: test_plugin_algorithm)."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

from swarm_ros.app import cli
from swarm_ros.core import Shape, World, algorithm
from swarm_ros.core.errors import Rejected
from swarm_ros.core.params import RunParams
from swarm_ros.core.strips import run_batched, strips_for
from swarm_ros.protocol.cdr import decode_cloud, encode_cloud
from swarm_ros.protocol.central_batch import CentralBatch
from swarm_ros.protocol.central_lockstep import CentralLockstep

pytestmark = pytest.mark.unit

FOLDER = Path(__file__).resolve().parent / "random_walk"
random_walk = None  #: the plug-in's module, imported (and registered) for this module's tests only


@pytest.fixture(scope="module", autouse=True)
def _registered():
    """The plug-in registered into a copy of the registry for this module's tests: the registry is global, and the
    other tests of this process see the built-in algorithms only."""
    global random_walk
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(algorithm, "_REGISTRY", dict(algorithm._REGISTRY))
        for module in ("random_walk", "random_walk.engine"):
            sys.modules.pop(module, None)
        random_walk = importlib.import_module("random_walk")
        yield


SHAPE = "#####\n" * 4  #: 20 cells in a world of 13 x 13


@pytest.fixture(scope="module")
def shape_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("walk") / "sq.txt"
    path.write_text(SHAPE)
    return path


@pytest.fixture
def shape(shape_file) -> Shape:
    return Shape.load(str(shape_file), World(6))


def params(**more) -> RunParams:
    return RunParams(40, algorithm=random_walk.NAME, seed=3, max_ticks=300, **more)


def test_the_plugin_is_one_folder_of_at_most_200_lines_that_swarm_ros_never_names():
    lines = sum(len(p.read_text().splitlines()) for p in FOLDER.glob("*.py"))
    assert lines <= 200, lines
    assert random_walk.NAME in algorithm.names() and algorithm.algorithm_of(random_walk.NAME).wire == "random_walk:Wire"
    package = Path(cli.__file__).parents[1]
    named = [p for p in package.rglob("*.py") if "random_walk" in p.read_text() or "random-walk" in p.read_text()]
    assert named == []


@pytest.mark.parametrize("batches", [1, 2, 3])
def test_k_batches_fed_the_worlds_messages_decide_as_the_in_process_engine(batches, shape):
    """The world's lockstep and the shared robot-batch host over the plug-in's rows, each batch sent only its area
    as the message the world sends: the run is the in-process one, tick for tick."""
    whole = random_walk.RandomWalk(shape, params())
    whole.run()
    split = random_walk.RandomWalk(shape, params())
    ls = CentralLockstep(split, random_walk.Wire)
    own = {"batches": batches, "region_cuts": ""}
    hosts = [
        CentralBatch(split.shape, split.params, {**own, "batch": k, "name": f"b{k}"}, None) for k in range(batches)
    ]
    for k, host in enumerate(hosts):
        ls.announce(f"b{k}", host.strip)
    assert ls.started and sum(len(ls.own(k)) for k in range(batches)) == 39
    while split.outcome is None:  # each batch's whole view at tick 0, then each tick's changes
        for k, (sent, entire) in ls.areas(list(range(batches)), set()).items():
            rows, tick = hosts[k].inboxes[0 if entire else 1].take(decode_cloud(encode_cloud(sent, split.tick)))
            ls.decisions(k, tick, rows)
    assert split.tick == whole.tick and np.array_equal(split.history, whole.history)
    assert all(np.array_equal(a, b) for a, b in zip(split.robots, whole.robots))
    assert whole.history[-1, 1] > 10  # robots stopped: decisions next to stopped robots across strips were made
    plain = random_walk.RandomWalk(shape, params())
    strips = strips_for(plain, 3)
    run_batched(plain, [random_walk.Batch(plain, strips, k) for k in range(3)])
    assert np.array_equal(plain.history, whole.history)


@pytest.mark.parametrize("shards, batches, seed, restarts", [(2, 2, 0, {}), (3, 3, 1, {21: 1}), (3, 4, 2, {})])
def test_world_shards_give_the_in_process_run(shards, batches, seed, restarts, shape):
    """The shared world-shard split (swarm_ros.core.central_shards) serves it as it is: each shard holds its columns
    and a halo, its messages delivered in a shuffled order, a shard restarted from its last save, and every shard's
    metrics, and each robot's row at its owner, are the one world's."""
    from swarm_ros.core.central_shards import run_sharded

    whole = random_walk.RandomWalk(shape, params())
    whole.run()
    make = lambda: random_walk.RandomWalk(shape, params())
    world = run_sharded(make, random_walk.Batch, shards, batches, seed=seed, restarts=restarts)
    assert all(np.array_equal(w.run.history, whole.history) for w in world) and whole.history[-1, 1] > 10
    assert all(np.array_equal(a[w.own], b[w.own]) for w in world for a, b in zip(w.run.robots, whole.robots))
    assert np.array_equal(np.sort(np.concatenate([w.own for w in world])), np.arange(40))


def test_a_shard_keeps_what_comes_early_ignores_repeats_and_refuses_the_rest(shape):
    from swarm_ros.core.central_shards import CentralExchange, CentralShard

    run = random_walk.RandomWalk(shape, params())
    strips = strips_for(run, 3)
    sent = []

    class Port:
        def __getattr__(self, name):
            return lambda *args: sent.append((name, args[0]))

    middle = CentralExchange(CentralShard(run, strips, 1, 3), Port())
    assert middle.neighbours == [0, 2] and middle.tick == 1
    no_rows = random_walk.Robots(*(np.empty(0, dtype=np.int64),) * 3)
    middle.border(0, 2, np.empty(0, dtype=np.int64), no_rows)  # the next tick's, early: kept
    middle.border(0, 0, np.empty(0, dtype=np.int64), no_rows)  # a closed tick's: a repeat
    assert list(middle.inbox) == [("border", 2)]
    with pytest.raises(Rejected, match="stale tick"):
        middle.border(2, 3, np.empty(0, dtype=np.int64), no_rows)
    with pytest.raises(Rejected, match="not its peer"):
        middle.border(5, 1, np.empty(0, dtype=np.int64), no_rows)
    own = run.deciding(middle.shard.own)
    middle.decided(1, *random_walk.Batch(run, None, 0).decide(1, own, None, run.robots))
    assert sorted(sent) == [("send_border", 0), ("send_border", 2)] and not run.tick  # waits for its neighbours
    with pytest.raises(Rejected, match="stale tick"):
        middle.decided(1, own, no_rows)


def test_the_world_rejects_hostile_rows_and_decisions_by_kind(shape):
    run = random_walk.RandomWalk(shape, params())
    ls = CentralLockstep(run, random_walk.Wire)
    ls.announce("b0", (0, run.grid.nx - 1))
    area = ls.area(0)
    for field, value, kind in (("x", 13, "bad state"), ("y", 2.5, "bad state"), ("id", 40, "bad ids")):
        bad = area.copy()
        bad[field][-1] = value
        with pytest.raises(Rejected, match=kind):
            random_walk.Wire.check_rows(run, bad, 0)
    ids, decided = random_walk.Batch(run, ls.strips, 0).decide(1, area["id"].astype(np.int64), None, run.robots)
    rows = random_walk.Wire.decision_rows(ids, decided)
    jump = rows.copy()
    jump["x"][0] = (jump["x"][0] + 2) % 13
    with pytest.raises(Rejected, match="illegal"):
        ls.decisions(0, 1, jump)
    with pytest.raises(Rejected, match="not its robots"):
        ls.decisions(0, 1, rows[1:])
    assert ls.decisions(0, 1, rows) and run.tick == 1
