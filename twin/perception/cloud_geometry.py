"""Small point-cloud geometry shared by the pipelines: transforms, planes, PCA, rigid fits, trimmed ICP.

Plain numpy/scipy so the pieces are testable on synthetic data and the RoboCup ICP can follow MATLAB's
`pcregistericp` semantics (inlier ratio, tolerance on the change of translation and rotation), which
open3d's ICP does not offer. The one exception is `NearestNeighbors`, which answers exactly as scipy's
cKDTree does but asks open3d's nanoflann index when open3d is installed, because it is 2-3x faster
(ICP spends most of its time there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from twin.perception.open3d_import import load_open3d

__all__ = [
    "IcpResult",
    "NearestNeighbors",
    "Pca",
    "Plane",
    "fit_plane",
    "fit_plane_ransac",
    "kabsch",
    "pca",
    "rot_z",
    "transform_points",
    "trimmed_icp",
]


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, 3) points mapped by the (4, 4) transform T.

    A whole camera frame (~300k points) is multiplied in row blocks on the calling thread (see
    _MATVEC_ROWS): handed to OpenBLAS whole, the product went to its worker threads and took 40-110 ms a
    frame on a loaded 2-core machine instead of ~10 ms (1.0 s of a RoboCup run's 2.3 s of scene clouds).
    Each row is the same gemm kernel's product either way, bit for bit (tests/test_perception_speed.py);
    only a 1-row product takes numpy's other path, so no block is left with one row."""
    R, t = T[:3, :3].T, T[:3, 3]
    n = len(points)
    if n <= _MATVEC_ROWS or not _blockable(points, R, t):
        return points @ R + t
    out = np.empty((n, 3))
    blocks = _row_blocks(n, _MATVEC_ROWS)
    if blocks[-1].stop - blocks[-1].start == 1:  # fold a last single row into the block before it
        blocks[-2:] = [slice(blocks[-2].start, n)]
    for b in blocks:
        np.matmul(points[b], R, out=out[b])
    out += t
    return out


def _blockable(points: np.ndarray, R: np.ndarray, t: np.ndarray) -> bool:
    """float64 (n, 3) C-contiguous points and a float64 transform: what the blocked product takes as is."""
    return (
        isinstance(points, np.ndarray)
        and points.ndim == 2
        and points.shape[1] == 3
        and points.dtype == np.float64
        and points.flags.c_contiguous
        and R.dtype == np.float64
        and t.dtype == np.float64
    )


def rot_z(yaw: float) -> np.ndarray:
    """(3, 3) rotation about z."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class Plane:
    """The plane normal . x = offset (unit normal (3,)); `inliers` is a mask over the fitted points."""

    normal: np.ndarray
    offset: float
    inliers: np.ndarray

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (m) of (n, 3) points, positive on the normal's side."""
        return points @ self.normal - self.offset

    def oriented(self, towards: np.ndarray) -> Plane:
        """The same plane with its normal pointing to the side of point `towards`."""
        if float(np.dot(self.normal, towards) - self.offset) >= 0:
            return self
        return Plane(-self.normal, -self.offset, self.inliers)


