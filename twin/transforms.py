"""Rotations and rigid poses: the one implementation of each conversion the project uses.

Conventions
* roll-pitch-yaw as URDF defines it: fixed-axis X, then Y, then Z, i.e. R = Rz(yaw) @ Ry(pitch) @ Rx(roll)
  (PyBullet's `getQuaternionFromEuler` uses the same convention);
* quaternions x-y-z-w (PyBullet's order);
* poses are (4, 4) homogeneous transforms, metres and radians.

Why one module: the same conversions were written in several modules (types, urdf_model, scene_layout,
the CLI, a plugin); one copy keeps every caller numerically identical. Pure numpy, no other import.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = [
    "matrix_to_quat",
    "matrix_to_rpy",
    "pose_from_xyz_rpy",
    "quat_to_matrix",
    "quats_to_matrices",
    "rpy_to_matrix",
]


def rpy_to_matrix(rpy: Any) -> np.ndarray:
    """(3, 3) rotation of fixed-axis roll, pitch, yaw, rad (URDF: R = Rz(yaw) @ Ry(pitch) @ Rx(roll))."""
    roll, pitch, yaw = (float(a) for a in rpy)
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_to_rpy(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw), rad, of a (3, 3) rotation (or the rotation block of a (4, 4) pose), inverse
    of `rpy_to_matrix`: pitch in [-pi/2, pi/2], roll and yaw in (-pi, pi]. At pitch = +-pi/2 (gimbal
    lock) only roll -+ yaw is determined; the split returned is arbitrary."""
    R = np.asarray(R, dtype=float)
    roll = math.atan2(R[2, 1], R[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, R[2, 0])))
    yaw = math.atan2(R[1, 0], R[0, 0])
    return roll, pitch, yaw


def pose_from_xyz_rpy(xyz: Sequence[float] = (0.0, 0.0, 0.0), rpy: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """(4, 4) homogeneous transform from a translation (3,), m, and URDF roll-pitch-yaw (3,), rad."""
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(rpy)
    T[:3, 3] = [float(v) for v in xyz]
    return T


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion x-y-z-w of a (3, 3) rotation matrix (Shepperd's method; the sign is not
    normalised, q and -q are the same rotation)."""
    t = np.trace(R)
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        q = [0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif R[1, 1] > R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        q = [(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s]
    v = np.array(q)
    return v / np.linalg.norm(v)


def quat_to_matrix(q: Any) -> np.ndarray:
    """(3, 3) rotation of a quaternion (4,) x-y-z-w; it need not be unit length."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quats_to_matrices(q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations of (n, 4) quaternions x-y-z-w (vectorised `quat_to_matrix`)."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((q.shape[0], 3, 3))
    R[:, 0, 0] = 1 - 2 * (y * y + z * z)
    R[:, 0, 1] = 2 * (x * y - z * w)
    R[:, 0, 2] = 2 * (x * z + y * w)
    R[:, 1, 0] = 2 * (x * y + z * w)
    R[:, 1, 1] = 1 - 2 * (x * x + z * z)
    R[:, 1, 2] = 2 * (y * z - x * w)
    R[:, 2, 0] = 2 * (x * z - y * w)
    R[:, 2, 1] = 2 * (y * z + x * w)
    R[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return R
