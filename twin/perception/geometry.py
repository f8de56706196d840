"""Small point-cloud geometry shared by the pipelines: transforms, planes, PCA, rigid fits, trimmed ICP.

Plain numpy/scipy so the pieces are testable on synthetic data and the RoboCup ICP can follow MATLAB's
`pcregistericp` semantics (inlier ratio, tolerance on the change of translation and rotation), which
open3d's ICP does not offer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "IcpResult",
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
    """(n, 3) points mapped by the (4, 4) transform T."""
    return points @ T[:3, :3].T + T[:3, 3]


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
    best_count, best = -1, (np.array([0.0, 0.0, 1.0]), 0.0)
    idx = rng.integers(0, len(points), size=(iterations, 3))
    for i, j, k in idx:
        n = np.cross(points[j] - points[i], points[k] - points[i])
        norm = np.linalg.norm(n)
        if norm < 1e-12:
            continue
        n /= norm
        d = float(n @ points[i])
        count = int(np.count_nonzero(np.abs(points @ n - d) < threshold_m))
        if count > best_count:
            best_count, best = count, (n, d)
    n, d = best
    inl = np.abs(points @ n - d) < threshold_m
    if refine and inl.sum() >= 3:
        n, d = fit_plane(points[inl])
        inl = np.abs(points @ n - d) < threshold_m
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


@dataclass(frozen=True)
class IcpResult:
    """Pose (4, 4) mapping the source onto the target, inlier RMSE (m), iterations, converged flag."""

    T: np.ndarray
    rmse: float
    iterations: int
    converged: bool


def trimmed_icp(
    source: np.ndarray,
    target: np.ndarray | cKDTree,
    T_init: np.ndarray,
    *,
    max_iterations: int = 60,
    tolerance: tuple[float, float] = (1e-4, 1e-6),
    inlier_ratio: float = 0.7,
) -> IcpResult:
    """Point-to-point ICP keeping the `inlier_ratio` closest pairs each iteration (as `pcregistericp`).

    Stops when the change of translation is below tolerance[0] (m) and of rotation below tolerance[1]
    (rad) between two iterations, or after `max_iterations`. RMSE is over the kept pairs.
    """
    tree = target if isinstance(target, cKDTree) else cKDTree(np.asarray(target))
    tgt = tree.data
    T = np.array(T_init, dtype=float)
    n_keep = max(3, int(round(inlier_ratio * len(source))))
    rmse, it, converged = float("inf"), 0, False
    for it in range(1, max_iterations + 1):  # noqa: B007 - `it` is read after the loop: the iteration count
        moved = transform_points(T, source)
        dist, nn = tree.query(moved)
        keep = np.argpartition(dist, n_keep - 1)[:n_keep] if n_keep < len(dist) else np.arange(len(dist))
        R, t = kabsch(moved[keep], tgt[nn[keep]])
        dT = np.eye(4)
        dT[:3, :3], dT[:3, 3] = R, t
        T = dT @ T
        rmse = float(np.sqrt(np.mean(dist[keep] ** 2)))
        d_ang = float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))
        if np.linalg.norm(t) < tolerance[0] and d_ang < tolerance[1]:
            converged = True
            break
    moved = transform_points(T, source)
    dist, _ = tree.query(moved)
    keep = np.sort(dist)[:n_keep]
    rmse = float(np.sqrt(np.mean(keep**2)))
    return IcpResult(T, rmse, it, converged)
