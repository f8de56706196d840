"""Nearest neighbour for the compiled search: a k-d tree over each tree's nodes, rebuilt as the tree grows, with
the nodes added since the last build scanned linearly.

Why: a linear scan costs ~1 ns a node and joint; at the 20 000-40 000 nodes a narrow passage (MotionBenchMaker's
cage) needs, it was most of an iteration. A k-d tree answers in ~log n; rebuilding it whenever the unindexed tail
exceeds a quarter of the indexed nodes (and 64) costs O(log n) per node added, amortised. The answer is exact
(the same nearest node as the scan, ties aside), so the search does not depend on when the index was built.

Layout: one `Index` per search, arrays with a leading axis for the two trees: idx (2, capacity) the node order
of the build; per k-d node lo, hi (range of idx), dim, split, left, right (-1: a leaf); built (2,) how many nodes
of each tree the index holds; then work arrays (the build's and the query's stacks, the build's bounds), so that
`nearest` and `refresh` allocate nothing and run without numba's runtime (`_nrt=False`, as the sphere kernels:
with it, every array taken out of the index tuple was reference-counted by an atomic call, per query).
"""

from __future__ import annotations

import numpy as np

from twin.plugin import no_runtime_njit

__all__ = ["LEAF", "nearest", "new_index", "refresh"]

LEAF = 16  # most nodes in a k-d leaf
_STACK = 256  # deepest query stack: far more than the depth of a tree of 2^40 nodes


def new_index(capacity: int) -> tuple[np.ndarray, ...]:
    """An empty index for trees of up to `capacity` nodes: (idx, lo, hi, dim, split, left, right, built, and the
    work arrays: the build's stack (3, m) and bounds (2, 6), the query's stack of nodes and distances)."""
    m = 4 * (capacity // LEAF + 2)
    return (
        np.zeros((2, capacity), dtype=np.int64),
        np.zeros((2, m), dtype=np.int64),
        np.zeros((2, m), dtype=np.int64),
        np.zeros((2, m), dtype=np.int64),
        np.zeros((2, m)),
        np.full((2, m), -1, dtype=np.int64),
        np.full((2, m), -1, dtype=np.int64),
        np.zeros(2, dtype=np.int64),
        np.zeros((3, m), dtype=np.int64),
        np.zeros((2, 6)),
        np.zeros(_STACK, dtype=np.int64),
        np.zeros(_STACK),
    )


@no_runtime_njit()
def _build(pts: np.ndarray, n: int, index: tuple, t: int) -> None:  # type: ignore[type-arg]
    """Index the first n points (columns of pts (6, capacity)) of tree t: split at the middle of the widest
    coordinate's spread until leaves hold at most LEAF points."""
    idx, lo_, hi_, dim_, split_, left_, right_, built = index[:8]
    idx, lo_, hi_, dim_, split_, left_, right_ = idx[t], lo_[t], hi_[t], dim_[t], split_[t], left_[t], right_[t]
    for i in range(n):
        idx[i] = i
    stack, bounds = index[8], index[9]
    st_node, st_lo, st_hi, mn, mx = stack[0], stack[1], stack[2], bounds[0], bounds[1]
    sp = 1
    st_node[0], st_lo[0], st_hi[0] = 0, 0, n
    count = 1
    while sp > 0:
        sp -= 1
        node, lo, hi = st_node[sp], st_lo[sp], st_hi[sp]
        lo_[node], hi_[node] = lo, hi
        if hi - lo <= LEAF:
            left_[node] = -1
            continue
        for j in range(6):
            mn[j], mx[j] = np.inf, -np.inf
        for k in range(lo, hi):
            for j in range(6):
                v = pts[j, idx[k]]
                mn[j] = min(mn[j], v)
                mx[j] = max(mx[j], v)
        d = 0
        for j in range(1, 6):
            if mx[j] - mn[j] > mx[d] - mn[d]:
                d = j
        split = 0.5 * (mn[d] + mx[d])
        i, k = lo, hi - 1
        while i <= k:
            if pts[d, idx[i]] < split:
                i += 1
            else:
                idx[i], idx[k] = idx[k], idx[i]
                k -= 1
        if i in (lo, hi):  # every point equal in d (so in all): any split keeps the pruning exact
            i = (lo + hi) // 2
        dim_[node], split_[node] = d, split
        left_[node], right_[node] = count, count + 1
        st_node[sp], st_lo[sp], st_hi[sp] = count, lo, i
        st_node[sp + 1], st_lo[sp + 1], st_hi[sp + 1] = count + 1, i, hi
        sp += 2
        count += 2
    built[t] = n


@no_runtime_njit()
def refresh(pts: np.ndarray, n: int, index: tuple, t: int) -> None:  # type: ignore[type-arg]
    """Rebuild tree t's index when the nodes added since its build outnumber a quarter of it (and 64)."""
    built = index[7][t]
    if n - built > max(64, built // 4):
        _build(pts, n, index, t)


@no_runtime_njit()
def nearest(pts: np.ndarray, n: int, index: tuple, t: int, q: np.ndarray) -> int:  # type: ignore[type-arg]
    """The node of tree t (the first n columns of pts (6, capacity)) nearest to q (6,), joint-space L2."""
    idx, lo_, hi_, dim_, split_, left_, right_, built = index[:8]
    idx, lo_, hi_, dim_, split_, left_, right_ = idx[t], lo_[t], hi_[t], dim_[t], split_[t], left_[t], right_[t]
    nb = built[t]
    best, best_d = -1, np.inf
    for i in range(nb, n):  # the tail added since the build
        d = 0.0
        for j in range(6):
            e = pts[j, i] - q[j]
            d += e * e
        if d < best_d:
            best, best_d = i, d
    if nb == 0:
        return best
    st_node, st_d = index[10], index[11]
    sp = 1
    st_node[0], st_d[0] = 0, 0.0
    while sp > 0:
        sp -= 1
        node, dmin = st_node[sp], st_d[sp]
        if dmin >= best_d:
            continue
        if left_[node] < 0:
            for k in range(lo_[node], hi_[node]):
                i = idx[k]
                d = 0.0
                for j in range(6):
                    e = pts[j, i] - q[j]
                    d += e * e
                if d < best_d or (d == best_d and i < best):
                    best, best_d = i, d
            continue
        diff = q[dim_[node]] - split_[node]
        near, far = (left_[node], right_[node]) if diff < 0.0 else (right_[node], left_[node])
        st_node[sp], st_d[sp] = far, max(dmin, diff * diff)
        st_node[sp + 1], st_d[sp + 1] = near, dmin
        sp += 2
    return best
