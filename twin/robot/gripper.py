"""The gripper's geometry, read from the robot's URDF: its stroke and the boxes its collision shapes fill.

Why here: the tasks (where a grasp fits, what a jam touches), the planning scene (the stroke bounds the
opening) and the world read the same gripper; its geometry belongs to the robot, not to one task.
"""

from __future__ import annotations

import numpy as np

from twin.errors import ConfigError
from twin.robot.urdf_model import RobotModel, primitive_half_extents

__all__ = ["gripper_boxes", "gripper_stroke_m"]


def gripper_stroke_m(model: RobotModel) -> float:
    """Largest total finger opening, m: each finger moves half the opening (RobotModel convention), so
    the stroke is twice the smallest gripper-joint upper limit (0 without gripper joints)."""
    g = model.gripper_joints
    return 2.0 * min(model.joints[n].upper for n in g) if g else 0.0


def gripper_boxes(
    model: RobotModel, opening_m: float, *, where: str = "robot URDF"
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(lo (3,), hi (3,)) in the tcp frame of every collision shape of the gripper (the links below tool0)
    at a finger opening. The tcp's z axis points away from the flange, so when grasping from above a
    larger z is lower in the world. `where` names the URDF in the error for a non-primitive shape."""
    poses = model.link_poses(np.zeros((1, 6)), finger_opening=opening_m)
    T_inv = np.linalg.inv(poses["tcp"][0])
    out = []
    for name in model.link_names:
        up: str | None = name
        while up is not None and up != "tool0":
            up = model.parent_link(up)
        if up is None:  # not on the gripper
            continue
        for shape in model.links[name].shapes:
            try:
                half = primitive_half_extents(shape.kind, shape.size)
            except ValueError:
                raise ConfigError(f"{where}: gripper link {name!r} uses a {shape.kind}; primitives only") from None
            T = T_inv @ poses[name][0] @ shape.origin
            h = np.abs(T[:3, :3]) @ half
            out.append((T[:3, 3] - h, T[:3, 3] + h))
    return out
