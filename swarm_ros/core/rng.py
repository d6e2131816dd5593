"""Counter-based randomness: every draw is a pure function of (seed, robot, tick, stream).

A robot's random numbers at a tick do not depend on which process hosts it, on how
many other robots there are, or on the order in which robots are processed, so any
split of the swarm over processes gives the same run. Draws are made by chaining the
SplitMix64 finaliser (Steele, Lea & Flood, "Fast splittable pseudorandom number
generators", OOPSLA 2014) over the four keys; the result's top 53 bits give a float
in [0, 1).
"""

from __future__ import annotations

import numba
import numpy as np

# Independent streams a robot draws from within one tick.
STREAM_WIGGLE = 0  #: heading change while wandering
STREAM_TURN = 1  #: new heading after a blocked step
STREAM_PRIORITY = 2  #: lottery ticket when several robots claim one patch
STREAM_PLACE_X = 3  #: x offset within the start patch (tick 0)
STREAM_PLACE_Y = 4  #: y offset within the start patch (tick 0)
STREAM_PLACE_HEADING = 5  #: start heading (tick 0)
STREAM_FAIL = 6  #: which robots fail at the failure tick (``RunParams.fail_fraction``)
# ``steps: literal`` makes up to three Move calls and two turns a tick; the first of each
# uses STREAM_WIGGLE / STREAM_TURN, the others these.
STREAM_WIGGLE_2 = 7  #: second wiggle of a tick
STREAM_WIGGLE_3 = 8  #: third wiggle of a tick
STREAM_TURN_2 = 9  #: second random turn of a tick
# 3D only: a place's z, and a heading's second angle.
STREAM_PLACE_Z = 10  #: z offset within the start voxel (tick 0)
STREAM_PLACE_PITCH = 11  #: start heading's elevation (tick 0)
#: A 3D heading change draws two numbers: the angle from the old heading, from the stream the 2D rule
#: uses, and the direction it turns towards, from that stream + SPIN (so 3D draws never reuse 2D ones).
SPIN = 16

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0  # 2**-53


@numba.njit(cache=True, inline="always")
def _mix(z: np.uint64) -> np.uint64:
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@numba.njit(cache=True, inline="always")
def draw_bits(seed: int, robot: int, tick: int, stream: int) -> np.uint64:
    """64 random bits for (seed, robot, tick, stream)."""
    z = _mix(np.uint64(seed) + _GOLDEN)
    z = _mix(z ^ np.uint64(robot))
    z = _mix(z ^ np.uint64(tick))
    return _mix(z ^ np.uint64(stream))


@numba.njit(cache=True, inline="always")
def draw_uniform(seed: int, robot: int, tick: int, stream: int) -> float:
    """A float in [0, 1) for (seed, robot, tick, stream)."""
    return float(draw_bits(seed, robot, tick, stream) >> _S11) * _INV53


@numba.njit(cache=True)
def uniform_array(seed: int, robots: np.ndarray, tick: int, stream: int) -> np.ndarray:
    """Vector form of :func:`draw_uniform` over robot ids (used at set-up and in tests)."""
    out = np.empty(robots.size, dtype=np.float64)
    for k in range(robots.size):
        out[k] = draw_uniform(seed, robots[k], tick, stream)
    return out
