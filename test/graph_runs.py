"""Runs of the ROS 2 graph and their processes: the environment, the processes of a run, a node's pid, killing
it, what its saves and recordings say, and a run checked against simulate's."""

from __future__ import annotations

import json
import os
import shlex
import signal
from pathlib import Path

import numpy as np
from bagcheck import assert_bag_holds_run
from recordings import Recording
from waiting import wait_for

from swarm_ros.ros.shm import shm_locks


def run_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("ROS_DOMAIN_ID", None)  # every run picks a free domain of its own
    env.setdefault("HOME", "/tmp")
    return env


def _processes_where(read: str, holds) -> list[int]:
    """Pids of the live processes whose /proc/<pid>/``read`` file's text ``holds`` (one that ended meanwhile: no)."""
    found = []
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit():
            try:
                text = (proc / read).read_bytes().decode(errors="replace")
            except OSError:
                continue
            if holds(text):
                found.append(int(proc.name))
    return found


def processes_mentioning(text: str) -> list[int]:
    """Pids of the processes whose command line holds ``text``."""
    return _processes_where("cmdline", lambda cmdline: text in cmdline)


def command_args(pid: int) -> list[str]:
    """Process ``pid``'s command line as arguments: NUL-separated as exec gave them, or a node forked by
    ``swarm-ros run`` whose title (setproctitle) is its command, quoted (swarm_ros/app/forking.py). [] if gone."""
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes().rstrip(b"\0").decode(errors="replace")
    except OSError:
        return []
    if "\0" in raw:
        return raw.split("\0")
    try:
        return shlex.split(raw)
    except ValueError:
        return raw.split()


def run_processes(out: Path) -> list[int]:
    """Pids of the node processes of the run writing ``out`` (their parameter files are in its hidden logs
    folder), and of no other run on the machine, a test running beside this one included."""
    return processes_mentioning(f"{out.absolute().parent}/.{out.name}.logs-")


def assert_same_run(ref: Path, got: Path, launched: bool = True) -> None:
    """``got`` (a ROS run; ``launched``: by ``swarm-ros run``) equals ``ref`` (``simulate``) but for timings."""
    assert (ref / "metrics.csv").read_bytes() == (got / "metrics.csv").read_bytes()
    assert (ref / "final_state.csv").read_bytes() == (got / "final_state.csv").read_bytes()
    a = json.loads((ref / "summary.json").read_text())
    b = json.loads((got / "summary.json").read_text())
    assert (a.pop("engine"), b.pop("engine")) == ("inprocess", "ros2")
    a.pop("wall_seconds"), b.pop("wall_seconds")
    # a ROS run's overheads: from the command's start to tick 0, and from the outcome to the last process gone
    # (only the launcher knows the latter, from the world's status: its progress listener heard the graph)
    startup, shutdown = b.pop("startup_seconds"), b.pop("shutdown_seconds")
    assert isinstance(startup, float) and 0 < startup < 120
    assert (isinstance(shutdown, float) and 0 < shutdown < 60) if launched else shutdown is None
    assert b.pop("rejected_messages") == {"world": 0, "monitor": 0}  # an honest run: nothing dropped
    processes, shards = b.pop("processes"), b.pop("world_shards")  # how it ran
    assert isinstance(shards, int) and shards >= 1
    assert (isinstance(processes, int) and processes >= shards) if launched else processes is None
    b.pop("bag_robots_every", None)  # checked against the bag (bagcheck)
    assert a == b
    assert (got / "final.png").stat().st_size > 0 and (got / "convergence.png").stat().st_size > 0
    assert_bag_holds_run(got)  # the rosbag2 of the run, read with another library than the one that wrote it
    # the monitor records with the same module: the same data (ids, timestamps and chunking may differ)
    assert Recording(got / "recording.rrd").same_data(Recording(ref / "recording.rrd"))


# The star under the local join rule: ~3600 ticks, several seconds over the graph, long enough to kill in
STAR_LOCAL = ["--shape", "star", "--seed", "5", "--rules", "local"]


#: STAR_LOCAL cut at 1,000 ticks (outcome timeout): the fault tests' run, about 3 s over the graph once started;
#: their kills are timed on what the run writes, all before tick 600
STAR_SHORT = [*STAR_LOCAL, "--max-ticks", "1000"]


def node_pid(out: Path, node: str, timeout: float = 60, not_pid: int | None = None) -> int:
    """The pid of the process running ``node`` for the run into ``out`` (a new one if ``not_pid`` is given)."""

    def found() -> int | None:
        for pid in run_processes(out):
            args = command_args(pid)
            if f"__node:={node}" in args and any(str(out.parent) in a for a in args) and pid != not_pid:
                return pid
        return None

    return wait_for(found, timeout, f"a process for {node}", poll=0.02)


def wait_ticks_recorded(out: Path, size: int, timeout: float = 120) -> None:
    """Wait until the run's partial recording holds ``size`` bytes: ticks are flowing."""
    partial = out.parent / f"{out.name}.partial.rrd"
    wait_for(lambda: partial.exists() and partial.stat().st_size > size, timeout, "the run getting going", poll=0.02)


def assert_identical_run(reference: Path, out: Path) -> dict:
    for name in ("metrics.csv", "final_state.csv"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
    got, ref = (json.loads((d / "summary.json").read_text()) for d in (out, reference))
    assert got["outcome"] == ref["outcome"] and got["lost_robots"] == 0 and got["losses"] == []
    return got


def wait_rubenstein_saved(out: Path, tick: int, timeout: float = 120) -> None:
    """Wait until a rubenstein run's world has saved its checkpoint of ``tick`` or a later one: ticks are flowing, and
    the monitor holds the records up to its window behind it (the world runs no further ahead). Not the partial
    recording's size: Rerun may flush a small run's file only at its end."""
    import zipfile

    logs = staged_logs(out)

    def past() -> bool:
        try:
            with np.load(logs / "world.checkpoint") as saved:
                return int(saved["tick"][0]) >= tick
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):  # not there yet, or being replaced
            return False

    wait_for(past, timeout, f"the world saving tick {tick}", poll=0.02)


