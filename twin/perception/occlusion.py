"""Where a box of known size stands when the camera sees only part of it.

A cube half hidden behind something taller (the warehouse's unmodelled box, the obstacle wall) leaves a
cluster of its visible part only: the centre of that part's footprint lies up to half a side off the
cube's centre, and a gripper sent there closes on a corner or on nothing. Two facts pin the box down all
the same, and a real cell has both: every visible point of the cluster lies on the box, and every table
point the camera saw is a ray from the camera that passed through no box ("free space"). Where the table
is seen beside the visible part, the box cannot reach; where it is hidden, it may. Among the poses of the
box (centre and yaw, standing on the table) that contain the visible points, the fit takes the one that
the seen rays run through the least (summed over the rays, in metres), plus how far it leaves visible
points outside.

Scored on a grid (coarse, then fine around the best) of the centres that keep the visible points inside,
per yaw; plain numpy over the rays near the cluster, run only for clusters too small to be the whole box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PARTIAL_VIEW_TOL_M", "BoxFit", "fit_partly_seen_box"]

# a cluster whose footprint is this much shorter (or narrower) than the object it is of is that object seen
# only in part: the footprint of a whole one is its size within a few mm of depth noise
PARTIAL_VIEW_TOL_M = 0.008

_COARSE_YAW = np.radians(6.0)
_FINE_YAW = np.radians(0.5)
_COARSE_STEP_M = 0.004
_FINE_STEP_M = 0.001
_INSIDE_TOL_M = 0.004  # a visible point this far outside the box (depth noise) still lies on it
_RAY_MARGIN_M = 0.008  # a seen ray ends this far before its point: its point may lie on the box's face
_TABLE_BAND_M = 0.008  # table points: within this of the table plane (higher ones may lie on a box face)
_THROUGH_M = 0.002  # a ray through the box for less than this grazes it (the grid's step, the noise)
_TIE_M = 1e-4  # poses whose rays inside and points outside add up to within this are as good
_KEEP_PCT = 0.5  # the box's place is bounded by all but this percentile of the visible points at each side
_CHUNK = 256  # candidate centres scored at once
_MAX_POINTS = 1000  # the visible points scored at most (the bounds of the box's place come from all)
_MAX_RAYS = 3000  # the seen rays scored at most: a wrist camera sees ~50 000 table points around a bottle


@dataclass(frozen=True)
class BoxFit:
    """The box's centre (x, y) on the table and yaw (rad); `free_rays_through`: seen rays it blocks;
    `points_outside`: visible points it leaves out; `shift_m`: how far the centre moved from the visible
    part's footprint centre."""

    center_xy: np.ndarray
    yaw: float
    free_rays_through: int
    points_outside: int
    shift_m: float