def fit_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane through (n >= 3, 3) points: (unit normal, offset)."""
    c = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    n = vt[2]
    return n, float(n @ c)


# fit_plane_ransac's point-plane products in pieces of at most this many rows, which OpenBLAS computes on
# the calling thread (bigger ones go to its worker threads: for 3 columns that costs more than it saves,
# and the workers then spin for ~0.1 s, taking CPU from open3d's threads on a 2-core machine). Each row's
# product is the same computation either way: bit for bit the same numbers (the tests check).
_MATVEC_ROWS = 3000


def _row_blocks(n: int, rows: int) -> list[slice]:
    return [slice(start, min(start + rows, n)) for start in range(0, n, rows)]


def fit_plane_ransac(
    points: np.ndarray,
    threshold_m: float,
    *,
    iterations: int = 300,
    rng: np.random.Generator | None = None,
    refine: bool = True,
) -> Plane:
    """RANSAC plane (3-point hypotheses), then a least-squares refit on the inliers.

    The refit matters for calibration: the RANSAC hypothesis is only as good as 3 noisy points, the refit
    averages thousands.
    """
    if len(points) < 3:
        raise ValueError("a plane needs at least 3 points")
    rng = rng if rng is not None else np.random.default_rng(0)
    # Same draws, same arithmetic, same first-best rule as a plain loop over the hypotheses (see
    # tests/test_perception_speed.py), only cheaper: the points are copied once to a contiguous array
    # (products over a strided view such as cloud[::4] are twice as slow; the values are the same), the
    # cross products are taken for all hypotheses at once (element-wise, so bit for bit the same), the
    # distances go to reused buffers in row blocks (see _MATVEC_ROWS), and a hypothesis is dropped as soon
    # as its count plus the points not yet looked at cannot beat the best count: it would lose anyway (on
    # the RoboCup table frames the average hypothesis is dropped after ~40 % of the points).
    pts = np.ascontiguousarray(points)
    best_count, best = -1, (np.array([0.0, 0.0, 1.0]), 0.0)
    idx = rng.integers(0, len(pts), size=(iterations, 3))
    normals = np.cross(pts[idx[:, 1]] - pts[idx[:, 0]], pts[idx[:, 2]] - pts[idx[:, 0]])
    dist = np.empty(len(pts), dtype=np.result_type(pts, normals))
    inside = np.empty(len(pts), dtype=bool)
    blocks = [  # (a block of rows, the row slices of its products)
        (b, [slice(b.start + c.start, b.start + c.stop) for c in _row_blocks(b.stop - b.start, _MATVEC_ROWS)])
        for b in _row_blocks(len(pts), 8 * _MATVEC_ROWS)
    ]
    for h in range(iterations):
        n = normals[h]
        norm = np.linalg.norm(n)
        if norm < 1e-12:
            continue
        n = n / norm
        d = float(n @ pts[idx[h, 0]])
        count = 0
        for b, parts in blocks:
            for c in parts:
                np.matmul(pts[c], n, out=dist[c])
            np.subtract(dist[b], d, out=dist[b])
            np.abs(dist[b], out=dist[b])
            np.less(dist[b], threshold_m, out=inside[b])
            count += int(np.count_nonzero(inside[b]))
            if count + len(pts) - b.stop <= best_count:
                break  # cannot beat the best any more
        if count > best_count:
            best_count, best = count, (n, d)
    n, d = best
    inl = np.abs(pts @ n - d) < threshold_m
    if refine and inl.sum() >= 3:
        n, d = fit_plane(pts[inl])
        inl = np.abs(pts @ n - d) < threshold_m
    return Plane(n, d, inl)


@dataclass(frozen=True)
class Pca:
    """Principal axes of a point set: centroid (3,), eigenvalues (3,) descending, axes (3, 3) as columns."""

    centroid: np.ndarray
    eigenvalues: np.ndarray
    axes: np.ndarray


def pca(points: np.ndarray) -> Pca:
    """Sample covariance C = 1/N sum (p - mean)(p - mean)^T, eigen-decomposed (seed 002, eq. 1)."""
    c = points.mean(axis=0)
    C = (points - c).T @ (points - c) / max(len(points), 1)
    w, v = np.linalg.eigh(C)
    order = np.argsort(w)[::-1]
    return Pca(c, w[order], v[:, order])


def kabsch(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (3, 3) and translation t (3,) minimising sum |R src + t - dst|^2."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    H = (src - cs).T @ (dst - cd)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cd - R @ cs


class NearestNeighbors:
    """The nearest of fixed (n, 3) points to query points: `query` answers exactly as
    `scipy.spatial.cKDTree(points).query(x, distance_upper_bound=...)` (k = 1) does.

    With open3d installed the answers come from its nanoflann index (`open3d.core.nns`), 2-3x faster
    than cKDTree on this machine; both compute the squared distance the same way (the three squared
    differences summed in order), so distances and indices agree (to the last bit with these builds; a
    build that fuses multiply-adds may differ in it). Where they may not - two points at the same distance
    to 1e-12 (a tie, which the two trees break differently; it does happen with voxel centroids of the
    regular pixel grid) or a distance at the upper bound itself - the query goes to cKDTree. Without
    open3d every query goes to cKDTree. `data` is the (n, 3) float64 point array.
    """

    def __init__(self, points: np.ndarray, *, tree: cKDTree | None = None) -> None:
        self.data = np.ascontiguousarray(points, dtype=np.float64)
        self._tree = tree
        self._index: Any = None  # open3d's index, built on the first query; False when open3d is missing

    @property
    def tree(self) -> cKDTree:
        """The cKDTree over `data` (built on first use)."""
        if self._tree is None:
            self._tree = cKDTree(self.data)
        return self._tree

    def _open3d_index(self) -> Any:
        if self._index is None:
            try:
                o3d = load_open3d()
            except ImportError:
                self._index = False
            else:
                index = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor.from_numpy(self.data))
                self._index = index if index.knn_index() else False
        return self._index or None

    def query(self, x: np.ndarray, *, distance_upper_bound: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
        """(m,) distances and (m,) indices into `data` of the nearest point to each of the (m, 3) points
        `x`; inf and n where none is nearer than `distance_upper_bound` (strictly, as cKDTree)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        index = self._open3d_index() if len(self.data) >= 2 and x.ndim == 2 and len(x) > 0 else None
        if index is None:
            dist, nn = self.tree.query(x, distance_upper_bound=distance_upper_bound)
            return dist, nn
        o3d = load_open3d()
        idx_t, d2_t = index.knn_search(o3d.core.Tensor.from_numpy(x), 2)
        idx, d2 = idx_t.numpy(), d2_t.numpy()
        nn = idx[:, 0].astype(np.intp)  # a copy
        d2_best = d2[:, 0]
        dist = np.sqrt(d2_best)  # cKDTree reports sqrt of the same squared distance
        unsure = d2[:, 1] <= d2_best * (1.0 + 1e-12)  # a tie, or one to rounding: cKDTree may order them otherwise
        if math.isfinite(distance_upper_bound):
            bound2 = distance_upper_bound * distance_upper_bound
            unsure |= np.abs(d2_best - bound2) <= 1e-12 * bound2
            out = ~(d2_best < bound2)
            dist[out] = math.inf
            nn[out] = len(self.data)
        if unsure.any():
            k = np.flatnonzero(unsure)
            dist[k], nn[k] = self.tree.query(x[k], distance_upper_bound=distance_upper_bound)
        return dist, nn