def wait_monitor_holds(out: Path, topic: str, messages: int, timeout: float = 120) -> None:
    """Wait until the monitor's bag holds ``messages`` messages of ``topic`` durably (it makes its bag durable each
    time it holds one more whole record): read as a restarted monitor reads it."""
    from swarm_ros.ros.bag_writer import unfinished_messages

    def held() -> bool:
        holder = next(out.parent.glob(f".{out.name}.bag-*"), None)
        return holder is not None and sum(t == topic for t, _, _ in unfinished_messages(holder)) >= messages

    wait_for(held, timeout, f"{messages} messages of {topic} in the monitor's bag", poll=0.05)


def staged_logs(out: Path, timeout: float = 60) -> Path:
    return wait_for(lambda: next(out.parent.glob(f".{out.name}.logs-*"), None), timeout, "its logs", poll=0.01)


def _run_of(logs: Path) -> Path:
    """The run directory whose staged logs are ``logs`` (``.<run>.logs-XXXX`` beside it)."""
    return logs.parent / logs.name[1:].split(".logs-")[0]


def saved_tick(logs: Path, name: str = "") -> int:
    """The last tick the run's monitor holds durably in its bag (:func:`bag_tick`), from the run's staged logs.
    (``name``: unused, the world process's; every world process's tick is the run's.)"""
    return bag_tick(_run_of(logs))


def bag_tick(out: Path) -> int:
    """The last tick the monitor of the run into ``out`` holds durably in its bag (its /clock, written as it takes
    each tick's metrics); -1 before tick 0."""
    from swarm_ros.ros.bag_writer import held_tick

    return held_tick(out.parent.glob(f".{out.name}.bag-*"))


def wait_saved(logs: Path, tick: int, timeout: float = 180, name: str = "") -> int:
    """Wait until the run's monitor holds ``tick`` (:func:`saved_tick`): the world got there, and a restarted world
    goes on from its last checkpoint at or before it; return the tick held when seen."""
    saved = wait_for(  # a one-item list: true even for tick 0
        lambda: [t for t in (saved_tick(logs),) if t >= tick], timeout, f"tick {tick} held", poll=0.1
    )
    return saved[0]


def kill_starting(out: Path, node: str, timeout: float = 60) -> int:
    """SIGKILL ``node``'s first process in the run into ``out`` as it starts, long before tick 0: once its DDS
    participant holds its own two shared-memory ports. (A process forked from the launcher makes its participant at
    once, and one killed while Fast DDS makes a port can leave a port that wedges every later participant on the
    host: docs/faults.md. CI saw it once, with a batch killed as soon as its process existed.)"""
    pid = node_pid(out, node, timeout=timeout)

    def ported() -> bool:
        return sum("fastrtps_port" in f for f in shm_locks(pid)) >= 2 or not os.path.exists(f"/proc/{pid}")

    wait_for(ported, timeout, f"{node}'s shared-memory ports", poll=0.005)
    os.kill(pid, signal.SIGKILL)
    return pid


def kill_node(out: Path, node: str, not_pid: int | None = None) -> int:
    pid = node_pid(out, node, not_pid=not_pid)
    os.kill(pid, signal.SIGKILL)
    return pid


def finish_restarted_run(launcher, reference: Path, out: Path, restarts: list[str]) -> dict:
    _, err = launcher.communicate(timeout=300)
    assert launcher.returncode == 0, err
    summary = assert_identical_run(reference, out)
    assert [r["node"] for r in summary["restarts"]] == restarts, summary["restarts"]
    assert_bag_holds_run(out)
    assert not list(out.parent.glob(f".{out.name}.*")), "nothing of the run left beside it"
    assert not list((out / "logs").glob("world.checkpoint*")), "the checkpoint is removed with the run"
    assert not processes_mentioning(str(out)), "a process outlived the run"
    return summary


def children_of(pid: int) -> list[int]:
    """Pids of the processes whose parent is ``pid``."""
    return _processes_where("stat", lambda stat: int(stat.rsplit(")", 1)[1].split()[1]) == pid)


def shm_left(files) -> list[str]:
    """Those of the Fast DDS shared-memory ``files`` that still exist and that no live process uses: left
    behind. A port's files (``fastrtps_portN``) are shared by every participant on that port, so a run or test
    beside this one may rightly still hold them."""
    from swarm_ros.ros.shm import in_use

    return sorted(f for f in files if os.path.exists(f) and not in_use(shm_group(f)))


def shm_group(path: str) -> set[str]:
    """A Fast DDS shared-memory file's group: its segment, its lock file and (a port's) its semaphore."""
    name = Path(path).name.removesuffix("_el")
    if name.startswith("sem.") and name.endswith("_mutex"):
        name = name.removeprefix("sem.").removesuffix("_mutex")
    return {f"/dev/shm/{name}", f"/dev/shm/{name}_el", f"/dev/shm/sem.{name}_mutex"}


def descendants_of(pid: int) -> list[int]:
    """Pids of ``pid``'s children, their children, and so on."""
    found, todo = [], [pid]
    while todo:
        kids = children_of(todo.pop())
        found += kids
        todo += kids
    return found


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (not gone, not a zombie)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False
