"""RRT-Connect and path shortcutting wholly in compiled code (numba), on twin's planning model.

Why compiled: the search's own work (sampling, nearest neighbour, steering, tree bookkeeping) costs a few
microseconds an iteration in Python and nothing here; with the motion checks compiled too
(`twin.plugin.first_touch_on_motion`, the robot's sphere cover against the scene's primitives, each motion
proven free continuously by conservative advancement), one query is one call with no Python in its loop.

The search (`rrt_connect`): two trees, the start's and the goals' (every goal configuration a root); each
iteration samples a configuration uniformly inside the bounds, extends one tree by at most `step` (joint-space
L2) toward it and, when that extension is free, connects the other tree to the new node greedily (steps of at
most `step` while they are free). Two refinements VAMP's RRT-Connect uses (its defaults), both optional:
- tree balance: the trees take turns, except that a tree with at most 1/(1 + tree_ratio) of the other's
  nodes is extended again (tree_ratio 0: strict turns, as OMPL's RRTConnect);
- dynamic domain (Yershova, Sim and LaValle, 2005): a node whose extension failed gets a radius, and a sample
  farther from its nearest node than that radius is dropped before any check. Nodes on an obstacle's boundary
  stop drawing the samples of the whole Voronoi region behind them, which is what makes narrow passages
  (MotionBenchMaker's cage) slow. The radius starts at `radius`, shrinks by (1 - alpha) on each failure down
  to `min_radius`, and grows by (1 + alpha) on each success.
Nearest neighbour: a k-d tree over each tree's nodes, rebuilt as it grows (`twin_compiled.nearest`). The random
numbers are a xorshift64* stream seeded by the request's seed, so the same query and seed give the same path.

Shortcutting (`shortcut`): greedy vertex reduction (from each kept waypoint, the farthest later waypoint
reached by a free straight motion), then `tries` random shortcuts between two points on the path (a point
anywhere on a segment, not only a waypoint), each kept when free and shorter.

The search loop allocates nothing and is compiled without numba's runtime (`twin.plugin.no_runtime_njit`, as
the kernels it calls and `twin_compiled.nearest`), so no array it touches is reference-counted per iteration.

Work is bounded by `max_iterations` per call: the Python side (`twin_compiled.planner`) calls again until
its deadline, and the trees carry over, so where a search ends depends on the work done, not on the clock,
except at the time limit.
"""

from __future__ import annotations

import hashlib
import logging
import math
from pathlib import Path

import numpy as np
from numba import njit
from numba.core.caching import NullCache

from twin.plugin import (
    KERNEL_FINGERPRINT,
    first_flagged_motion,
    first_touch_on_motion,
    no_runtime_njit,
    sphere_evaluate,
)
from twin_compiled.nearest import nearest, refresh

__all__ = ["first_uncertified", "grown", "motion_free", "new_trees", "rrt_connect", "shortcut", "tree_path"]

_START, _GOAL = 0, 1
# the search's settings vector (`rrt_connect`)
_STEP, _RESOLUTION, _FLOOR, _RADIUS, _MIN_RADIUS, _ALPHA, _TREE_RATIO = range(7)


@no_runtime_njit()
def _next(rng: np.ndarray) -> float:
    """A uniform number in [0, 1) from the xorshift64* state rng[0] (uint64), advanced."""
    x = rng[0]
    x ^= x >> np.uint64(12)
    x ^= x << np.uint64(25)
    x ^= x >> np.uint64(27)
    rng[0] = x
    return float((x * np.uint64(2685821657736338717)) >> np.uint64(11)) / 9007199254740992.0


