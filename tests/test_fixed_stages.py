"""Stages the compared planner does not plan choose, before they move, among equivalent ways the one that is
clear in the planning scene: a task row must fail only where the planner under test planned."""

from __future__ import annotations

import logging
import math
import re
from pathlib import Path

import numpy as np

from twin.compare.worker import task_attribution
from twin.config import load_config
from twin.tasks import run_task
from twin.tasks.cell import Cell, StageFailed, note_failure, top_down
from twin.types import ObjectOutcome
from twin.world import World

ROOT = Path(__file__).resolve().parent.parent
# the four cubes in a strip right behind the obstacle wall (its face at x = -0.48, y = 0.09 .. 0.39)
BESIDE_THE_WALL = (
    "world.objects.region_x=[-0.555,-0.55]",
    "world.objects.region_y=[0.06,0.42]",
    "world.objects.min_gap_m=0.01",
)
FAILED_ATTEMPT = re.compile(r"attempt \d+ failed: (\w+):")


def test_cubes_right_beside_the_obstacle_are_placed_with_no_fixed_stage_failing(caplog):
    # a transfer planner that carries every cube over the wall: whatever fails is the task script's
    settings = load_config(ROOT / "configs/warehouse.yaml", BESIDE_THE_WALL)
    with caplog.at_level(logging.INFO, logger="twin"):
        r = run_task(settings, seed=0, planner="ompl.rrtconnect")
    failed_stages = [m.group(1) for msg in caplog.messages if (m := FAILED_ATTEMPT.search(msg))]
    assert r.success_rate == 1.0, [(o.id, o.error) for o in r.objects if not o.placed]
    # before: "hover: ruckig.movej: collision (right_finger with obstacle)" for two of the four cubes
    assert failed_stages == [], failed_stages


def test_the_grasp_yaw_turns_the_fingers_away_from_the_obstacle():
    settings = load_config(ROOT / "configs/warehouse.yaml")
    with World(settings, seed=0, renderer="tiny") as world:
        cell = Cell(settings, world)
        cell.scene.add_box_bounds("obstacle", np.array([-0.48, 0.09, 0.0]), np.array([-0.36, 0.39, 0.20]))
        cell.open_gripper()
        c = np.array([-0.535, 0.24, 0.025])  # a cube 3 cm from the wall's face
        way_down = [c, c + [0, 0, 0.05], c + [0, 0, 0.10]]
        q = world.joint_positions()
        # the seed's yaw puts a finger into the wall
        assert cell.clearance_at(top_down(c, 0.0), q) < 0.0
        yaw, clearance = cell.choose_top_down_yaw(way_down, [0.0, math.pi / 4, math.pi / 2])
        assert clearance >= 0.01
        assert yaw == math.pi / 2
        # nothing clear: the clearest, and the caller is told how clear it is
        c_in = np.array([-0.515, 0.24, 0.025])  # 1 cm from it: no yaw fits
        yaw, clearance = cell.choose_top_down_yaw([c_in], [0.0, math.pi / 4, math.pi / 2])
        assert yaw == math.pi / 2 and clearance < 0.0


def test_the_way_home_avoids_a_straight_joint_motion_that_folds_the_arm_through_itself():
    settings = load_config(ROOT / "configs/warehouse.yaml")
    with World(settings, seed=0, renderer="tiny") as world:
        cell = Cell(settings, world)
        # the other elbow branch, as a sampling planner's transfer can leave the arm: the straight joint
        # motion home folds the forearm through the gripper
        q_flipped = np.array([-2.2, -1.6, -1.8, 1.83, -1.57, 3.66])
        home = np.asarray(settings.robot.home, dtype=float)
        assert not cell.scene.check_path(np.array([q_flipped, home])).free
        world.reset_joints(q_flipped)
        cell.settle(0.2)
        cell.move_joints_over("home", home)
        assert np.abs(world.joint_positions() - home).max() < 0.01
        stages = [(r.stage, r.status) for r in cell.records]
        assert stages[0][1] == "collision"  # the direct way was refused in planning, not moved
        assert all(s == "success" for _, s in stages[1:])


def _outcome(stage: str | None, planner: str | None = None) -> ObjectOutcome:
    return ObjectOutcome("o", "cube", None, "bin", False, error=f"{stage}: x", stage=stage, planner=planner)


def test_a_failed_row_is_attributed_to_the_compared_planner_only_for_its_own_stages():
    mine = task_attribution([_outcome("transfer", "ompl.rrt"), _outcome("descent", "toppra.movel")])
    assert mine["failed_stage"] == "transfer" and mine["failed_planner"] == "ompl.rrt"
    assert mine["failure_in"] == "planner"
    assert (mine["objects_failed_in_planner"], mine["objects_failed_elsewhere"]) == (1, 1)
    elsewhere = task_attribution([_outcome("perception"), _outcome("transfer", "ompl.rrt")])
    assert elsewhere["failure_in"] == "elsewhere" and elsewhere["failed_planner"] is None
    assert task_attribution([])["failure_in"] is None


def test_an_objects_failure_is_its_first_attempts_later_ones_are_added_to_the_reason():
    class Rec:
        error = failure = stage = planner = None

    rec = Rec()
    note_failure(rec, StageFailed("transfer", "dropped", failure="grasp_lost"), 1)
    note_failure(rec, StageFailed("descent", "toppra.movel: collision", failure="collision", planner="toppra.movel"), 2)
    assert (rec.stage, rec.planner, rec.failure) == ("transfer", None, "grasp_lost")
    assert rec.error == "transfer: dropped; attempt 2: descent: toppra.movel: collision"
