"""Reading a run's bag/ back with a library other than the one that wrote it.

The monitor writes the bag with ``rosbags``; these checks read it with ``mcap`` and
``mcap-ros2-support`` (their own CDR decoder, from the message definitions embedded in
the file), and compare it with the run's own files.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from swarm_ros.core.metrics import tick_metrics
from swarm_ros.core.state import MOVING_STATES, STATE_COUNT, RobotState
from swarm_ros.protocol.rows import PATCH_METRES, VOXEL_ROW, decision_row, robot_row

TYPES = {
    "/swarm/robots": "sensor_msgs/msg/PointCloud2",
    "/swarm/decisions": "sensor_msgs/msg/PointCloud2",
    "/swarm/occupancy": "nav_msgs/msg/OccupancyGrid",
    "/swarm/shape": "nav_msgs/msg/OccupancyGrid",
    "/swarm/status": "diagnostic_msgs/msg/DiagnosticArray",
    "/swarm/metrics": "std_msgs/msg/Int64MultiArray",
    "/swarm/tally": "std_msgs/msg/Int64MultiArray",
    "/clock": "rosgraph_msgs/msg/Clock",
}
#: A 3D run's topics: its shape and occupancy are PointCloud2s of voxel centres.
TYPES_3D = {**TYPES, "/swarm/occupancy": "sensor_msgs/msg/PointCloud2", "/swarm/shape": "sensor_msgs/msg/PointCloud2"}


#: A rubenstein run's topics.
RUBENSTEIN_TYPES = {
    "/swarm/rubenstein/robots": "sensor_msgs/msg/PointCloud2",
    "/swarm/rubenstein/metrics": "sensor_msgs/msg/PointCloud2",
    "/swarm/status": "diagnostic_msgs/msg/DiagnosticArray",
    "/swarm/shape": "nav_msgs/msg/OccupancyGrid",
    "/swarm/occupancy": "nav_msgs/msg/OccupancyGrid",
    "/clock": "rosgraph_msgs/msg/Clock",
}


def bag_metadata(bag: Path, dims: int = 2, types: dict[str, str] | None = None) -> dict:
    """metadata.yaml, checked against what rosbag2 (version 9) requires of it, its topics ``types`` (default: a
    run of the study's model in ``dims`` dimensions)."""
    types = types or (TYPES if dims == 2 else TYPES_3D)
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["bag_0.mcap"] and [f["path"] for f in info["files"]] == ["bag_0.mcap"]
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert {name: t["topic_metadata"]["type"] for name, t in topics.items()} == types
    for t in topics.values():
        meta = t["topic_metadata"]
        assert meta["serialization_format"] == "cdr" and meta["type_description_hash"].startswith("RIHS01_")
        assert len(meta["offered_qos_profiles"]) == 1 and meta["offered_qos_profiles"][0]["reliability"]
    assert info["message_count"] == sum(t["message_count"] for t in topics.values())
    assert info["files"][0]["message_count"] == info["message_count"]
    assert info["duration"]["nanoseconds"] >= 0 and info["starting_time"]["nanoseconds_since_epoch"] > 0
    return info


def read_bag(bag: Path, dims: int = 2, types: dict[str, str] | None = None) -> tuple[dict, dict[str, list]]:
    """(metadata.yaml, {topic: decoded messages in log order}); counts and times checked against the MCAP file."""
    info = bag_metadata(bag, dims, types)
    with open(bag / "bag_0.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        messages: dict[str, list] = {topic: [] for topic in (types or TYPES)}
        for _, channel, _, decoded in reader.iter_decoded_messages(log_time_order=True):
            messages[channel.topic].append(decoded)
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert {topic: len(got) for topic, got in messages.items()} == counts
    assert summary.statistics.message_count == info["message_count"]
    stats = summary.statistics
    assert stats.message_start_time == info["starting_time"]["nanoseconds_since_epoch"]
    assert stats.message_end_time - stats.message_start_time == info["duration"]["nanoseconds"]
    return info, messages


def assert_bag_holds_run(run: Path) -> None:
    """Every tick's robot rows in the bag rebuild final_state.csv; its metrics equal metrics.csv; every
    tick's decisions are in it, one per robot moving after the tick before; shape, status, occupancy too.
    With ``record_every`` > 1 (summary.json's ``bag_robots_every``): every robot's row every k-th tick and at the
    last, that tick's decisions, and the world's tallies of every tick, which give metrics.csv."""
    final_state = (run / "final_state.csv").read_text()
    dims = 3 if final_state.startswith("id,x,y,z,") else 2
    _, messages = read_bag(run / "bag", dims)
    every = json.loads((run / "summary.json").read_text())["bag_robots_every"]
    robots = messages["/swarm/robots"]
    ticks = [m.header.stamp.sec for m in robots]
    with open(run / "metrics.csv", newline="") as f:
        table = list(csv.reader(f))
    last = len(table) - 2  # the header, then ticks 0..last
    if every == 1:  # one robots message per tick, in order; with world shards, one per shard, a tick's together
        assert sorted(set(ticks)) == list(range(last + 1)) and ticks == sorted(ticks), "every tick, in order"
        assert not messages["/swarm/tally"]
    else:  # every k-th tick and the last, each whole (every robot once, over the shards' parts)
        recorded = sorted({*range(0, last + 1, every), last})
        assert sorted(set(ticks)) == recorded and ticks == sorted(ticks), (sorted(set(ticks))[:5], every)
    row_type = robot_row(dims)
    n = sum(np.frombuffer(m.data, dtype=row_type).size for m in robots if m.header.stamp.sec == 0)
    columns = ("x", "y", "z", "heading", "pitch") if dims == 3 else ("x", "y", "heading")
    pose = {name: np.zeros(n) for name in columns}
    state = np.zeros(n, dtype=np.int64)
    moving_after: dict[int, set[int]] = {}
    by_state: dict[int, np.ndarray] = {}
    for at, m in enumerate(robots):
        rows = np.frombuffer(m.data, dtype=row_type)
        ids = rows["id"].astype(np.int64)
        state[ids] = rows["state"]
        for name in columns:
            pose[name][ids] = rows[name] / (PATCH_METRES if name in "xyz" else 1.0)
        tick = m.header.stamp.sec
        if at + 1 == len(robots) or robots[at + 1].header.stamp.sec != tick:  # the tick is whole
            moving_after[tick] = set(np.flatnonzero(np.isin(state, MOVING_STATES)).tolist())
            by_state[tick] = np.bincount(state, minlength=STATE_COUNT)
            if every > 1:
                whole = np.sort(
                    np.concatenate(
                        [np.frombuffer(r.data, dtype=row_type)["id"] for r in robots if r.header.stamp.sec == tick]
                    ).astype(np.int64)
                )
                assert np.array_equal(whole, np.arange(n)), f"tick {tick}: every robot once"
    labels = [s.label for s in RobotState]
    values = [pose[name].tolist() for name in columns]
    rebuilt = [",".join(("id", *columns, "state"))]
    rebuilt += [",".join([str(i), *(repr(v[i]) for v in values), labels[state[i]]]) for i in range(n)]
    assert "\n".join(rebuilt) + "\n" == final_state

    got = [[str(v) for v in m.data] for m in messages["/swarm/metrics"]]
    assert [m.layout.dim[0].label for m in messages["/swarm/metrics"][:1]] == [",".join(table[0])]
    assert got == table[1:]
    if every > 1:  # one tally a tick (the world's, or world shard 0's) gives its metrics; at a recorded tick, its rows
        tallies: dict[int, list[np.ndarray]] = {}
        for m in messages["/swarm/tally"]:
            data = np.asarray(m.data, dtype=np.int64)
            assert int(data[1]) == every
            tallies.setdefault(int(data[0]), []).append(data[2:])
        assert sorted(tallies) == list(range(last + 1)) and {len(v) for v in tallies.values()} == {1}
        for tick, parts in tallies.items():
            counts = np.sum(parts, axis=0)
            assert [str(v) for v in tick_metrics(tick, counts, 0)[:5]] == table[tick + 1][:5], f"tick {tick}"
            if tick in by_state:
                assert np.array_equal(by_state[tick], counts), f"tick {tick}: the rows and the tallies"

    # Decisions: the world starts once it has discovered the monitor's readers, so every tick's are in,
    # one row for each robot moving after the tick before (a batch may also decide for the tick after the
    # last, before it hears the outcome). With record_every > 1, those of the recorded ticks: as many as the
    # metrics' moving robots after the tick before.
    decided: dict[int, list[int]] = {}
    for m in messages["/swarm/decisions"]:
        rows = np.frombuffer(m.data, dtype=decision_row(dims))
        decided.setdefault(m.header.stamp.sec, []).extend(rows["id"].tolist())
    moving = table[0].index("moving")
    for tick in range(1, last + 1):
        if every == 1:
            assert sorted(decided.get(tick, [])) == sorted(moving_after[tick - 1]), f"decisions of tick {tick}"
        elif tick in by_state:
            assert len(decided.get(tick, [])) == int(table[tick][moving]), f"decisions of tick {tick}"
    allowed = set(range(1, last + 2)) if every == 1 else {t for t in by_state if t > 0} | {last + 1}
    assert set(decided) <= allowed, sorted(set(decided) - allowed)
    counts = {topic: len(got) for topic, got in messages.items()}
    assert counts["/swarm/shape"] == 1 and counts["/swarm/status"] >= 1 and counts["/swarm/occupancy"] >= 1, counts
    for m in messages["/swarm/occupancy"] + messages["/swarm/shape"]:
        cells = m.width * m.height * VOXEL_ROW.itemsize if dims == 3 else m.info.width * m.info.height
        assert len(m.data) == cells and m.header.frame_id == "world"
    # the monitor writes /clock and the occupancy itself, from the rows it verified: every tick's clock, and
    # the occupancy at tick 0 and after every tick in which the localized robots changed, ending at the final one
    clock = [m.clock.sec for m in messages["/clock"]]
    assert clock == list(range(last + 1)), (clock[:5], len(clock), last)
    on_patches = np.isin(state, [RobotState.SEED, RobotState.LOCALIZED]).sum()
    if dims == 3:  # the filled voxels' centres: where the localized robots stand
        final = np.frombuffer(messages["/swarm/occupancy"][-1].data, dtype=VOXEL_ROW)
        standing = np.isin(state, [RobotState.SEED, RobotState.LOCALIZED])
        centres = {
            (float(a), float(b), float(c))
            for a, b, c in zip(pose["x"][standing], pose["y"][standing], pose["z"][standing])
        }
        assert {(float(r["x"]), float(r["y"]), float(r["z"])) for r in final} == centres
    else:
        final = np.asarray(messages["/swarm/occupancy"][-1].data, dtype=np.int8)
        assert (final == 100).sum() == on_patches, "the last occupancy is the final state's"
    assert messages["/swarm/occupancy"][0].header.stamp.sec == 0


def assert_rubenstein_bag_holds_run(run: Path, interrupted: bool = False) -> None:
    """A rubenstein run's bag: the metrics rows of every tick (a tick's again after a world's restart, the same)
    equal metrics.csv; every robot's row every ``bag_robots_every``-th tick and at the last, each robot once in a
    record (from one message or, with world shards, one a shard), and the last rebuilds final_state.csv; the statuses
    hold the outcome at the last tick and no other (world shards' statuses come in any order: a shard's "running" may
    come after another's outcome); the clock of every tick, the shape, and the occupancy at each record that covered
    more pixels (the monitor encodes them from the rows). ``interrupted``: the run was written up to its last record,
    and the bag also holds the metrics of the ticks the monitor took after it; no outcome went out."""
    from swarm_ros.core.rubenstein.rule import STATE_NAMES
    from swarm_ros.core.rubenstein.run import COLUMNS
    from swarm_ros.protocol.central_rows import metrics_row
    from swarm_ros.protocol.rubenstein.rows import RUBENSTEIN_ROW

    RUBENSTEIN_METRICS_ROW = metrics_row(COLUMNS)

    _, messages = read_bag(run / "bag", types=RUBENSTEIN_TYPES)
    summary = json.loads((run / "summary.json").read_text())
    table = np.loadtxt(run / "metrics.csv", delimiter=",", skiprows=1, ndmin=2)
    rows = np.concatenate(
        [np.frombuffer(m.data, dtype=RUBENSTEIN_METRICS_ROW) for m in messages["/swarm/rubenstein/metrics"]]
    )
    got = np.column_stack([rows[name] for name in RUBENSTEIN_METRICS_ROW.names])
    _, first = np.unique(got[:, 0], return_index=True)  # a restarted world sends the ticks since its last record again
    assert np.array_equal(got, got[first][got[:, 0].astype(int)]), "a tick's rows sent again differ"
    assert np.array_equal(got[first][: len(table)] if interrupted else got[first], table)
    last = int(table[-1, 0])
    records: dict[int, list[np.ndarray]] = {}  # tick -> its messages' rows (S world shards: one message each)
    for m in messages["/swarm/rubenstein/robots"]:
        records.setdefault(m.header.stamp.sec, []).append(np.frombuffer(m.data, dtype=RUBENSTEIN_ROW))
    assert list(records) == sorted({*range(0, last + 1, summary["bag_robots_every"]), last})
    wholes = [np.concatenate(parts) for parts in records.values()]
    assert all(np.array_equal(np.sort(w["id"]), np.arange(summary["robots"])) for w in wholes), "a robot not once"
    final = wholes[-1][np.argsort(wholes[-1]["id"])]
    with open(run / "final_state.csv", newline="") as f:
        state = list(csv.DictReader(f))
    assert [float(r["x"]) for r in state] == final["x"].tolist()
    assert [r["state"] for r in state] == [STATE_NAMES[c] for c in final["state"]]
    held = got[first]  # every tick's metrics the monitor took
    assert [m.clock.sec for m in messages["/clock"]] == list(range(len(held))), "not each tick's clock once"
    (shape,) = messages["/swarm/shape"]  # the shape's pixels, and the covered ones at each record that covered more
    assert sum(np.asarray(shape.data) == 0) == summary["shape_pixels"]
    covered, ticks = held[:, COLUMNS.index("covered")], sorted(records)
    grown = [t for i, t in enumerate(ticks) if i == 0 or covered[t] != covered[ticks[i - 1]]]
    grids = messages["/swarm/occupancy"]
    assert [g.header.stamp.sec for g in grids] == grown
    assert [sum(np.asarray(g.data) == 100) for g in grids] == [covered[t] for t in grown]
    assert all((g.info.width, g.info.height) == (shape.info.width, shape.info.height) for g in grids)
    statuses = [
        (m.header.stamp.sec, v.value)
        for m in messages["/swarm/status"]
        for st in m.status
        for v in st.values
        if v.key == "outcome"
    ]  # (tick, outcome); world shards' statuses interleave in the order they came
    ended = {outcome for _, outcome in statuses if outcome not in ("starting", "running")}
    if interrupted:
        assert not ended, ended
    else:
        assert ended == {summary["outcome"]}, ended
        assert (last, summary["outcome"]) in statuses and max(t for t, _ in statuses) == last