@dataclass(frozen=True)
class IcpResult:
    """Pose (4, 4) mapping the source onto the target, inlier RMSE (m), iterations, converged flag."""

    T: np.ndarray
    rmse: float
    iterations: int
    converged: bool


def trimmed_icp(
    source: np.ndarray,
    target: np.ndarray | cKDTree | NearestNeighbors,
    T_init: np.ndarray,
    *,
    max_iterations: int = 60,
    tolerance: tuple[float, float] = (1e-4, 1e-6),
    inlier_ratio: float = 0.7,
) -> IcpResult:
    """Point-to-point ICP keeping the `inlier_ratio` closest pairs each iteration (as `pcregistericp`).

    Stops when the change of translation is below tolerance[0] (m) and of rotation below tolerance[1]
    (rad) between two iterations, or after `max_iterations`. RMSE is over the kept pairs. Pass the
    target as a `NearestNeighbors` (cache it per template) to skip building its index per call.
    """
    if isinstance(target, NearestNeighbors):
        tree = target
    elif isinstance(target, cKDTree):
        tree = NearestNeighbors(target.data, tree=target)
    else:
        tree = NearestNeighbors(np.asarray(target))
    tgt = tree.data
    T = np.array(T_init, dtype=float)
    n_keep = max(3, int(round(inlier_ratio * len(source))))
    it, converged = 0, False
    for it in range(1, max_iterations + 1):  # noqa: B007 - `it` is read after the loop: the iteration count
        moved = transform_points(T, source)
        dist, nn = tree.query(moved)
        keep = np.argpartition(dist, n_keep - 1)[:n_keep] if n_keep < len(dist) else np.arange(len(dist))
        R, t = kabsch(moved[keep], tgt[nn[keep]])
        dT = np.eye(4)
        dT[:3, :3], dT[:3, 3] = R, t
        T = dT @ T
        d_ang = float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))
        if np.linalg.norm(t) < tolerance[0] and d_ang < tolerance[1]:
            converged = True
            break
    moved = transform_points(T, source)
    dist, _ = tree.query(moved)
    keep = np.sort(dist)[:n_keep]
    rmse = float(np.sqrt(np.mean(keep**2)))
    return IcpResult(T, rmse, it, converged)
