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

#: The cells /swarm/occupancy shows done, by algorithm, from a tick's metrics (``col(name)``) and summary.json: the
#: covered pixels, or the shape's patches a localized robot stands on.
DONE_CELLS = {
    "rubenstein": lambda col, summary: col("covered"),
    "darr-niazi": lambda col, summary: summary["shape_patches"] - col("empty_patches"),
    "random-walk": lambda col, summary: col("covered"),
}


def central_types(algorithm: str, dims: int = 2) -> dict[str, str]:
    """A central world's run's topics: its robots and metrics under /swarm/<algorithm>/, the status, the maps (3D:
    voxel clouds) and the clock."""
    cloud, grid = (
        "sensor_msgs/msg/PointCloud2",
        "nav_msgs/msg/OccupancyGrid" if dims == 2 else "sensor_msgs/msg/PointCloud2",
    )
    under = f"/swarm/{algorithm.replace('-', '_')}"
    return {
        f"{under}/robots": cloud,
        f"{under}/metrics": cloud,
        "/swarm/status": "diagnostic_msgs/msg/DiagnosticArray",
        "/swarm/shape": grid,
        "/swarm/occupancy": grid,
        "/clock": "rosgraph_msgs/msg/Clock",
    }


def bag_metadata(bag: Path, dims: int = 2, types: dict[str, str] | None = None) -> dict:
    """metadata.yaml, checked against what rosbag2 (version 9) requires of it, its topics ``types`` (default: a
    run of the study's model in ``dims`` dimensions)."""
    types = types or central_types("darr-niazi", dims)
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
        messages: dict[str, list] = {topic: [] for topic in (types or central_types("darr-niazi", dims))}
        for _, channel, _, decoded in reader.iter_decoded_messages(log_time_order=True):
            messages[channel.topic].append(decoded)
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert {topic: len(got) for topic, got in messages.items()} == counts
    assert summary.statistics.message_count == info["message_count"]
    stats = summary.statistics
    assert stats.message_start_time == info["starting_time"]["nanoseconds_since_epoch"]
    assert stats.message_end_time - stats.message_start_time == info["duration"]["nanoseconds"]
    return info, messages


def assert_bag_holds_run(run: Path, interrupted: bool = False) -> None:
    """A central world's run's bag (any algorithm's): the metrics rows of every tick (a tick's again after a world's
    restart, the same) equal metrics.csv; every robot's row every ``bag_robots_every``-th tick and at the last, each
    robot once in a record (from one message or, with world shards, one a shard), and the last gives final_state.csv's
    positions; the statuses hold the outcome at the last tick and no other (world shards' statuses come in any order:
    a shard's "running" may come after another's outcome); the clock of every tick, the shape, and the occupancy at
    each record that changed what it shows (counted by the algorithm's :data:`DONE_CELLS`; the monitor encodes them
    from the rows). ``interrupted``: the run was written up to its last record, and the bag also holds the metrics of
    the ticks the monitor took after it; no outcome went out."""
    from swarm_ros.core.algorithm import algorithm_of
    from swarm_ros.protocol.central_rows import metrics_row

    summary = json.loads((run / "summary.json").read_text())
    with open(run / "final_state.csv", newline="") as f:
        state = list(csv.DictReader(f))
    dims = 3 if "z" in state[0] else 2
    types = central_types(summary["algorithm"], dims)
    robots_topic, metrics_topic = list(types)[:2]
    _, messages = read_bag(run / "bag", types=types)
    header = (run / "metrics.csv").read_text().split("\n", 1)[0].split(",")
    table = np.loadtxt(run / "metrics.csv", delimiter=",", skiprows=1, ndmin=2)
    metrics = metrics_row(tuple(header))
    rows = np.concatenate([np.frombuffer(m.data, dtype=metrics) for m in messages[metrics_topic]])
    got = np.column_stack([rows[name] for name in metrics.names])
    _, first = np.unique(got[:, 0], return_index=True)  # a restarted world sends the ticks since its last record again
    assert np.array_equal(got, got[first][got[:, 0].astype(int)]), "a tick's rows sent again differ"
    assert np.array_equal(got[first][: len(table)] if interrupted else got[first], table)
    last = int(table[-1, 0])
    row = algorithm_of(summary["algorithm"]).hook("wire")(dims).row
    records: dict[int, list[np.ndarray]] = {}  # tick -> its messages' rows (S world shards: one message each)
    for m in messages[robots_topic]:
        records.setdefault(m.header.stamp.sec, []).append(np.frombuffer(m.data, dtype=row))
    assert list(records) == sorted({*range(0, last + 1, summary["bag_robots_every"]), last})
    wholes = [np.concatenate(parts) for parts in records.values()]
    assert all(np.array_equal(np.sort(w["id"]), np.arange(summary["robots"])) for w in wholes), "a robot not once"
    final = wholes[-1][np.argsort(wholes[-1]["id"])]
    assert [float(r["x"]) for r in state] == final["x"].tolist() and [float(r["y"]) for r in state] == final[
        "y"
    ].tolist()
    held = got[first]  # every tick's metrics the monitor took
    assert [m.clock.sec for m in messages["/clock"]] == list(range(len(held))), "not each tick's clock once"
    (shape,) = messages["/swarm/shape"]  # the shape's cells, and the done ones at each record that changed them
    cells = (lambda m: m.width * m.height) if dims == 3 else (lambda m, full=0: sum(np.asarray(m.data) == full))
    assert cells(shape) == summary.get("shape_patches", summary.get("shape_pixels"))
    done = DONE_CELLS[summary["algorithm"]](lambda name: held[:, header.index(name)], summary)
    ticks = sorted(records)
    changed = [t for i, t in enumerate(ticks) if i == 0 or done[t] != done[ticks[i - 1]]]
    grids = messages["/swarm/occupancy"]
    assert [g.header.stamp.sec for g in grids] == changed
    assert [cells(g) if dims == 3 else cells(g, 100) for g in grids] == [done[t] for t in changed]
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
