"""Whether numba's cache of the core's kernels is filled, judged from files only (swarm_ros.core.kernels)."""

from __future__ import annotations

import os

import pytest

from swarm_ros.core import kernels

pytestmark = pytest.mark.unit


@pytest.fixture
def core(tmp_path, monkeypatch):
    """A fake core: a shared module whose kernels are all inlined, and each algorithm's package with a kernel
    module of its own."""
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    (tmp_path / "rng.py").write_text('@numba.njit(cache=True, inline="always")\n')
    (tmp_path / "plain.py").write_text("x = 1\n")
    for package, module in (("darr_niazi", "engine.py"), ("rubenstein", "rule.py")):
        (tmp_path / package / "__pycache__").mkdir(parents=True)
        (tmp_path / package / module).write_text("@numba.njit(cache=True)\n")
    monkeypatch.setattr(kernels, "_CORE", tmp_path)
    monkeypatch.setattr(kernels, "_CACHE", cache)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    return tmp_path


def _at(path, seconds):
    os.utime(path, (seconds, seconds))


def test_indexes_newer_than_their_sources_without_a_stamp_do_not_mean_filled(core):
    """A process that compiled some kernels on first use leaves their indexes, newer than every module, beside a
    cache that is only partly filled: only compile_kernels' stamp says it is filled."""
    for index in (
        core / "__pycache__" / "rng.draw-1.py311.nbi",
        core / "darr_niazi/__pycache__/engine.tick-2.py311.nbi",
    ):
        index.touch()
        _at(index, 2000)
    _at(core / "rng.py", 1000)
    _at(core / "darr_niazi" / "engine.py", 1000)
    assert not kernels.kernels_cached("darr-niazi")


def test_a_stamp_newer_than_every_kernel_module_means_filled(core):
    stamp = core / "__pycache__" / kernels._STAMP.format("darr-niazi")
    stamp.touch()
    _at(stamp, 4000)
    _at(core / "rng.py", 3000)
    _at(core / "darr_niazi" / "engine.py", 3000)
    assert kernels.kernels_cached("darr-niazi"), "compile_kernels ran after the last change"
    assert not kernels.kernels_cached("rubenstein"), "each algorithm has a stamp of its own"
    other = core / "__pycache__" / kernels._STAMP.format("rubenstein")
    other.touch()
    _at(other, 4000)
    _at(core / "rubenstein" / "rule.py", 3000)
    assert kernels.kernels_cached(), "both algorithms' stamps are newer than their modules"
    _at(core / "darr_niazi" / "engine.py", 5000)
    assert not kernels.kernels_cached("darr-niazi"), "a kernel module changed since"
    assert kernels.kernels_cached("rubenstein"), "a change to the study's model's kernels is not the other's"
    _at(core / "rng.py", 5000)  # but a change to a core kernel the other calls is (kernels.SHARED)
    assert not kernels.kernels_cached("rubenstein")


def test_no_cache_at_all_is_not_filled(core):
    assert not kernels.kernels_cached()


def test_drop_stale_removes_the_core_caches_written_before_the_last_change_to_a_kernel_module(core):
    cache = core / "__pycache__"
    old, new = core / "darr_niazi" / "__pycache__" / "engine.tick-2.py311.nbi", cache / "rng.draw-1.py311.nbc"
    other, stamp = cache / "plain.x-1.py311.nbi", cache / kernels._STAMP.format("darr-niazi")  # plain.py: no kernel
    for path, at in ((old, 1000), (new, 3000), (other, 1000), (stamp, 1000)):
        path.touch()
        _at(path, at)
    _at(core / "rng.py", 500)
    _at(core / "rubenstein" / "rule.py", 500)
    _at(core / "darr_niazi" / "engine.py", 2000)  # edited after old was written, before new
    assert kernels.drop_stale() == 1
    assert not old.exists() and new.exists() and other.exists() and stamp.exists()
    assert kernels.drop_stale() == 0


def test_the_command_names_an_algorithm_it_does_not_know_in_one_line(capsys):
    assert kernels.main(["kilobots"]) == 2
    assert capsys.readouterr().err == "swarm_ros: no algorithm 'kilobots' (known: darr-niazi, rubenstein)\n"


def test_count_compiles_counts_what_numba_compiles_in_this_process_from_then_on():
    import numba

    compiled = kernels.count_compiles()

    @numba.njit
    def plus_one(x):
        return x + 1

    assert compiled() == 0
    assert plus_one(1) == 2 and compiled() == 1
    assert plus_one(2) == 3 and compiled() == 1, "the same signature is not compiled again"
