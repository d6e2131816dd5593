"""The rubenstein algorithm (Rubenstein et al.'s Kilobot self-assembly): each rule piece, the invariants over
whole runs, the outcomes, and its parameters."""

import math

import numpy as np
import pytest

from swarm_ros.core import Shape, World
from swarm_ros.core.errors import InvariantError, ParameterError
from swarm_ros.core.params import RunParams, Settings
from swarm_ros.core.rubenstein.layout import SEEDS, ShapeFrame, start_positions
from swarm_ros.core.rubenstein.rule import (
    JOINED,
    MOVE_INSIDE,
    MOVE_OUTSIDE,
    NEVER,
    START,
    UNKNOWN_G,
    WAIT,
    good_geometry,
    sweep,
    trilaterate,
)
from swarm_ros.core.rubenstein.run import RubensteinRun, hole_filled, summary_of
from swarm_ros.core.rubenstein.tick_checks import check_tick, snapshot

pytestmark = pytest.mark.unit


def square(side: int) -> Shape:
    """A solid square of ``side`` x ``side`` pixels."""
    return Shape.from_grid(np.ones((side, side), dtype=bool), World(), name=f"square{side}", source="test")


def ring(side: int, hole: int) -> Shape:
    """A ``side`` x ``side`` square with a centred ``hole`` x ``hole`` hole."""
    mask = np.ones((side, side), dtype=bool)
    a = (side - hole) // 2
    mask[a : a + hole, a : a + hole] = False
    return Shape.from_grid(mask, World(), name=f"ring{side}", source="test")


def rubenstein(shape: Shape, robots: int, **values) -> RubensteinRun:
    return RubensteinRun(shape, RunParams(robots, algorithm="rubenstein", **values))


def contacts(pos: np.ndarray) -> list[list[int]]:
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
    return [list(np.flatnonzero((row > 0.5) & (row < 1.0 + 1e-9))) for row in d]


def test_the_start_is_a_touching_hexagonal_pack_below_the_seeds_and_outside_the_shape():
    pos = start_positions(200)
    assert np.allclose(pos[:4], SEEDS)
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1)) + np.eye(200) * 9
    assert d.min() > 1.0 - 1e-9  # touching, never overlapping
    assert (pos[4:, 1] <= -math.sqrt(3) + 1e-9).all()  # the shape lies at y >= 0: every robot 1.5 d from it
    seen, todo = {0}, [0]  # connected through touching neighbours
    links = contacts(pos)
    while todo:
        for j in links[todo.pop()]:
            if j not in seen:
                seen.add(j)
                todo.append(j)
    assert len(seen) == 200


def test_the_gradient_counts_the_rings_of_a_hexagonal_pack():
    run = rubenstein(square(8), 120, startup_ticks=1000)
    run.run(60)
    pos = np.stack([run.robots.x, run.robots.y], axis=1)
    hops = np.full(120, -1)
    hops[:4] = [0, 1, 1, 1]
    frontier = [0, 1, 2, 3]
    links = contacts(pos)
    while frontier:  # breadth first from the seeds, through touching robots
        nxt = []
        for i in frontier:
            for j in links[i]:
                if hops[j] < 0 or hops[j] > hops[i] + 1:
                    hops[j] = hops[i] + 1
                    nxt.append(j)
        frontier = nxt
    assert (run.robots.state[4:] == START).all()
    assert np.array_equal(run.robots.g, hops)
    assert run.robots.g.max() >= 6


@pytest.mark.parametrize("noise", [0.0, 0.06])
def test_localization_of_the_pack_converges_within_a_tenth_of_a_diameter(noise):
    run = rubenstein(square(8), 60, startup_ticks=1000, range_noise=noise, seed=3)
    run.run(150)
    s = run.robots
    assert s.loc.all() and s.est.all()
    error = np.hypot(s.ex - s.x, s.ey - s.y)
    assert error.max() < 0.1, error.max()