def fit_partly_seen_box(
    points: np.ndarray,
    size_xy: tuple[float, float],
    height_m: float,
    table_z: float,
    camera_origin: np.ndarray,
    table_points: np.ndarray,
    start_xy: np.ndarray,
) -> BoxFit:
    """Fit a box of `size_xy` (length, width) m and `height_m`, standing on the table at `table_z`, to the
    visible `points` (n, 3) of it; `table_points` (m, 3): table points the camera at `camera_origin` (3,)
    saw (all in one frame, z up); `start_xy`: the visible part's footprint centre (`shift_m` is measured
    from it). For each yaw only the centres that keep the visible points inside the box (all but the
    outermost 1 %, give or take the noise) are scored."""
    pts = np.asarray(points, dtype=float)
    o = np.asarray(camera_origin, dtype=float)
    half = np.array([size_xy[0] / 2, size_xy[1] / 2, height_m / 2])
    start = np.asarray(start_xy, dtype=float)
    reach = float(np.hypot(half[0], half[1])) + float(np.linalg.norm(pts[:, :2] - start, axis=1).max())
    rays = _rays_near(o, np.asarray(table_points, dtype=float), table_z, height_m, start, reach)
    rays = rays[:: -(-len(rays) // _MAX_RAYS) or 1]  # evenly thinned (in the image's order): a few mm apart
    ends = rays - _RAY_MARGIN_M * (rays - o) / np.maximum(np.linalg.norm(rays - o, axis=1, keepdims=True), 1e-9)
    period = np.pi / 2 if abs(size_xy[0] - size_xy[1]) < 1e-9 else np.pi
    coarse = _search(pts, ends, o, half, table_z, np.arange(0.0, period, _COARSE_YAW), _COARSE_STEP_M)
    yaws = coarse[1] + np.arange(-_COARSE_YAW, _COARSE_YAW + 1e-9, _FINE_YAW)
    c, yaw, through, outside = _search(
        pts, ends, o, half, table_z, yaws, _FINE_STEP_M, near=(coarse[0], 1.5 * _COARSE_STEP_M)
    )
    return BoxFit(c, float(yaw % period), through, outside, float(np.linalg.norm(c - start)))


def _rays_near(o: np.ndarray, table: np.ndarray, table_z: float, h: float, c: np.ndarray, r: float) -> np.ndarray:
    """The table points (k, 3) on the table plane whose ray, where it runs lower than the box's top,
    passes within `r` of `c` in x, y: only those can pass through a box near c."""
    p = table[np.abs(table[:, 2] - table_z) < _TABLE_BAND_M]
    if len(p) == 0:
        return p
    # where the ray from o to p comes down to the box's top: o + s (p - o) at z = table_z + h
    s = np.clip((o[2] - (table_z + h)) / np.maximum(o[2] - p[:, 2], 1e-9), 0.0, 1.0)
    a = o[:2] + s[:, None] * (p[:, :2] - o[:2])
    ab = p[:, :2] - a
    t = np.clip(np.einsum("ij,ij->i", c - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0.0, 1.0)
    d = np.linalg.norm(a + t[:, None] * ab - c, axis=1)
    return p[d < r]


def _centres(
    lo_q: np.ndarray, hi_q: np.ndarray, half: np.ndarray, step: float, near: tuple[np.ndarray, float] | None
) -> np.ndarray:
    """(c, 2) candidate centres, in the box's axes, of a box that holds the visible points spanning `lo_q` to
    `hi_q` (2,) in the box's axes: a grid over the interval each axis allows (the middle when the points spread
    wider than the box), within `near` (centre (2,) in the box's axes, half width) when given."""
    axes = []
    for k in range(2):
        lo, hi = hi_q[k] - half[k] - _INSIDE_TOL_M, lo_q[k] + half[k] + _INSIDE_TOL_M
        if near is not None:
            lo, hi = max(lo, near[0][k] - near[1]), min(hi, near[0][k] + near[1])
        axes.append(np.arange(lo, hi + 1e-9, step) if hi > lo else np.array([(lo + hi) / 2]))
    gu, gv = np.meshgrid(axes[0], axes[1], indexing="ij")
    return np.column_stack([gu.ravel(), gv.ravel()])


def _search(
    pts: np.ndarray,
    ends: np.ndarray,
    o: np.ndarray,
    half: np.ndarray,
    table_z: float,
    yaws: np.ndarray,
    step: float,
    *,
    near: tuple[np.ndarray, float] | None = None,
) -> tuple[np.ndarray, float, int, int]:
    """The best (centre (2,), yaw, rays through, points outside) over `yaws` and, for each, the centres
    `_centres` allows (within `near`: a centre (2,) and half width, when given): the least run of rays inside and
    points outside; of poses as good, the one whose centre is nearest the middle of theirs."""
    zc = table_z + half[2]
    found: list[tuple[np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]] = []  # per yaw: centres, scores
    turns = [np.array([[np.cos(y), np.sin(y)], [-np.sin(y), np.cos(y)]]) for y in yaws]  # world x, y -> box axes
    seen = [pts[:, :2] @ R.T for R in turns]
    # the points' span in the box's axes, all but the outermost `_KEEP_PCT` % at each side
    spans = [np.percentile(q, [_KEEP_PCT, 100.0 - _KEEP_PCT], axis=0) for q in seen]
    fits = [bool(np.all(hi - lo <= 2.0 * (half[:2] + _INSIDE_TOL_M))) for lo, hi in spans]
    for yaw, R, q, (lo_q, hi_q), holds in zip(yaws, turns, seen, spans, fits, strict=True):
        if any(fits) and not holds:  # the points spread wider than the box at this yaw: not its yaw
            continue
        cq = _centres(lo_q, hi_q, half, step, None if near is None else (R @ near[0], near[1]))
        q = q[:: -(-len(q) // _MAX_POINTS) or 1]  # scored on an even sample of the points
        # how far each visible point lies outside the box (scored from the box's faces, so that noise
        # either side centres it; counted beyond the noise)
        beyond = np.maximum(np.abs(q[None, :, :] - cq[:, None, :]) - half[:2], 0.0).max(axis=2)
        outside = (beyond > _INSIDE_TOL_M).sum(axis=1)
        if len(ends):
            through, depth = _rays_through(o, ends, R, cq, half, zc)
        else:
            through, depth = np.zeros(len(cq), dtype=int), np.zeros(len(cq))
        found.append((cq @ R, depth + beyond.sum(axis=1), float(yaw), through, outside))
    # the poses that explain the view equally well, over every yaw: the one nearest their middle (a view
    # that leaves the box some freedom, in a shadow no one sees into, gets the least wrong guess)
    least = min(float(score.min()) for _, score, _, _, _ in found) + _TIE_M
    tied = np.concatenate([c[score <= least] for c, score, _, _, _ in found])
    mid = tied.mean(axis=0)
    best: tuple[float, np.ndarray, float, int, int] | None = None
    for c, score, yaw, through, outside in found:
        for k in np.flatnonzero(score <= least):
            d = float(np.linalg.norm(c[k] - mid))
            if best is None or d < best[0]:
                best = (d, c[k], yaw, int(through[k]), int(outside[k]))
    assert best is not None
    return best[1], best[2], best[3], best[4]


def _rays_through(
    o: np.ndarray, ends: np.ndarray, R: np.ndarray, cq: np.ndarray, half: np.ndarray, zc: float
) -> tuple[np.ndarray, np.ndarray]:
    """How many segments o -> ends (k, 3) pass through each box (centres `cq` (c, 2) in the box axes that
    R (2, 2) maps to, half extents `half`, centre height `zc`) for more than `_THROUGH_M`, and how far they
    run inside it in all (m): the slab test."""
    oq = R @ o[:2]
    dq = (ends[:, :2] - o[:2]) @ R.T  # (k, 2) directions in the box axes
    dz = ends[:, 2] - o[2]
    length = np.linalg.norm(ends - o, axis=1)[None, :]
    counts = np.zeros(len(cq), dtype=int)
    depth = np.zeros(len(cq))
    with np.errstate(divide="ignore", invalid="ignore"):
        tz1 = (zc - half[2] - o[2]) / dz  # the z slab is the same for every candidate
        tz2 = (zc + half[2] - o[2]) / dz
        z_lo = np.maximum(np.minimum(tz1, tz2), 0.0)[None, :]
        z_hi = np.minimum(np.maximum(tz1, tz2), 1.0)[None, :]
        for j in range(0, len(cq), _CHUNK):
            c = cq[j : j + _CHUNK]
            lo, hi = z_lo, z_hi
            for ax in range(2):
                d = dq[None, :, ax]
                t1 = (c[:, None, ax] - half[ax] - oq[ax]) / d
                t2 = (c[:, None, ax] + half[ax] - oq[ax]) / d
                lo = np.maximum(lo, np.minimum(t1, t2))
                hi = np.minimum(hi, np.maximum(t1, t2))
            inside = np.maximum(hi - lo, 0.0) * length  # how far each ray runs inside the box
            counts[j : j + _CHUNK] = (inside > _THROUGH_M).sum(axis=1)
            depth[j : j + _CHUNK] = inside.sum(axis=1)
    return counts, depth
