"""The robot: the arm's kinematics, its URDF model and the gripper's geometry, built once per run
(`Robot.from_settings`) and handed down on the plugin context."""

from twin.robot.gripper import gripper_boxes, gripper_stroke_m
from twin.robot.robot import Robot

__all__ = ["Robot", "gripper_boxes", "gripper_stroke_m"]