def test_one_sweep_moves_the_estimate_towards_the_measured_circles_and_trilateration_starts_it():
    anchors = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 3.0], [3.0, 3.0]])
    truth = np.array([1.2, 0.7])
    am = np.hypot(*(anchors - truth).T)
    ax, ay = anchors[:, 0].copy(), anchors[:, 1].copy()
    x, y, ok = trilaterate(ax, ay, am, 4)
    assert ok and math.hypot(x - truth[0], y - truth[1]) < 1e-9
    px, py = 2.5, 2.5
    for _ in range(200):
        px, py = sweep(px, py, ax, ay, am, 4, 0.25)
    assert math.hypot(px - truth[0], py - truth[1]) < 1e-6
    assert good_geometry(ax, ay, 4, math.radians(15))
    line = np.array([0.0, 1.0, 2.0, 3.0])
    assert not good_geometry(line, line * 0.01, 4, math.radians(15))  # nearly collinear anchors
    # a band three rows deep and seven long, as along a straight edge of the pack: a good triangle is in it
    bx = np.concatenate([np.arange(7.0) + 0.5 * (r % 2) for r in range(3)])
    by = np.concatenate([np.full(7, r * math.sqrt(3) / 2) for r in range(3)])
    order = np.argsort(-bx, kind="stable")  # the first anchor at an end of the band
    assert good_geometry(bx[order].copy(), by[order].copy(), 21, math.radians(15))


def test_an_edge_follower_keeps_its_distance_around_a_fixed_group():
    run = rubenstein(square(8), 60, startup_ticks=0)
    s = run.robots
    mover = 59
    group = np.arange(59)
    s.state[group] = JOINED  # a fixed group: nothing else moves, and nothing joins
    s.joined[group] = 0
    s.loc[:] = 0  # no anchors: the mover never localizes, so never enters the shape
    s.state[mover], s.began[mover] = MOVE_OUTSIDE, 0
    s.x[mover], s.y[mover] = s.x[group].min() - 1.3, s.y[group].mean()
    s.heading[mover] = math.pi / 2
    cx, cy = s.x[group].mean(), s.y[group].mean()
    gaps, angles = [], []
    for _ in range(6000):
        run.step()
        gaps.append(np.hypot(s.x[group] - s.x[mover], s.y[group] - s.y[mover]).min())
        angles.append(math.atan2(s.y[mover] - cy, s.x[mover] - cx))
        if s.state[mover] != MOVE_OUTSIDE:
            break
    gaps = np.array(gaps[200:])  # once it has settled along the edge
    assert gaps.min() >= 1.0 - 1e-9 and gaps.max() < 1.3 + 0.5
    assert abs(np.median(gaps) - 1.3) < 0.15
    turned = np.unwrap(angles)
    assert turned[-1] - turned[0] < -math.pi  # clockwise round the group, the group on its right


@pytest.mark.parametrize("stale", [0, 5, 20])
def test_a_mover_drops_an_estimate_it_could_not_update_for_loc_stale_ticks_and_never_joins_without_one(stale):
    """An edge-follower walks on with an estimate and no anchors (no robot is localized): after
    ``loc_stale_ticks`` ticks it drops it (and is no longer localized), to trilaterate afresh where anchors
    are; 0 keeps it for good. Placed inside the shape, a robot without an estimate does not join."""
    run = rubenstein(square(8), 60, startup_ticks=0, loc_stale_ticks=stale)
    s = run.robots
    mover, group = 59, np.arange(59)
    s.state[group], s.joined[group], s.loc[:] = JOINED, 0, 0
    s.state[mover], s.began[mover], s.est[mover], s.loc[mover] = MOVE_OUTSIDE, 0, 1, 1
    s.x[mover], s.y[mover] = s.x[group].min() - 1.3, s.y[group].mean()
    s.ex[mover], s.ey[mover] = s.x[mover], s.y[mover]
    seen = []
    for _ in range(30):
        run.step()
        seen.append((int(s.est[mover]), int(s.loc[mover]), int(s.blind[mover])))
        assert s.ex[mover] == s.x[group].min() - 1.3 or not s.est[mover]  # never updated without anchors
    if stale == 0:
        assert seen == [(1, 1, t) for t in range(1, 31)]
    else:
        assert seen[: stale - 1] == [(1, 1, t) for t in range(1, stale)]
        assert all(flags == (0, 0, 0) for flags in seen[stale - 1 :])
    # no estimate, inside the shape, next to a stationary robot of the same gradient: it does not join
    s.state[mover] = MOVE_INSIDE
    s.x[mover], s.y[mover] = s.x[group[-1]], s.y[group[-1]] + 1.05
    run.step()
    assert s.state[mover] == (JOINED if stale == 0 else MOVE_INSIDE)


