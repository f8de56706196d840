"""The robot: the arm's kinematics (`kinematics`, its compiled DH kernel, the UR model table `ur_models`),
its URDF (`urdf_model` reads one, `ur_urdf` writes twin's), the gripper's geometry (`gripper`), and the value
that holds them, built once per run (`Robot.from_settings`) and handed down on the plugin context."""

from twin.robot.gripper import gripper_boxes, gripper_stroke_m
from twin.robot.kinematics import URArm
from twin.robot.robot import Robot

__all__ = ["Robot", "URArm", "gripper_boxes", "gripper_stroke_m"]
