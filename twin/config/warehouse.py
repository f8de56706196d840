"""The warehouse task's settings (config sections `task.warehouse` and `perception.warehouse`): drop
zones and the seeds-000/001 cube detector.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from twin.config.base import ConfigModel, Vec3

__all__ = ["WarehousePerceptionSettings", "WarehouseTaskSettings"]


class WarehousePerceptionSettings(ConfigModel):
    """Seeds 000/001 `cube_detector`: depth thresholds, RANSAC plane, DBSCAN, labels by mean colour.

    `voxel_m` > 0 downsamples before DBSCAN (full-resolution DBSCAN takes seconds); `dbscan_min_points`
    is the full-resolution value and is scaled by the downsampling ratio. Point counts (obstacle, cubes)
    are counted in the full-resolution cloud. `roi_min`/`roi_max` (base frame) drop points of the robot
    (its base at the origin, the gripper hanging above the table) and anything off the table; the work
    area lies at negative x. `centroid`: "resting" takes x, y from the cluster's footprint (the smallest
    rectangle around it seen from above) and z half way between its top face and the table (unbiased for
    boxes on the table); "mean" is the seed's plain mean of the visible points (~2 cm off: towards the
    camera and upwards, as only the top and front faces are seen).

    `plane_method`: "ransac" fits the table by twin's seeded RANSAC (`fit_plane_ransac`, `plane_iterations`
    hypotheses drawn from every `plane_every`-th point, a least-squares refit on the inliers, inliers
    counted on the whole cloud): repeatable, the same plane for the same seed, and ~6x faster. "open3d" is
    the seed's `segment_plane` on the whole cloud, which on this machine returns different planes for the
    same seed now and then (open3d's RANSAC runs on several threads), so a run was not always repeatable.
    `voxel_m` 5 mm (the seed's pipeline used 4 mm: the same cube centroids, DBSCAN twice as fast).

    `partial_view_fit` (not in the seed): a cube cluster whose footprint is clearly narrower than
    `cube_side_m` is the visible part of a cube hidden in part behind something taller; its centre is the
    cube pose that contains the visible points and blocks none of the table the camera saw
    (`twin.perception.occlusion`) instead of the visible part's centre, up to half a side off.
    """

    min_depth_m: float = Field(0.25, ge=0)
    max_depth_m: float = Field(1.5, gt=0)
    plane_threshold_m: float = Field(0.02, gt=0)
    plane_iterations: int = Field(500, ge=10)
    plane_method: Literal["ransac", "open3d"] = "ransac"
    plane_every: int = Field(8, ge=1)  # "ransac": hypotheses from every n-th point
    dbscan_eps_m: float = Field(0.015, gt=0)
    dbscan_min_points: int = Field(40, ge=1)
    voxel_m: float = Field(0.005, ge=0)
    obstacle_min_points: int = Field(10000, ge=1)
    obstacle_color: str = "blue"
    labels: list[str] = Field(default_factory=lambda: ["black", "red", "blue", "green"])
    cube_min_points: int = Field(150, ge=1)
    cube_max_extent_m: float = Field(0.09, gt=0)
    roi_min: Vec3 = (-1.0, -0.8, -0.05)
    roi_max: Vec3 = (-0.10, 0.8, 0.30)
    box_extension_y_m: float = Field(0.5, ge=0)
    centroid: Literal["resting", "mean"] = "resting"
    cube_side_m: float = Field(0.05, gt=0)
    partial_view_fit: bool = True


class WarehouseTaskSettings(ConfigModel):
    """The seed-000/001 task: fixed drop location per colour on the robot's side of the obstacle."""

    drop_zones: dict[str, Vec3] = Field(
        default_factory=lambda: {
            "black": (-0.28, -0.30, 0.0),
            "red": (-0.28, -0.16, 0.0),
            "blue": (-0.28, 0.18, 0.0),
            "green": (-0.28, 0.32, 0.0),
        }
    )
    drop_radius_m: float = Field(0.06, gt=0)  # success: the cube rests within this xy distance of its zone
    hover_m: float = Field(0.25, gt=0, le=0.5)  # above the obstacle top: MoveJ there is a straight joint path
    release_height_m: float = Field(0.02, ge=0, le=0.5)  # cube bottom above the table when released
    retries: int = Field(1, ge=0, le=5)