def test_the_start_rule_lets_one_rim_robot_go_at_a_time():
    run = rubenstein(square(8), 150, startup_ticks=50, seed=5)
    s = run.robots
    began_any = 0
    for _ in range(1500):
        moving_before = np.flatnonzero((s.state == MOVE_OUTSIDE) | (s.state == MOVE_INSIDE))
        x, y = s.x.copy(), s.y.copy()
        run.step()
        new = np.flatnonzero(s.began == run.tick)
        began_any += new.size
        for i in new:
            near = np.hypot(x - x[i], y - y[i]) < run.params.comm_range
            near[i] = False
            assert not near[moving_before].any()  # no robot in range was moving
            assert not near[new].any()  # and none in range began with it
    assert began_any >= 5


def test_every_tick_of_a_run_keeps_what_check_checks():
    """No overlap ever, joined robots stay put with their gradient and estimate, stationary robots do not move and
    movers step at most a step: every tick of a whole run, by the checks ``simulate --check`` runs."""
    run = rubenstein(square(6), 40, seed=1)
    while not run.done:
        prev, covered = snapshot(run), run.metrics["covered"]
        run.step()
        check_tick(prev, covered, run)
    assert run.outcome.value in ("complete", "complete_with_extras")


def _damaged(what: str) -> tuple[RubensteinRun, object, float]:
    """A run past its first joins, one tick stepped, then ``what`` broken in its robots (before, after, covered)."""
    run = rubenstein(square(6), 40, seed=1)
    run.run(3000)
    prev, covered = snapshot(run), run.metrics["covered"]
    run.step()
    s = run.robots
    joined = int(np.flatnonzero((prev.state == JOINED) & (np.arange(40) >= 4))[0])
    mover = int(np.flatnonzero((prev.state == MOVE_OUTSIDE) | (prev.state == MOVE_INSIDE))[0])
    waiting = int(np.flatnonzero(prev.state == WAIT)[0])
    if what == "joined moved":
        s.x[joined] += 0.01
    elif what == "joined forgot":
        s.g[joined] += 1
    elif what == "leapt":
        s.x[mover] += 0.2
    elif what == "stationary moved":
        s.y[waiting] -= 0.01
    elif what == "back to start":
        s.state[mover] = START
    elif what == "unknown state":
        s.state[waiting] = 9
    elif what == "overlap":  # a waiting robot that was, and is, half a diameter from a joined one
        for robots in (prev, s):
            robots.x[waiting], robots.y[waiting] = s.x[joined] + 0.5, s.y[joined]
    return run, prev, covered


@pytest.mark.parametrize(
    "what,rule",
    [
        ("joined moved", "joined robot \\[\\d+\\] changed its x"),
        ("joined forgot", "joined robot \\[\\d+\\] changed its g"),
        ("leapt", "stepped \\[0\\.\\d+\\] d, more than a step"),
        ("stationary moved", "stationary robot \\[\\d+\\] moved"),
        ("back to start", "went back to start"),
        ("unknown state", "a state code outside"),
        ("overlap", "robots \\[\\[\\d+, \\d+\\]\\] overlap"),
    ],
)
def test_the_tick_checks_name_each_broken_rule(what, rule):
    run, prev, covered = _damaged(what)
    with pytest.raises(InvariantError, match=f"tick {run.tick}: .*{rule}"):
        check_tick(prev, covered, run)


def test_a_small_solid_shape_completes_and_covers_every_pixel():
    run = rubenstein(square(6), 40, seed=1)
    run.run()
    assert run.outcome.value in ("complete", "complete_with_extras")  # the left-over robots edge-follow on
    m = run.metrics
    assert m["covered"] == run.pixels == 36
    assert m["loc_error"] < 0.1


