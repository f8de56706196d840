"""nmpc keeps the arm from itself (issue 39): its NLP's self rows (`twin.planning.selfrows`, shared with croc) keep the
gripper and the held cube from the forearm and upper arm. The case is the transfer an unseen-seed campaign lost
(nominal warehouse: "transfer: nmpc: collision: the next segment would collide (forearm_link with
gripper_base)"), kept here as numbers: the arm at the pick, the cube in the closed fingers, the perceived
wall's box (extended in y) and a cube placed before, and the drop position with the orientation free, so the
wrist may fold the gripper into the forearm on the way."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("casadi")

from twin.collision.scene import PlanningScene
from twin.config import PlannerBlock, load_config
from twin.planning import densify, limits_from_settings, make_context, make_planner, plan_with
from twin.types import MotionRequest, Pose, PoseGoal

START = np.array([3.05449760925, -2.28710987024, -0.78610788941, -4.7807665962, -1.57079982884, 3.05451737132])
GOAL_POSITION = np.array([-0.28, -0.16, 0.105])
GOAL_QUAT = np.array([0.707106781187, 0.707106781187, 4.32978028118e-17, 4.32978028118e-17])
# the planning scene's run-time boxes: name -> (full size, centre), axis-aligned, base frame
BOXES = {
    "obstacle": ([0.120806412903, 1.30184485997, 0.200436754535], [-0.42102462676, 0.241221027901, 0.101012401568]),
    "placed_0": ([0.0707106781187, 0.0707106781187, 0.05], [-0.28, -0.3, 0.025]),
}
CUBE_M = 0.05
OPENING_M = 0.050537


def _case():
    settings = load_config("warehouse")
    scene = PlanningScene.from_settings(settings, unknown_fixtures="ignore")
    for name, (size, centre) in BOXES.items():
        T = np.eye(4)
        T[:3, 3] = centre
        scene.add_box(name, np.array(size), T)
    scene.set_gripper_opening(OPENING_M)
    scene.attach_box("cube", (CUBE_M,) * 3, np.eye(4))
    goal = PoseGoal(Pose(GOAL_POSITION, GOAL_QUAT), position_tolerance_m=0.03, orientation_tolerance_rad=None)
    request = MotionRequest(START, goal, limits_from_settings(settings))
    return settings, scene, request


def _closest_fold(scene: PlanningScene, qs: np.ndarray) -> float:
    """The least distance (m) along joints qs (m, 6) at which the scene's nearest pair is the forearm or upper
    arm and the gripper or the held cube (inf when that pair is never the nearest)."""
    out = np.inf
    for q in qs:
        d = scene.min_distance(q)
        arm, tool = sorted((d.robot_part, d.other), key=lambda n: n not in ("forearm_link", "upper_arm_link"))
        if arm in ("forearm_link", "upper_arm_link") and tool in (
            "gripper_base",
            "left_finger",
            "right_finger",
            "cube",
        ):
            out = min(out, d.distance)
    return out


def test_the_transfer_a_campaign_lost_to_a_self_collision_keeps_the_gripper_off_the_forearm():
    """Planned on its own (no lag, no tracking error), the seed's formulation takes the gripper within 2 mm of
    the forearm, which a run's tracking closed; the rows keep it about a centimetre off (twice the box margin
    and their tightening, less what the knots leave between them)."""
    settings, scene, request = _case()
    ctx = make_context(settings)
    closest = {}
    for slots in (4, 0):
        planner = make_planner(PlannerBlock(name="nmpc", params={"self_slots": slots}), ctx)
        res = plan_with(planner, request, scene, ctx)
        assert res.success, res.reason
        qs = densify(res.trajectory, ctx.kinematics, max_step_rad=0.01, max_step_m=0.005)
        assert not scene.in_collision_batch(qs).any()
        closest[slots] = _closest_fold(scene, qs)
    assert closest[0] < 0.004, closest
    assert closest[4] > 0.008, closest
