"""Where a camera is when its marker cannot say: the table plane in its own depth image measures the camera's
height and tilt over the table top (z = 0 in the base frame), and the mount's tolerance bounds the rest.

Used by a calibration that found no marker in any view (`twin.tasks.robocup.calibration` for the wrist camera,
the warehouse task for the fixed one): the configured pose levelled on the table plane (`level_on_table`), with
the error bound that implies for a point on the table (`error_bound_m`); and by a calibration that did find it,
to check its estimate against the plane (`table_disagreement`).
"""

from __future__ import annotations

import math

import numpy as np

from twin.camera import camera_pose, point_cloud
from twin.config import Settings
from twin.perception.capture import Capture, wrist_camera_offset
from twin.robot.kinematics import URArm

__all__ = ["error_bound_m", "level_on_table", "table_disagreement", "table_plane"]

_PLANE_MIN_INLIERS = 0.3  # the table is the dominant plane when it holds this share of the depth points
_PLANE_STRIDE = 4  # every 4th pixel in each direction: ~19 000 points from 640 x 480, plenty for a plane


def table_plane(cap: Capture) -> tuple[np.ndarray, float] | None:
    """The dominant plane of the depth image in the camera frame: (unit normal towards the camera, the
    camera's distance from it m); None when no plane holds `_PLANE_MIN_INLIERS` of the points."""
    from twin.perception.cloud_geometry import fit_plane_ransac  # lazy: scipy

    pts, _ = point_cloud(cap.frame, stride=_PLANE_STRIDE)
    if len(pts) < 500:
        return None
    plane = fit_plane_ransac(pts, 0.01, iterations=200, rng=np.random.default_rng(0)).oriented(np.zeros(3))
    if plane.inliers.sum() < _PLANE_MIN_INLIERS * len(pts):
        return None
    return plane.normal, -plane.offset


def table_disagreement(cap: Capture, T_base_camera: np.ndarray) -> tuple[float, float] | None:
    """(tilt deg, height m) by which camera pose `T_base_camera` disagrees with the table plane in `cap`'s
    depth image: the angle between the plane's normal carried to the base frame and +z, and the camera's
    height over z = 0 less its distance from the plane. None when no table plane is seen."""
    plane = table_plane(cap)
    if plane is None:
        return None
    n, dist = plane
    up = T_base_camera[:3, :3] @ n
    tilt = math.degrees(math.acos(float(np.clip(up[2], -1.0, 1.0))))
    return tilt, float(T_base_camera[2, 3] - dist)


def level_on_table(cap: Capture, settings: Settings) -> np.ndarray:
    """The nominal camera pose of `cap` turned (about a level axis through the camera) and lifted so that
    the table plane of its depth image is level at z = 0: a mount error's tilt and height measured, its turn
    about the vertical and level shift not. The nominal pose where no table plane is seen, or where levelling
    would turn it more than twice `camera.mount_tolerance` (then the plane is not the table)."""
    from scipy.spatial.transform import Rotation

    T = np.array(cap.T_base_camera_nominal, dtype=float)
    plane = table_plane(cap)
    if plane is None:
        return T
    n, dist = plane
    up = T[:3, :3] @ n
    axis = np.cross(up, [0.0, 0.0, 1.0])
    angle = math.atan2(float(np.linalg.norm(axis)), float(up[2]))
    if angle > 2.0 * math.radians(settings.camera.mount_tolerance.rotation_deg):
        return T
    if angle > 1e-9:
        T[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix() @ T[:3, :3]
    T[2, 3] = dist
    return T


def error_bound_m(settings: Settings, arm: URArm, *, levelled: bool = False) -> float:
    """How far (m) an object in the spawn region (`world.objects.region_x` x `region_y`, on the table), seen from
    the capture pose, may be misplaced by a camera pose off its mount by `camera.mount_tolerance` (t, r):
    t + d r, d the range to the region's farthest corner (small angles). Levelled on the table plane (tilt and
    height measured): t + rho r, rho that corner's level distance from the camera (a turn about the vertical
    and a level shift are what is left). The region, not the image: a fixed camera's image reaches past the
    table, where no object is looked for."""
    cam = settings.camera
    t, r = cam.mount_tolerance.translation_m, math.radians(cam.mount_tolerance.rotation_deg)
    if cam.mount == "wrist":
        T = arm.fk(np.asarray(cam.capture_pose, dtype=float), "flange")
        T = T @ wrist_camera_offset(settings)
    else:
        T = camera_pose(cam)
    region = settings.world.objects
    corners = np.array([[x, y, 0.0] for x in region.region_x for y in region.region_y])
    far = float(np.max(np.linalg.norm(corners - T[:3, 3], axis=1)))
    rho = float(np.max(np.linalg.norm(corners[:, :2] - T[:2, 3], axis=1)))
    return t + (rho if levelled else far) * r