def test_too_few_robots_leave_the_shape_incomplete_once_every_robot_has_joined():
    run = rubenstein(square(6), 20, seed=1)
    run.run()
    assert run.outcome.value == "incomplete"
    assert run.metrics["joined"] == 20 and run.metrics["covered"] < run.pixels


def test_the_shape_frame_finds_a_holes_pixels_and_no_hole_in_an_open_notch():
    assert ShapeFrame.of(ring(9, 3), 1.2).holes.sum() == 9 and ShapeFrame.of(square(6), 1.2).holes.sum() == 0
    notch = np.ones((6, 6), dtype=bool)
    notch[2:4, 2:] = False  # open to the right: outside, not a hole
    frame = ShapeFrame.of(Shape.from_grid(notch, World(), name="notch", source="test"), 1.2)
    assert frame.holes.sum() == 0


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_shape_with_a_hole_ends_with_its_hole_measured_robots_stop_at_the_rim(seed):
    """A 9 x 9 square with a 3 x 3 hole, one robot per pixel: the run ends (documented outcomes only), and how
    much of the hole the joined robots' discs fill is measured. Robots that reach the hole's rim stop there,
    their centres at most a tenth of d inside it, so they fill a band of it and no robot stands deeper in
    it. ``hole_filled`` is checked against the same area sampled independently, on a finer grid."""
    run = rubenstein(ring(9, 3), 72, seed=seed)
    run.run(100_000)
    assert run.outcome is not None and run.outcome.value != "timeout"
    s, frame = run.robots, run.frame
    joined = s.state == JOINED
    x0, x1 = frame.x0 + 3 * frame.pixel, frame.x0 + 6 * frame.pixel  # the hole's columns 3-5, rows 3-5
    y0, y1 = frame.y0 + 3 * frame.pixel, frame.y0 + 6 * frame.pixel
    inside = joined & (s.x > x0) & (s.x < x1) & (s.y > y0) & (s.y < y1)
    depth = np.minimum.reduce([s.x - x0, x1 - s.x, s.y - y0, y1 - s.y])[inside]
    assert depth.size == 0 or depth.max() < 0.1
    g = (np.arange(40) + 0.5) / 40
    px, py = np.meshgrid(x0 + g * (x1 - x0), y0 + g * (y1 - y0))
    near = np.hypot(px.ravel()[:, None] - s.x[joined], py.ravel()[:, None] - s.y[joined]).min(axis=1)
    by_hand = float(np.mean(near < 0.5))
    summary = summary_of(run, 0.0)
    assert 0.0 < summary["hole_filled"] == hole_filled(run) < 0.5
    assert abs(summary["hole_filled"] - by_hand) < 0.03


def test_the_same_seed_gives_the_same_run_and_step_equals_run():
    a, b = rubenstein(square(6), 40, seed=4), rubenstein(square(6), 40, seed=4)
    a.run(700)
    for _ in range(700):
        b.step()
    assert np.array_equal(a.history, b.history)
    for name in a.robots._fields:
        assert np.array_equal(getattr(a.robots, name), getattr(b.robots, name)), name
    c = rubenstein(square(6), 40, seed=5)
    c.run(700)
    assert not np.array_equal(a.robots.x, c.robots.x)


def test_the_shape_frame_puts_the_lowest_row_on_the_x_axis_centred():
    frame = ShapeFrame.of(square(6), 1.5)
    assert frame.extent == (-1.0, 0.0, 8.0, 9.0)  # the seeds at its lower-left corner
    assert (
        frame.inside(np.array([0.0, 0.0, 8.1, -1.1]), np.array([0.5, -0.1, 1.0, 1.0])).tolist() == [True] + [False] * 3
    )


