"""Pinhole camera maths shared by the world (rendering) and perception (back-projection).

Camera frame convention is OpenCV's: x right, y down, z forward along the optical axis. PyBullet
renders with OpenGL matrices; the conversions live here so the world module stays a thin adapter.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from twin.config import CameraSettings, ExtrinsicErrorSettings

__all__ = [
    "Intrinsics",
    "RGBDFrame",
    "camera_pose",
    "depth_from_zbuffer",
    "gl_projection_matrix",
    "gl_view_matrix",
    "look_at",
    "mount_error",
    "point_cloud",
    "point_cloud_within",
    "true_camera_pose",
]

_CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels; the principal point is the image centre (pixel centres at integers)."""

    width: int
    height: int
    fx: float
    fy: float

    @property
    def cx(self) -> float:
        return (self.width - 1) / 2.0

    @property
    def cy(self) -> float:
        return (self.height - 1) / 2.0

    @classmethod
    def from_settings(cls, cam: CameraSettings) -> Intrinsics:
        return cls(cam.width, cam.height, cam.fx, cam.fy)

    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K (OpenCV)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class RGBDFrame:
    """One rendered frame: rgb (H, W, 3) uint8, depth_m (H, W) metric depth along the optical axis
    (0 where there is no return), and the intrinsics. Perception gets nothing else."""

    rgb: np.ndarray
    depth_m: np.ndarray
    intrinsics: Intrinsics


def look_at(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> np.ndarray:
    """(4, 4) pose of an OpenCV camera at `eye` looking at `target`, image 'up' towards `up`."""
    eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:  # looking straight along `up`: pick any perpendicular
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T


def gl_view_matrix(T_world_camera: np.ndarray) -> list[float]:
    """PyBullet's view matrix (16 floats, column-major) for an OpenCV camera pose."""
    view = _CV_TO_GL @ np.linalg.inv(T_world_camera)
    return view.T.reshape(-1).tolist()


def gl_projection_matrix(intr: Intrinsics, near_m: float, far_m: float) -> list[float]:
    """PyBullet's projection matrix (16 floats, column-major) matching the pinhole intrinsics."""
    W, H, n, f = intr.width, intr.height, near_m, far_m
    P = np.array(
        [
            [2.0 * intr.fx / W, 0.0, 0.0, 0.0],
            [0.0, 2.0 * intr.fy / H, 0.0, 0.0],
            [0.0, 0.0, -(f + n) / (f - n), -2.0 * f * n / (f - n)],
            [0.0, 0.0, -1.0, 0.0],
        ]
    )
    return P.T.reshape(-1).tolist()


def depth_from_zbuffer(zbuf: np.ndarray, near_m: float, far_m: float) -> np.ndarray:
    """Metric depth along the optical axis from PyBullet's non-linear z-buffer; 0 at the far plane."""
    d = np.asarray(zbuf, dtype=np.float64)
    z = far_m * near_m / (far_m - (far_m - near_m) * d)
    z[d >= 1.0 - 1e-7] = 0.0
    return z


@lru_cache(maxsize=16)
def _pixel_offsets(width: int, height: int, stride: int, cx: float, cy: float) -> tuple[np.ndarray, np.ndarray]:
    """Flat (u - cx) and (v - cy) of the sampled pixels, row-major (read-only; cached per image geometry)."""
    v, u = np.mgrid[0:height:stride, 0:width:stride]
    du, dv = (u - cx).ravel(), (v - cy).ravel()
    du.flags.writeable = dv.flags.writeable = False
    return du, dv


def point_cloud(frame: RGBDFrame, *, stride: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) points in the camera frame and (n, 3) colours in [0, 1] for every pixel with depth, in
    row-major pixel order: x = (u - cx) z / fx, y = (v - cy) z / fy.

    The pixel offsets are cached per image size and the pixels are picked by index (numpy's boolean
    indexing of (H, W, 3) arrays is several times slower); the arithmetic is the same as computing it
    all afresh, so the values are bit for bit the same.
    """
    d = frame.depth_m[::stride, ::stride]
    return _back_project(frame, d, np.flatnonzero(d > 0), stride)


def point_cloud_within(frame: RGBDFrame, min_depth_m: float, max_depth_m: float) -> tuple[np.ndarray, ...]:
    """`point_cloud(frame)` of the pixels whose depth is within [min_depth_m, max_depth_m], and their flat
    pixel indices (n,) (row-major): the points and colours of `point_cloud` at those rows, bit for bit, without
    back-projecting and then dropping the rest (a RoboCup frame: ~20 ms of 300k rows taken again)."""
    d = frame.depth_m
    idx = np.flatnonzero((d > 0) & (d >= min_depth_m) & (d <= max_depth_m))
    pts, colours = _back_project(frame, d, idx, 1)
    return pts, colours, idx


def _back_project(frame: RGBDFrame, d: np.ndarray, idx: np.ndarray, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 3) and colours (n, 3) of the flat pixel indices `idx` into `d` (the depth at `stride`)."""
    intr = frame.intrinsics
    du, dv = _pixel_offsets(intr.width, intr.height, stride, intr.cx, intr.cy)
    z = d.reshape(-1)[idx]
    pts = np.empty((len(idx), 3), dtype=np.result_type(du, z))
    pts[:, 0] = du[idx] * z / intr.fx
    pts[:, 1] = dv[idx] * z / intr.fy
    pts[:, 2] = z
    colours = np.take(frame.rgb[::stride, ::stride].reshape(-1, 3), idx, axis=0)
    return pts, colours.astype(np.float64) / 255.0


def camera_pose(cam: CameraSettings, T_world_tool0: np.ndarray | None = None) -> np.ndarray:
    """(4, 4) pose of the configured camera in the world (= base) frame; a wrist mount needs tool0's pose."""
    if cam.mount == "fixed":
        return look_at(np.array(cam.position), np.array(cam.target))
    if T_world_tool0 is None:
        raise ValueError("a wrist-mounted camera needs the tool0 pose")
    T = np.eye(4)
    T[:3, 3] = cam.wrist_offset_m
    return np.asarray(T_world_tool0) @ T


def mount_error(err: ExtrinsicErrorSettings, seed: int) -> np.ndarray:
    """(4, 4) the camera's real pose in its configured one: a translation of `err.translation_m` along, and a
    rotation of `err.rotation_deg` about, unit directions drawn from `seed` (exactly the identity when both
    are 0, so a run without the fault is the nominal run)."""
    T = np.eye(4)
    if err.translation_m == 0.0 and err.rotation_deg == 0.0:
        return T
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng([int(seed), 0xCA3E])
    t_dir, axis = rng.normal(size=3), rng.normal(size=3)
    T[:3, 3] = err.translation_m * t_dir / np.linalg.norm(t_dir)
    T[:3, :3] = Rotation.from_rotvec(np.deg2rad(err.rotation_deg) * axis / np.linalg.norm(axis)).as_matrix()
    return T


def true_camera_pose(cam: CameraSettings, seed: int, T_world_tool0: np.ndarray | None = None) -> np.ndarray:
    """(4, 4) where the camera really is: the configured pose (`camera_pose`) times its mount error for scene
    `seed` (`camera.extrinsic_error`). Rendering and judging use this; perception never does."""
    return camera_pose(cam, T_world_tool0) @ mount_error(cam.extrinsic_error, seed)


OVERVIEW_EYE = np.array([-1.45, -1.35, 1.15])
OVERVIEW_TARGET = np.array([-0.25, 0.0, 0.05])
