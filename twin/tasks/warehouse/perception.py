"""The warehouse `cube_detector` (seeds 000/001): obstacle box and labelled cubes from one RGB-D frame.

Steps, as in the seed: (1) depth thresholds; (2) RANSAC plane (0.02 m), plane inliers removed; (3) DBSCAN
(eps 0.015 m, minPts 40); (4) obstacle = the blue cluster with >= 10000 points; (5) every other cluster
is a cube labelled black/red/blue/green by its mean colour. The plane is fitted in the camera frame; the
remaining points are then mapped to the base frame with the camera-to-base transform (DBSCAN does not
change under a rigid transform), so the obstacle's axis-aligned box is axis-aligned in the base frame, as
the planner needs it, and it is extended by 0.5 m in +-y. Cube centroids are reported in both frames.

Deviations, each for a measured reason (see WarehousePerceptionSettings): the cloud is voxel-downsampled
before DBSCAN (full resolution takes seconds) with minPts scaled by the downsampling ratio, while point
counts stay full-resolution counts; points outside a base-frame region of interest are dropped so the
robot's own links never become clusters; the box's bottom face is put on the fitted table plane (the
plane step cut the box's lowest 2 cm); cube centroids are by default taken from the footprint and the
top face ("resting" centroid) because the mean of the visible points sits ~2 cm off the true centre.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from twin.camera import RGBDFrame, point_cloud
from twin.config import WarehousePerceptionSettings
from twin.perception.cloud_geometry import Plane, fit_plane_ransac, transform_points
from twin.perception.colors import classify_color
from twin.perception.occlusion import PARTIAL_VIEW_TOL_M, fit_partly_seen_box
from twin.perception.segmentation import Cluster, cluster_points, footprint, open3d, plane_to_frame
from twin.timing import stage
from twin.types import BoxBounds

__all__ = ["LabeledCube", "WarehouseResult", "perceive_warehouse"]

log = logging.getLogger("twin")
_SLACK_M = 0.01  # a cluster this far past the obstacle's box (a noisy face of it) still lies within it


@dataclass(frozen=True)
class LabeledCube:
    """One cube: centroid (3,) in the base frame (and in the camera frame), colour label, full-res points."""

    centroid: np.ndarray
    color_label: str
    n_points: int
    centroid_camera: np.ndarray
    mean_rgb: np.ndarray


@dataclass(frozen=True)
class WarehouseResult:
    """What the warehouse perception hands to the planner (base frame) plus diagnostics.

    `obstacle`: smallest AABB around the obstacle cluster (None when no obstacle was seen);
    `obstacle_extended`: the same box grown by `box_extension_y_m` in +y and -y; `cubes`: every other
    cluster; `rejected`: clusters that were neither (too small, too large, wrong colour); `unknown`: the
    AABB (down to the table) of each rejected cluster of a cube's points or more that is too large for a
    cube: something stands there that no one named, which the planner must go around all the same;
    `timings_s`: seconds per stage.
    """

    obstacle: BoxBounds | None
    obstacle_extended: BoxBounds | None
    cubes: tuple[LabeledCube, ...]
    obstacle_points: int
    rejected: int
    table_plane_base: Plane
    timings_s: dict[str, float] = field(default_factory=dict)
    unknown: tuple[BoxBounds, ...] = ()


def _table_plane(pts: np.ndarray, params: WarehousePerceptionSettings, seed: int, o3d: Any) -> tuple[Plane, np.ndarray]:
    """The table plane in the camera frame (normal towards the camera) and the mask of its points."""
    if params.plane_method == "ransac":
        sub = pts[:: params.plane_every]
        fit = fit_plane_ransac(
            sub, params.plane_threshold_m, iterations=params.plane_iterations, rng=np.random.default_rng(seed)
        )
        plane = Plane(fit.normal, fit.offset, np.zeros(0, dtype=bool)).oriented(np.zeros(3))
        return plane, np.abs(pts @ plane.normal - plane.offset) < params.plane_threshold_m
    o3d.utility.random.seed(int(seed))
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    model, inliers = pcd.segment_plane(params.plane_threshold_m, 3, params.plane_iterations)
    a, b, c, d = model
    n = np.array([a, b, c])
    plane = Plane(n / np.linalg.norm(n), float(-d / np.linalg.norm(n)), np.zeros(0, dtype=bool)).oriented(np.zeros(3))
    on_plane = np.zeros(len(pts), dtype=bool)
    on_plane[np.asarray(inliers, dtype=np.int64)] = True
    return plane, on_plane


def perceive_warehouse(
    frame: RGBDFrame, T_base_camera: np.ndarray, params: WarehousePerceptionSettings, *, seed: int = 0
) -> WarehouseResult:
    """Run the seed's cube_detector on one frame; `T_base_camera` (4, 4) from the ArUco calibration."""
    o3d = open3d()
    timings: dict[str, float] = {}
    # Points are picked by index (np.take) rather than by boolean mask: the same rows in the same order,
    # several times faster for (n, 3) arrays.
    with stage("perception.cloud") as cloud_stage:
        pts, rgb = point_cloud(frame)
        pts, rgb = _rows(
            np.flatnonzero((pts[:, 2] >= params.min_depth_m) & (pts[:, 2] <= params.max_depth_m)), pts, rgb
        )
    timings["cloud"] = cloud_stage.seconds

    with stage("perception.plane") as plane_stage:
        plane_cam, on_plane = _table_plane(pts, params, seed, o3d)
        table_cam = pts[on_plane]  # free space, for a cube seen only in part
        pts, rgb = _rows(np.flatnonzero(~on_plane), pts, rgb)
    timings["plane"] = plane_stage.seconds

    plane_base = plane_to_frame(plane_cam, T_base_camera)
    plane_base = plane_base.oriented(np.array([0.0, 0.0, 10.0]))  # normal up
    pts_base = transform_points(T_base_camera, pts)
    roi = np.ones(len(pts_base), dtype=bool)
    for k in range(3):  # one axis at a time: the same test as np.all(lo <= p <= hi, axis=1), faster
        roi &= (pts_base[:, k] >= params.roi_min[k]) & (pts_base[:, k] <= params.roi_max[k])
    pts, rgb, pts_base = _rows(np.flatnonzero(roi), pts, rgb, pts_base)

    with stage("perception.dbscan") as dbscan_stage:
        clusters = cluster_points(
            pts_base, rgb, eps_m=params.dbscan_eps_m, min_points=params.dbscan_min_points, voxel_m=params.voxel_m
        )
    timings["dbscan"] = dbscan_stage.seconds

    with stage("perception.label") as label_stage:
        obstacle: BoxBounds | None = None
        obstacle_n = 0
        cubes: list[LabeledCube] = []
        unknown: list[BoxBounds] = []
        rejected = 0
        table_base: np.ndarray | None = None
        table_z = _table_height(plane_base)
        T_camera_base = np.linalg.inv(T_base_camera)
        for cl in clusters:
            label = classify_color(cl.mean_rgb, params.labels)
            if label == params.obstacle_color and cl.n_points >= params.obstacle_min_points:
                if cl.n_points > obstacle_n:
                    lo, hi = cl.points.min(axis=0), cl.points.max(axis=0)
                    lo[2] = min(lo[2], table_z)  # it stands on the table: the plane step removed its bottom
                    obstacle = BoxBounds(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])
                    obstacle_n = cl.n_points
                continue
            extent = cl.points.max(axis=0) - cl.points.min(axis=0)
            if cl.n_points < params.cube_min_points or float(extent.max()) > params.cube_max_extent_m:
                rejected += 1
                log.debug(
                    "warehouse: rejected a %s cluster of %d points, extent %s", label, cl.n_points, np.round(extent, 3)
                )
                if cl.n_points >= params.cube_min_points:  # not noise: something too large for a cube stands there
                    lo, hi = cl.points.min(axis=0), cl.points.max(axis=0)
                    lo[2] = min(lo[2], table_z)
                    unknown.append(BoxBounds(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]))
                continue
            centroid = _cube_centroid(cl, table_z) if params.centroid == "resting" else cl.points.mean(axis=0)
            # a footprint clearly narrower than a cube's face: the rest of the cube is hidden (behind something
            # taller, or cut off by the image's edge)
            width = footprint(cl.points).width if params.partial_view_fit else params.cube_side_m
            if width < params.cube_side_m - PARTIAL_VIEW_TOL_M:
                if table_base is None:
                    table_base = transform_points(T_base_camera, table_cam)
                centroid = _fit_partly_seen(cl, width, centroid, params.cube_side_m, table_z, T_base_camera, table_base)
            cubes.append(
                LabeledCube(
                    centroid, label, cl.n_points, transform_points(T_camera_base, centroid[None])[0], cl.mean_rgb
                )
            )
    timings["label"] = label_stage.seconds
    extended = obstacle.extended_y(params.box_extension_y_m) if obstacle is not None else None
    if extended is not None:  # a face of the obstacle seen apart from the rest (shaded otherwise) is the obstacle
        unknown = [b for b in unknown if not _within(b, extended, _SLACK_M)]
    log.debug("warehouse: %d cubes, obstacle %s (%d points), %d rejected", len(cubes), obstacle, obstacle_n, rejected)
    return WarehouseResult(
        obstacle, extended, tuple(cubes), obstacle_n, rejected, plane_base, timings, unknown=tuple(unknown)
    )


