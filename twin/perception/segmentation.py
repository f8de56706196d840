"""Clusters of points above the table: DBSCAN on a voxel grid, mapped back to full resolution.

DBSCAN on the full 640x480 cloud takes seconds (LIBRARY-NOTES), so it runs on a voxel-downsampled copy
with `min_points` scaled by the downsampling ratio (the density drops by that ratio, so a core point
needs proportionally fewer neighbours); every full-resolution point then takes the label of its
nearest voxel point, so point counts, colours and masks stay full-resolution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from twin.perception.cloud_geometry import NearestNeighbors, Plane
from twin.perception.open3d_import import load_open3d

__all__ = ["Cluster", "Footprint", "cluster_points", "footprint", "open3d", "plane_to_frame"]


open3d = load_open3d  # the open3d module, imported on first use (`twin.perception.open3d_import`)


@dataclass(frozen=True)
class Cluster:
    """Full-resolution points (n, 3), colours (n, 3) in [0, 1], and their pixel indices (n,) if known."""

    points: np.ndarray
    rgb: np.ndarray
    pixels: np.ndarray | None

    @property
    def n_points(self) -> int:
        return int(len(self.points))

    @property
    def mean_rgb(self) -> np.ndarray:
        return self.rgb.mean(axis=0)


@dataclass(frozen=True)
class Footprint:
    """The smallest rectangle around points seen from above: centre (2,), length >= width (m), angle of
    the length axis (rad, in (-pi/2, pi/2])."""

    center: np.ndarray
    length: float
    width: float
    angle: float

    def contains(self, xy: np.ndarray, *, shrink: float = 1.0) -> np.ndarray:
        """Mask of (n, 2) points inside the rectangle scaled by `shrink` about its centre."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        d = xy - self.center
        u = d @ np.array([c, s])
        v = d @ np.array([-s, c])
        return (np.abs(u) <= shrink * self.length / 2) & (np.abs(v) <= shrink * self.width / 2)


def footprint(points: np.ndarray) -> Footprint:
    """Minimum-area rectangle of the points' x, y (OpenCV's rotating calipers)."""
    (cx, cy), (w, h), ang = cv2.minAreaRect(points[:, :2].astype(np.float32))
    a = math.radians(ang)
    if h > w:
        w, h, a = h, w, a + math.pi / 2
    a = (a + math.pi / 2) % math.pi - math.pi / 2
    return Footprint(np.array([cx, cy], dtype=float), float(w), float(h), a)


def plane_to_frame(plane: Plane, T: np.ndarray) -> Plane:
    """The plane expressed in the frame that T (4, 4) maps into."""
    n = T[:3, :3] @ plane.normal
    return Plane(n, float(plane.offset + n @ T[:3, 3]), plane.inliers)


def cluster_points(
    points: np.ndarray,
    rgb: np.ndarray,
    *,
    eps_m: float,
    min_points: int,
    voxel_m: float,
    pixels: np.ndarray | None = None,
) -> list[Cluster]:
    """DBSCAN clusters (largest first). `min_points` is the full-resolution value; see the module doc."""
    o3d = open3d()
    if len(points) == 0:
        return []
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if voxel_m > 0:
        down = pcd.voxel_down_sample(voxel_m)
        ratio = len(down.points) / len(points)
    else:
        down, ratio = pcd, 1.0
    mp = max(3, int(round(min_points * ratio)))
    labels = np.asarray(down.cluster_dbscan(eps=eps_m, min_points=mp, print_progress=False))
    if labels.size == 0 or labels.max() < 0:
        return []
    if voxel_m > 0:
        dpts = np.asarray(down.points)
        dist, nn = NearestNeighbors(dpts).query(points, distance_upper_bound=max(voxel_m * 1.5, eps_m))
        full = np.full(len(points), -1)
        hit = np.isfinite(dist)
        full[hit] = labels[nn[hit]]
    else:
        full = labels
    # the points of each label in their original order (a stable sort by label), picked by index
    order = np.argsort(full, kind="stable")
    bounds = np.searchsorted(full[order], np.arange(labels.max() + 2))
    out = []
    for k in range(labels.max() + 1):
        sel = order[bounds[k] : bounds[k + 1]]
        if len(sel):
            out.append(
                Cluster(
                    np.take(points, sel, axis=0),
                    np.take(rgb, sel, axis=0),
                    None if pixels is None else np.take(pixels, sel, axis=0),
                )
            )
    out.sort(key=lambda c: -c.n_points)
    return out