def test_parameters_of_the_other_algorithm_are_refused_in_one_line():
    with pytest.raises(ParameterError, match="comm_range is a parameter of the rubenstein algorithm"):
        RunParams(100, comm_range=4.0)
    with pytest.raises(ParameterError, match="vision_radius is a parameter of the darr-niazi algorithm"):
        RunParams(100, algorithm="rubenstein", vision_radius=2.0)
    with pytest.raises(ParameterError, match="desired_distance < gradient_range"):
        RunParams(100, algorithm="rubenstein", desired_distance=1.6)
    with pytest.raises(ParameterError, match="comm_range must be at least 1 . step_length"):
        RunParams(
            100,
            algorithm="rubenstein",
            comm_range=1.4,
            gradient_range=1.2,
            desired_distance=1.1,
            yield_distance=1.3,
            step_length=0.5,
        )
    with pytest.raises(ParameterError, match="yield_distance must be below comm_range"):
        RunParams(100, algorithm="rubenstein", yield_distance=3.6)
    with pytest.raises(ParameterError, match="2D shapes only"):
        Settings(shape="box", algorithm="rubenstein").resolve()
    p = RunParams(100, algorithm="rubenstein")
    assert RunParams(**p.as_dict()) == p  # a summary's parameters, rule set resolved, read back


def test_the_state_codes_start_as_documented():
    run = rubenstein(square(6), 30)
    s = run.robots
    assert (s.state[:4] == JOINED).all() and (s.state[4:] == START).all()
    assert s.g[:4].tolist() == [0, 1, 1, 1] and (s.g[4:] == UNKNOWN_G).all()
    assert (s.began == NEVER).all() and WAIT == 1


def test_simulate_check_runs_the_tick_checks_after_every_tick(tmp_path, monkeypatch):
    from swarm_ros.app import cli
    from swarm_ros.core.rubenstein import tick_checks

    checked = []
    real = tick_checks.check_tick

    def spy(prev, covered, run):
        checked.append(run.tick)
        real(prev, covered, run)

    monkeypatch.setattr(tick_checks, "check_tick", spy)
    grid = tmp_path / "square.txt"
    grid.write_text("######\n" * 6)
    flags = ["--algorithm", "rubenstein", "--shape", str(grid), "--robots", "40", "--max-ticks", "300"]
    assert cli.main(["simulate", *flags, "--check", "--quiet", "--no-recording", "--out", str(tmp_path / "r")]) == 0
    assert checked == list(range(1, 301))


@pytest.mark.parametrize("algorithm", ["darr-niazi", "rubenstein"])
def test_every_algorithm_takes_at_most_one_robot_a_free_patch_of_its_world(algorithm):
    """One bound for both (Shape.check_room, called from check_run): the rubenstein pack no longer grows without
    limit (100,000 robots stood 332 d from a 32-patch world's centre)."""
    Settings(shape="star", algorithm=algorithm).updated(robots=3969).resolve()  # 63 x 63 free patches: fits
    with pytest.raises(ParameterError, match=r"star\.txt: 3970 robots do not fit on the 3969 free patches"):
        Settings(shape="star", algorithm=algorithm).updated(robots=3970).resolve()


def test_a_swarm_larger_than_the_memory_available_is_refused_before_anything_is_made(monkeypatch):
    from swarm_ros.core import resources

    monkeypatch.setattr(resources, "available_memory", lambda: 500 * 1024)  # 500 KiB free
    Settings(shape="star", robots=1000).resolve()  # 1,000 x 250 bytes: fits
    with pytest.raises(ParameterError, match=r"1,000 robots need about 0\.6 MiB under rubenstein \(600 bytes each\)"):
        Settings(shape="star", robots=1000, algorithm="rubenstein").resolve()
    monkeypatch.setattr(resources, "available_memory", lambda: None)  # not Linux: nothing to go by
    Settings(shape="star", robots=1000, algorithm="rubenstein").resolve()


def test_a_rubenstein_run_directory_is_named_without_a_vision_radius():
    from datetime import datetime

    from swarm_ros.artifacts.run_dir import default_run_dir

    at = datetime(2026, 11, 28, 14, 0, 0)
    assert default_run_dir("star", RunParams(1036, seed=1), at).name == "20261128-140000_star_n1036_v1_s1"
    rb = RunParams(1036, seed=2, algorithm="rubenstein")
    assert default_run_dir("star", rb, at).name == "20261128-140000_star_n1036_rubenstein_s2"
