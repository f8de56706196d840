"""What a `World` hands out and takes in: the robot's joint and link names the physics drives, the ground
truth of an object and of a contact, and the checks of a caller's vectors. PyBullet-free, so the scene
builder, the stepper and the ground-truth reads share them without importing each other."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from twin.errors import InvalidRequestError
from twin.robot.kinematics import JOINT_NAMES
from twin.robot.urdf_model import RobotModel

__all__ = [
    "ARM_JOINT_NAMES",
    "FINGER_JOINT_NAMES",
    "FINGER_LINKS",
    "FINGER_TRAVEL_M",
    "ContactPoint",
    "ObjectState",
    "as_vec",
    "contact_points",
    "physics_parts_missing",
]

ARM_JOINT_NAMES = JOINT_NAMES
FINGER_JOINT_NAMES = ("left_finger_joint", "right_finger_joint")
FINGER_TRAVEL_M = 0.0425  # each finger, along tool0 x; the opening is the sum of both

FINGER_LINKS = ("left_finger", "right_finger")


@dataclass(frozen=True)
class ObjectState:
    """Ground truth of one scene object (base frame, metres, quaternion x-y-z-w).

    `size` is the object's (x, y, z) extent in its own frame (cylinders: diameter, diameter, height);
    `lying` is true when the object's z axis is closer to horizontal than vertical.
    """

    id: int
    name: str
    cls: str
    color: str | None
    position: np.ndarray
    orientation_xyzw: np.ndarray
    lying: bool
    size: tuple[float, float, float]


@dataclass(frozen=True)
class ContactPoint:
    """One contact or closest-point pair between body A (link A) and body B (link B).

    Link -1 is a body's base. `distance` < 0 is penetration. `normal_on_b` points from B to A.
    """

    body_a: int
    body_b: int
    link_a: int
    link_b: int
    position_on_a: np.ndarray
    position_on_b: np.ndarray
    normal_on_b: np.ndarray
    distance: float
    normal_force: float


def contact_points(raw: Sequence[Any]) -> list[ContactPoint]:
    """PyBullet's contact or closest-point tuples (`getContactPoints`, `getClosestPoints`) as values."""
    return [
        ContactPoint(
            body_a=p[1],
            body_b=p[2],
            link_a=p[3],
            link_b=p[4],
            position_on_a=np.array(p[5]),
            position_on_b=np.array(p[6]),
            normal_on_b=np.array(p[7]),
            distance=float(p[8]),
            normal_force=float(p[9]),
        )
        for p in raw
    ]


def as_vec(x: Any, n: int, what: str) -> np.ndarray:
    """`x` as a finite (n,) float array; an InvalidRequestError naming `what` otherwise (a caller's mistake
    must not reach PyBullet, which would take a NaN target silently)."""
    a = np.asarray(x, dtype=float)
    if a.shape != (n,):
        raise InvalidRequestError(f"{what} must have shape ({n},), got {a.shape}")
    if not np.isfinite(a).all():  # the method: np.all's wrapper costs more than the check (every physics step)
        raise InvalidRequestError(f"{what} must be finite, got {a.tolist()}")
    return a


def physics_parts_missing(model: RobotModel) -> list[str]:
    """The joints and links of twin's arm and gripper the physics drives or reads that a robot URDF lacks
    (a spheres-only collision model has no finger joints: it can plan but not run in physics)."""
    missing = [n for n in ARM_JOINT_NAMES + FINGER_JOINT_NAMES if n not in model.joints]
    return missing + [n for n in ("tool0", "tcp", *FINGER_LINKS) if n not in model.link_index]