def _within(inner: BoxBounds, outer: BoxBounds, slack_m: float) -> bool:
    """Whether `inner` lies inside `outer` grown by `slack_m` on every side."""
    return bool(np.all(inner.lo >= outer.lo - slack_m) and np.all(inner.hi <= outer.hi + slack_m))


def _rows(idx: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The rows `idx` of each array."""
    return tuple(np.take(a, idx, axis=0) for a in arrays)


def _table_height(plane_base: Plane) -> float:
    """z of the table plane under the work area (the plane is nearly level in the base frame)."""
    nz = plane_base.normal[2]
    return float(plane_base.offset / nz) if abs(nz) > 1e-6 else 0.0


def _fit_partly_seen(
    cl: Cluster,
    width_m: float,
    centroid: np.ndarray,
    side_m: float,
    table_z: float,
    T_base_camera: np.ndarray,
    table: np.ndarray,
) -> np.ndarray:
    """The centre of the cube of which `cl` (its footprint `width_m` wide) is the visible part
    (twin.perception.occlusion): it contains the visible points and blocks none of the table the camera saw."""
    fit = fit_partly_seen_box(
        cl.points, (side_m, side_m), side_m, table_z, T_base_camera[:3, 3], table, np.asarray(centroid[:2])
    )
    log.info(
        "warehouse: a cube seen only in part (%d points, %.0f mm wide): fitted %.0f mm from the visible part's "
        "centre (%d seen rays through it, %d points outside)",
        cl.n_points,
        1000 * width_m,
        1000 * fit.shift_m,
        fit.free_rays_through,
        fit.points_outside,
    )
    return np.array([fit.center_xy[0], fit.center_xy[1], table_z + side_m / 2])


def _cube_centroid(cl: Cluster, table_z: float) -> np.ndarray:
    """x, y: centre of the footprint rectangle; z: half way between the top face and the table."""
    fp = footprint(cl.points)
    inner = fp.contains(cl.points[:, :2], shrink=0.6)
    z_top = float(np.median(cl.points[inner, 2])) if inner.sum() >= 5 else float(np.percentile(cl.points[:, 2], 95))
    return np.array([fp.center[0], fp.center[1], 0.5 * (z_top + table_z)])
