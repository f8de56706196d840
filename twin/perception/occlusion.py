"""Where a box of known size stands when the camera sees only part of it.

A cube half hidden behind something taller (the warehouse's unmodelled box, the obstacle wall) leaves a
cluster of its visible part only: the centre of that part's footprint lies up to half a side off the
cube's centre, and a gripper sent there closes on a corner or on nothing. Two facts pin the box down all
the same, and a real cell has both: every visible point of the cluster lies on the box, and every table
point the camera saw is a ray from the camera that passed through no box ("free space"). Where the table
is seen beside the visible part, the box cannot reach; where it is hidden, it may. Among the poses of the
box (centre and yaw, standing on the table) that contain the visible points, the fit takes the one that
the fewest seen rays pass through, counting a visible point left outside the box as heavily.

Scored on a grid (coarse, then fine around the best); plain numpy over a few thousand rays near the
cluster, run only for clusters too small to be the whole box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BoxFit", "fit_partly_seen_box"]

_COARSE_YAW = np.radians(6.0)
_FINE_YAW = np.radians(1.5)
_COARSE_STEP_M = 0.004
_FINE_STEP_M = 0.001
_INSIDE_TOL_M = 0.004  # a visible point this far outside the box (depth noise) still lies on it
_RAY_MARGIN_M = 0.008  # a seen ray ends this far before its point: its point may lie on the box's face
_TABLE_BAND_M = 0.008  # table points: within this of the table plane (higher ones may lie on a box face)


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
    saw (all in one frame, z up); `start_xy`: the visible part's footprint centre, where the search is
    centred (a box's centre lies within half its diagonal of any of its points)."""
    pts = np.asarray(points, dtype=float)
    o = np.asarray(camera_origin, dtype=float)
    half = np.array([size_xy[0] / 2, size_xy[1] / 2, height_m / 2])
    reach = float(np.hypot(half[0], half[1]))
    rays = _rays_near(o, np.asarray(table_points, dtype=float), table_z, height_m, np.asarray(start_xy), 2 * reach)
    period = np.pi / 2 if abs(size_xy[0] - size_xy[1]) < 1e-9 else np.pi
    best = _search(pts, rays, o, half, table_z, start_xy, reach, np.arange(0.0, period, _COARSE_YAW), _COARSE_STEP_M)
    yaws = best[1] + np.arange(-_COARSE_YAW, _COARSE_YAW + 1e-9, _FINE_YAW)
    fine = _search(pts, rays, o, half, table_z, best[0], 1.5 * _COARSE_STEP_M, yaws, _FINE_STEP_M)
    c, yaw, through, outside = fine
    return BoxFit(c, float(yaw % period), through, outside, float(np.linalg.norm(c - np.asarray(start_xy))))


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


def _search(
    pts: np.ndarray,
    rays: np.ndarray,
    o: np.ndarray,
    half: np.ndarray,
    table_z: float,
    center: np.ndarray,
    span: float,
    yaws: np.ndarray,
    step: float,
) -> tuple[np.ndarray, float, int, int]:
    """The best (centre, yaw, rays through, points outside) over `yaws` and a square grid of centres
    within `span` of `center`; ties go to the middle of the tied centres (nearest to it)."""
    offsets = np.arange(-span, span + 1e-9, step)
    gx, gy = np.meshgrid(center[0] + offsets, center[1] + offsets, indexing="ij")
    centers = np.column_stack([gx.ravel(), gy.ravel()])
    zc = table_z + half[2]
    ends = rays - _RAY_MARGIN_M * (rays - o) / np.linalg.norm(rays - o, axis=1, keepdims=True)
    best: tuple[float, np.ndarray, float, int, int] | None = None
    for yaw in yaws:
        cs, sn = np.cos(yaw), np.sin(yaw)
        R = np.array([[cs, sn], [-sn, cs]])  # world x, y -> the box's axes
        # visible points outside each candidate box (in the box's axes, by more than the noise)
        q = pts[:, :2] @ R.T
        cq = centers @ R.T
        out = (np.abs(q[None, :, 0] - cq[:, None, 0]) > half[0] + _INSIDE_TOL_M) | (
            np.abs(q[None, :, 1] - cq[:, None, 1]) > half[1] + _INSIDE_TOL_M
        )
        outside = out.sum(axis=1)
        through = _rays_through(o, ends, R, cq, half, zc) if len(ends) else np.zeros(len(centers), dtype=int)
        score = through + outside
        k = int(np.argmin(score))
        ties = np.flatnonzero(score == score[k])
        mid = centers[ties].mean(axis=0)
        k = int(ties[np.argmin(np.linalg.norm(centers[ties] - mid, axis=1))])
        key = float(score[k])
        if best is None or key < best[0]:
            best = (key, centers[k].copy(), float(yaw), int(through[k]), int(outside[k]))
    assert best is not None
    return best[1], best[2], best[3], best[4]


def _rays_through(
    o: np.ndarray, ends: np.ndarray, R: np.ndarray, cq: np.ndarray, half: np.ndarray, zc: float
) -> np.ndarray:
    """How many segments o -> ends (k, 3) pass through each box (centres `cq` (c, 2) in the box axes that
    R (2, 2) maps to, half extents `half`, centre height `zc`): the slab test."""
    oq = R @ o[:2]
    dq = (ends[:, :2] - o[:2]) @ R.T  # (k, 2) directions in the box axes
    dz = ends[:, 2] - o[2]
    counts = np.zeros(len(cq), dtype=int)
    with np.errstate(divide="ignore", invalid="ignore"):
        # z slab is the same for every candidate
        tz1 = (zc - half[2] - o[2]) / dz
        tz2 = (zc + half[2] - o[2]) / dz
        tz_lo, tz_hi = np.minimum(tz1, tz2), np.maximum(tz1, tz2)
        for j in range(0, len(cq), 256):
            c = cq[j : j + 256]
            lo, hi = np.maximum(tz_lo, 0.0)[None, :], np.minimum(tz_hi, 1.0)[None, :]
            for ax in range(2):
                d = dq[None, :, ax]
                t1 = (c[:, None, ax] - half[ax] - oq[ax]) / d
                t2 = (c[:, None, ax] + half[ax] - oq[ax]) / d
                lo = np.maximum(lo, np.minimum(t1, t2))
                hi = np.minimum(hi, np.maximum(t1, t2))
            counts[j : j + 256] = (lo <= hi).sum(axis=1)
    return counts
