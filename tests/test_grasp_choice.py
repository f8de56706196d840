"""Grasps the gripper can hold (issue 39): no grasp across a side that needs the stroke's last millimetres
when another side fits; a lying spam, whose only top-down side does, is gripped where it fits best; and a
grasp that slipped is not tried again as it was."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
import pytest

import twin.tasks.robocup.task as robocup
from twin.config import load_config
from twin.robot import Robot
from twin.scene_layout import OBJECT_TEMPLATES
from twin.tasks import run_task
from twin.tasks.cell import Cell, GraspCheck, GripStatus
from twin.tasks.robocup.perception import ObjectEstimate
from twin.tasks.robocup.task import (
    STROKE_MARGIN_M,
    GraspChoice,
    choose_grasp,
    feasible_cube_yaw,
    grasp_sides,
    grip_width,
)

STROKE_M = 0.085  # the 2F-85's


def _est(cls: str, orientation: Literal["vertical", "horizontal"] = "vertical", yaw: float = 0.3) -> ObjectEstimate:
    """A perceived object: the grasp lookup's tcp height 35 mm above a table at z = 0, opened to the stroke."""
    grasp = np.array([-0.4, 0.1, 0.035, yaw, math.pi, 0.0, STROKE_M])
    return ObjectEstimate(
        cls,
        None,
        f"{cls}_0",
        1.0,
        orientation,
        orientation,
        np.zeros(3),
        yaw,
        grasp,
        "icp",
        None,
        100,
        0.05,
        None,
    )


def test_a_lying_spam_has_one_top_down_side_and_it_needs_the_strokes_last_millimetres():
    """Lying, the spam's 60 mm side is its height: from above only its 83 and 102 mm sides face the fingers,
    and 102 mm is wider than the stroke. The 83 mm side (2 mm to spare) is the grasp that exists."""
    sides = {g.side: g for g in grasp_sides(_est("spam", "horizontal"), STROKE_M)}
    assert sides["short"].width_m == pytest.approx(0.083) and sides["long"].width_m == pytest.approx(0.102)
    assert sides["long"].margin_m < 0 and sides["short"].margin_m == pytest.approx(0.002)
    g = choose_grasp(_est("spam", "horizontal"), STROKE_M)
    assert g.side == "short" and g.tight and g.width_m == pytest.approx(0.083) and g.yaw_offset_rad == 0.0


def test_every_other_class_and_orientation_is_gripped_with_the_margin_to_spare():
    for cls, orient, width in [
        ("spam", "vertical", 0.060),
        ("cube", "vertical", 0.075),
        ("bottle", "vertical", 0.068),
        ("bottle", "horizontal", 0.068),
        ("can", "vertical", 0.066),
        ("can", "horizontal", 0.066),
        ("marker", "vertical", 0.021),
        ("marker", "horizontal", 0.021),
    ]:
        g = choose_grasp(_est(cls, orient), STROKE_M)
        assert g.width_m == pytest.approx(width) and not g.tight and g.margin_m >= STROKE_MARGIN_M, (cls, orient)
        assert grip_width(_est(cls, orient), STROKE_M) == pytest.approx(width)


def test_a_side_in_the_strokes_last_millimetres_gives_way_to_one_that_fits():
    """A cube's diagonal (the seed's self-locking grip) is taken where it fits with the margin to spare; with
    a stroke it fills to its last millimetres, the cube is gripped across a face instead."""
    diag = 0.075 * math.sqrt(2.0)
    roomy = choose_grasp(_est("cube"), diag + 2 * STROKE_MARGIN_M)
    assert roomy.side == "diagonal" and roomy.yaw_offset_rad == 0.0
    tight = choose_grasp(_est("cube"), diag + STROKE_MARGIN_M / 3)  # fits, but in its last 2 mm
    assert tight.side == "face" and tight.width_m == pytest.approx(0.075) and not tight.tight
    assert feasible_cube_yaw(_est("cube", yaw=0.3), 0.3, diag + STROKE_MARGIN_M / 3) == pytest.approx(0.3 - math.pi / 4)
    # the 85 mm stroke: the diagonal does not fit at all
    assert choose_grasp(_est("cube"), STROKE_M).side == "face"
    # a lying bottle in a stroke 2 mm wider than it: its length is no side a gripper closes across, so the
    # one side there is is gripped, and said to be tight
    g = choose_grasp(_est("bottle", "horizontal"), 0.070)
    assert g.side == "short" and g.tight


