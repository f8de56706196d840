"""Problems and twin's motion queries, one into the other.

A compare query (`twin.compare.spec.QuerySpec` as a dict) gives a pose goal as x, y, z, roll, pitch,
yaw; a problem set, as MoveIt does, as position and quaternion. The conversion is exact up to float
rounding (1e-15), so a problem exported and planned again is the same problem.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from twin.problems.problem_set import JointGoalSpec, PoseGoalSpec, PoseSpec, Problem
from twin.transforms import matrix_to_rpy, pose_from_xyz_rpy

__all__ = ["problem_of_query", "query_of_problem"]


def problem_of_query(query: dict[str, Any], *, id: str, time_limit_s: float, seed: int) -> Problem:
    """A Problem from a compare query dict (start, goal | goal_pose, frame, orientation_free, tolerance)."""
    goal: JointGoalSpec | PoseGoalSpec
    if query.get("goal") is not None:
        goal = JointGoalSpec(joints=[float(v) for v in query["goal"]])
    else:
        x, y, z, r, p, yw = (float(v) for v in query["goal_pose"])
        pose = PoseSpec.of(pose_from_xyz_rpy((x, y, z), (r, p, yw)))
        goal = PoseGoalSpec(
            kind="position" if query.get("orientation_free") else "pose",
            pose=pose,
            frame=query.get("frame", "tcp"),
            position_tolerance_m=query.get("position_tolerance_m"),
        )
    return Problem(
        id=id, start=[float(v) for v in query["start"]], goal=goal, time_limit_s=time_limit_s, seed=int(seed)
    )


def query_of_problem(problem: Problem) -> dict[str, Any]:
    """The compare query dict of a Problem (what `twin.compare.worker` plans)."""
    out: dict[str, Any] = {
        "start": list(problem.start),
        "goal": None,
        "goal_pose": None,
        "frame": "tcp",
        "orientation_free": False,
        "position_tolerance_m": None,
    }
    g = problem.goal
    if isinstance(g, JointGoalSpec):
        out["goal"] = list(g.joints)
        return out
    T = g.pose.matrix()
    r, p, y = matrix_to_rpy(T[:3, :3])
    out["goal_pose"] = [*(float(v) for v in np.asarray(T[:3, 3])), r, p, y]
    out["frame"] = g.frame
    out["orientation_free"] = g.kind == "position"
    out["position_tolerance_m"] = g.position_tolerance_m
    return out