def new_trees(capacity: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Empty trees for `rrt_connect`: nodes (2, 6, capacity) (per tree a column per joint), parents
    (2, capacity), the nodes' dynamic-domain radii (2, capacity; inf: none yet), counts (2,), and the random
    state seeded from `seed` (never zero)."""
    nodes = np.empty((2, 6, capacity))
    parents = np.full((2, capacity), -1, dtype=np.int64)
    radii = np.full((2, capacity), np.inf)
    counts = np.zeros(2, dtype=np.int64)
    mixed = (int(seed) * 0x9E3779B97F4A7C15 + 0x2545F4914F6CDD1D) % (1 << 64)
    rng = np.array([mixed or 1], dtype=np.uint64)
    return nodes, parents, radii, counts, rng


def grown(
    nodes: np.ndarray, parents: np.ndarray, radii: np.ndarray, capacity: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The trees' arrays with room for `capacity` nodes each, their nodes kept."""
    n, p, r = np.empty((2, 6, capacity)), np.full((2, capacity), -1, dtype=np.int64), np.full((2, capacity), np.inf)
    n[:, :, : nodes.shape[2]] = nodes
    p[:, : parents.shape[1]] = parents
    r[:, : radii.shape[1]] = radii
    return n, p, r


@no_runtime_njit()
def _steer(nodes: np.ndarray, tree: int, i: int, target: np.ndarray, step: float, out: np.ndarray) -> bool:
    """out = the node i of `tree` moved toward target by at most `step` (L2); True when it reaches target."""
    d = 0.0
    for j in range(6):
        e = target[j] - nodes[tree, j, i]
        d += e * e
    d = math.sqrt(d)
    if d <= step:
        for j in range(6):
            out[j] = target[j]
        return True
    f = step / d
    for j in range(6):
        out[j] = nodes[tree, j, i] + f * (target[j] - nodes[tree, j, i])
    return False


@no_runtime_njit()
def _add(nodes: np.ndarray, parents: np.ndarray, counts: np.ndarray, tree: int, q: np.ndarray, parent: int) -> int:
    i = counts[tree]
    for j in range(6):
        nodes[tree, j, i] = q[j]
    parents[tree, i] = parent
    counts[tree] = i + 1
    return i


@no_runtime_njit()
def motion_free(K: tuple, S: tuple, a: np.ndarray, b: np.ndarray, resolution: float, floor: float) -> bool:  # type: ignore[type-arg]
    """Is the straight motion a -> b free in the planning model? resolution > 0: its configurations that far
    apart (max-abs joint step), coarse to fine, a assumed free; resolution <= 0: continuously (conservative
    advancement, a and b included; `floor` m from touching counts as touching)."""
    if resolution > 0.0:
        return first_flagged_motion(K, S, a, b, resolution) == 0
    return first_touch_on_motion(K, S, a, b, floor) < 0.0


@no_runtime_njit()
def _free(
    K: tuple,  # type: ignore[type-arg]
    S: tuple,  # type: ignore[type-arg]
    nodes: np.ndarray,
    tree: int,
    i: int,
    q: np.ndarray,
    resolution: float,
    floor: float,
    a: np.ndarray,
) -> bool:
    """Is the motion from node i of `tree` to q free (`motion_free`)?"""
    for j in range(6):
        a[j] = nodes[tree, j, i]
    return motion_free(K, S, a, q, resolution, floor)


@no_runtime_njit()
def rrt_connect(
    K: tuple,  # type: ignore[type-arg]
    S: tuple,  # type: ignore[type-arg]
    lo: np.ndarray,
    hi: np.ndarray,
    settings: np.ndarray,
    max_iterations: int,
    room: int,
    nodes: np.ndarray,
    parents: np.ndarray,
    radii: np.ndarray,
    counts: np.ndarray,
    index: tuple,  # type: ignore[type-arg]
    rng: np.ndarray,
    turn: np.ndarray,
    work: np.ndarray,
) -> tuple[int, int, int]:
    """Grow the trees (start tree 0 and goal tree 1, roots already added) for at most `max_iterations`
    iterations or until they connect. Returns (status, start-tree node, goal-tree node): status 1 connected
    (at those nodes, equal configurations), 0 not yet, -1 a tree has fewer than `room` free slots (what one
    iteration can add at most: the caller grows the arrays and calls again, and the search goes on exactly
    as it would have). settings: step, resolution (motions as `motion_free`), floor, the dynamic domain's
    radius (inf: off), min_radius and alpha, tree_ratio (module docstring). `turn[0]` is the tree extended
    last, carried between calls (1 before the first: the start tree goes first); `work` (4, 6): scratch."""
    capacity = nodes.shape[2]
    step, resolution, floor = settings[_STEP], settings[_RESOLUTION], settings[_FLOOR]
    radius, min_radius, alpha, ratio = settings[_RADIUS], settings[_MIN_RADIUS], settings[_ALPHA], settings[_TREE_RATIO]
    q_rand, q_new, q_next, a = work[0], work[1], work[2], work[3]
    for _ in range(max_iterations):
        if counts[0] + room > capacity or counts[1] + room > capacity:
            return -1, -1, -1
        last = turn[0]
        t = 1 - last
        if ratio > 0.0 and counts[last] * (1.0 + ratio) <= counts[t]:
            t = last  # the last tree is the smaller by far: extend it again
        o = 1 - t
        turn[0] = t
        for j in range(6):
            q_rand[j] = lo[j] + _next(rng) * (hi[j] - lo[j])
        near = nearest(nodes[t], counts[t], index, t, q_rand)
        r = radii[t, near]
        if r < np.inf:
            d = 0.0
            for j in range(6):
                e = q_rand[j] - nodes[t, j, near]
                d += e * e
            if d > r * r:
                continue  # outside the node's dynamic domain: no check spent on it
        _steer(nodes, t, near, q_rand, step, q_new)
        if not _free(K, S, nodes, t, near, q_new, resolution, floor, a):
            if radius < np.inf:
                radii[t, near] = radius if r == np.inf else max(r * (1.0 - alpha), min_radius)
            continue
        if r < np.inf:
            radii[t, near] = r * (1.0 + alpha)
        new = _add(nodes, parents, counts, t, q_new, near)
        refresh(nodes[t], counts[t], index, t)
        # connect the other tree to the new node, step by step while free
        m = nearest(nodes[o], counts[o], index, o, q_new)
        while counts[o] < capacity - 1:
            reached = _steer(nodes, o, m, q_new, step, q_next)
            if not _free(K, S, nodes, o, m, q_next, resolution, floor, a):
                break
            m = _add(nodes, parents, counts, o, q_next, m)
            refresh(nodes[o], counts[o], index, o)
            if reached:
                return (1, new, m) if t == _START else (1, m, new)
    return 0, -1, -1


@njit(cache=True, nogil=True)
def tree_path(nodes: np.ndarray, parents: np.ndarray, start_node: int, goal_node: int) -> np.ndarray:
    """(m, 6) waypoints: the start tree's root to start_node, then goal_node back to its goal root (the two
    nodes are the same configuration; it appears once)."""
    n0 = 0
    i = start_node
    while i >= 0:
        n0 += 1
        i = parents[0, i]
    n1 = 0
    i = parents[1, goal_node]
    while i >= 0:
        n1 += 1
        i = parents[1, i]
    out = np.empty((n0 + n1, 6))
    i = start_node
    for k in range(n0 - 1, -1, -1):
        for j in range(6):
            out[k, j] = nodes[0, j, i]
        i = parents[0, i]
    i = parents[1, goal_node]
    for k in range(n0, n0 + n1):
        for j in range(6):
            out[k, j] = nodes[1, j, i]
        i = parents[1, i]
    return out


@njit(cache=True, nogil=True)
def _length(path: np.ndarray, lo: int, hi: int) -> float:
    total = 0.0
    for i in range(lo, hi):
        d = 0.0
        for j in range(6):
            e = path[i + 1, j] - path[i, j]
            d += e * e
        total += math.sqrt(d)
    return total


@njit(cache=True, nogil=True)
def shortcut(
    K: tuple,  # type: ignore[type-arg]
    S: tuple,  # type: ignore[type-arg]
    path: np.ndarray,
    tries: int,
    resolution: float,
    floor: float,
    rng: np.ndarray,
) -> np.ndarray:
    """A shorter free path with the same ends (see the module docstring), motions checked as `motion_free`."""
    a = np.empty(6)
    b = np.empty(6)
    # greedy vertex reduction: from each kept waypoint, the farthest later one reached by a free motion
    kept = np.empty(path.shape[0], dtype=np.int64)
    nk = 0
    i = 0
    last = path.shape[0] - 1
    while True:
        kept[nk] = i
        nk += 1
        if i == last:
            break
        j = last
        while j > i + 1:
            a[:] = path[i]
            b[:] = path[j]
            if motion_free(K, S, a, b, resolution, floor):
                break
            j -= 1
        i = j
    cur = np.empty((nk, 6))
    for k in range(nk):
        cur[k] = path[kept[k]]
    # random shortcuts between two points anywhere on the path
    for _ in range(tries):
        n = cur.shape[0]
        if n < 3:
            break
        s1 = int(_next(rng) * (n - 1))
        s2 = int(_next(rng) * (n - 1))
        if s1 == s2:
            continue
        if s1 > s2:
            s1, s2 = s2, s1
        f1, f2 = _next(rng), _next(rng)
        for j in range(6):
            a[j] = cur[s1, j] + f1 * (cur[s1 + 1, j] - cur[s1, j])
            b[j] = cur[s2, j] + f2 * (cur[s2 + 1, j] - cur[s2, j])
        # old length between a and b, against the straight a -> b
        d_ab = 0.0
        d_a = 0.0
        d_b = 0.0
        for j in range(6):
            d_ab += (b[j] - a[j]) ** 2
            d_a += (cur[s1 + 1, j] - a[j]) ** 2
            d_b += (b[j] - cur[s2, j]) ** 2
        old = math.sqrt(d_a) + _length(cur, s1 + 1, s2) + math.sqrt(d_b)
        if math.sqrt(d_ab) >= old - 1e-9:
            continue
        # a lies between the configurations checked on its segment: checked itself (the motion check takes its
        # start as free), or a later proof of the path could start from a configuration it cannot leave
        if sphere_evaluate(K, S, a)[0] or not motion_free(K, S, a, b, resolution, floor):
            continue
        # cur[: s1 + 1], a, b, cur[s2 + 1 :] (a or b dropped where it is a waypoint already)
        keep_a = f1 > 1e-12
        keep_b = f2 < 1.0 - 1e-12
        m = (s1 + 1) + int(keep_a) + int(keep_b) + (n - s2 - 1)
        nxt = np.empty((m, 6))
        nxt[: s1 + 1] = cur[: s1 + 1]
        k = s1 + 1
        if keep_a:
            nxt[k] = a
            k += 1
        if keep_b:
            nxt[k] = b
            k += 1
        nxt[k:] = cur[s2 + 1 :]
        cur = nxt
    return cur


@njit(cache=True, nogil=True)
def first_uncertified(K: tuple, S: tuple, path: np.ndarray, floor: float) -> int:  # type: ignore[type-arg]
    """The first segment of `path` the continuous check does not prove free, or -1 when it proves them all."""
    a = np.empty(6)
    b = np.empty(6)
    for i in range(path.shape[0] - 1):
        a[:] = path[i]
        b[:] = path[i + 1]
        if first_touch_on_motion(K, S, a, b, floor) >= 0.0:
            return i
    return -1


def _flush_stale_cache() -> None:
    """Drop this module's numba cache when the planning model's kernels or the k-d tree changed since it was
    compiled: numba keys a cached function by its own file only, and these functions inline the code of
    those files."""
    functions = [f for f in globals().values() if hasattr(f, "_cache") and hasattr(f, "py_func")]
    nearest_file = Path(__file__).with_name("nearest.py")
    fingerprint = f"{KERNEL_FINGERPRINT}-{hashlib.sha256(nearest_file.read_bytes()).hexdigest()[:16]}"
    try:
        stamp = Path(rrt_connect._cache._cache_path) / "twin_compiled.kernel"  # type: ignore[attr-defined]
        if stamp.exists() and stamp.read_text() == fingerprint:
            return
        for f in functions:
            f._cache.flush()
        stamp.write_text(fingerprint)
    except (AttributeError, OSError) as e:  # a numba without these internals, a read-only cache: compile anew
        logging.getLogger("twin").debug("twin_compiled: cache check failed (%r); compiling without the cache", e)
        for f in functions:
            f._cache = NullCache()


_flush_stale_cache()