def test_a_grasp_that_slipped_is_followed_by_a_different_one():
    """After a slip: another side that fits, where the object has one; where it has none (the lying spam),
    the same side deeper, squeezed harder and lifted slower."""
    spam = _est("spam", "horizontal")
    first = choose_grasp(spam, STROKE_M)
    again = choose_grasp(spam, STROKE_M, slipped=(first,), lower_max_m=0.015, force_max_n=235.0)
    assert again != first and again.side == first.side
    assert again.lower_m == pytest.approx(0.015) and again.force_n == 235.0 and again.lift_speed < 1.0
    # a cube with room for both: the face after the diagonal slipped
    roomy = 0.075 * math.sqrt(2.0) + 2 * STROKE_MARGIN_M
    diag = choose_grasp(_est("cube"), roomy)
    assert choose_grasp(_est("cube"), roomy, slipped=(diag,)).side == "face"
    # nothing deeper to go: still harder and slower, never the same grasp
    g = choose_grasp(_est("can"), STROKE_M, slipped=(choose_grasp(_est("can"), STROKE_M),), force_max_n=235.0)
    assert g.lower_m == 0.0 and g.force_n == 235.0 and g.lift_speed < 1.0


def test_the_deepest_grasp_keeps_the_fingertips_off_the_table_and_the_palm_off_the_top():
    s = load_config("robocup")
    robot = Robot.from_settings(s)
    for cls, orient in [("spam", "horizontal"), ("spam", "vertical"), ("cube", "vertical"), ("bottle", "vertical")]:
        est = _est(cls, orient)
        z = s.perception.robocup.grasp[f"{cls}_{orient}"].z_grasp_m  # the table at 0
        low = robocup._lowest_tcp(s, robot, est, z, STROKE_M)
        assert low <= z + 1e-9
        boxes = robot.gripper_boxes(STROKE_M)
        tip = max(hi[2] for _, hi in boxes)
        assert low - tip >= robocup._TIP_CLEARANCE_M - 1e-9  # fingertips above the table
        height = OBJECT_TEMPLATES[cls].height(orient == "horizontal")
        palm = max(hi[2] for lo, hi in boxes if lo[0] < 0.0 < hi[0])
        assert low - palm >= height + robocup._PALM_CLEARANCE_M - 1e-9  # the palm above its top
    spam = _est("spam", "horizontal")
    # 15 mm deeper than the lookup
    assert robocup._lowest_tcp(s, robot, spam, 0.035, STROKE_M) == pytest.approx(0.020)


def test_after_a_slip_on_the_ascent_the_robot_grips_the_spam_differently(monkeypatch):
    """A physics run with one lying spam: its first grasp is reported slipped on the ascent (the gripper's
    reading replaced once); the second attempt grips it deeper, harder and slower, and places it."""
    s = load_config("robocup", overrides=["world.objects.items=[{class: spam}]", "world.objects.lying_probability=1.0"])
    used: list[GraspChoice] = []
    real_pick = robocup._pick_and_place

    def pick(cell, est, bin_, placed, grasp=None, avoid_yaws=()):
        used.append(grasp)
        return real_pick(cell, est, bin_, placed, grasp, avoid_yaws)

    real_check = Cell.check_holding
    lied: list[bool] = []

    def check_holding(self):
        r = real_check(self)
        if not lied and self.records and self.records[-1].stage == "ascent":
            lied.append(True)
            return GraspCheck(GripStatus.LOST, 0.0, "the fingers closed (a slip, as the test reports it)")
        return r

    monkeypatch.setattr(robocup, "_pick_and_place", pick)
    monkeypatch.setattr(Cell, "check_holding", check_holding)
    r = run_task(s, seed=3)
    assert lied and len(used) == 2, used
    first, second = used
    assert first is not None and second is not None and first.tight and second != first
    assert second.lower_m > 0.01 and second.force_n == 235.0 and second.lift_speed < 1.0
    assert r.objects[0].placed, r.objects[0].error
