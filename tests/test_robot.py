"""The robot value (`twin.robot.Robot`): built once from `settings.robot` and handed down on the plugin
context; no planner falls back to a default arm."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from twin.config import load_config
from twin.errors import ConfigError
from twin.planning import make_context, make_planner
from twin.robot import Robot

PLANNERS = ["ompl.rrtconnect", "ruckig.movej", "toppra.movel"]


def test_the_robot_is_the_configured_arm_with_its_urdf_read_once() -> None:
    ur10e = Robot.from_settings(load_config("robocup", ["robot.model=ur10e"]))
    assert ur10e.name == "ur10e" and ur10e.urdf_path.name == "ur10e.urdf"
    assert ur10e.arm.urdf_mismatch(ur10e.model) is None  # the collision model is that arm
    assert ur10e.max_opening_m == pytest.approx(0.085)
    # the gripper's boxes open with the fingers (each finger's inner face half the opening from the tcp),
    # and a caller cannot change the robot's copy
    for opening in (0.0, 0.08):
        boxes = ur10e.gripper_boxes(opening)
        assert min(lo[0] for lo, _ in boxes if lo[0] >= 0) == pytest.approx(opening / 2)
    opened = ur10e.gripper_boxes(0.08)
    opened[0][0][:] = 9.0
    assert not np.any(ur10e.gripper_boxes(0.08)[0][0] == 9.0)


def test_a_urdf_of_another_arm_is_refused_when_the_robot_is_built() -> None:
    s = load_config("robocup", ["robot.model=ur10e", "robot.urdf=urdf/ur5e.urdf"])
    with pytest.raises(ConfigError, match=r"robot\.urdf urdf/ur5e\.urdf is not the arm of robot\.model ur10e"):
        Robot.from_settings(s)


@pytest.mark.parametrize("name", PLANNERS)
def test_a_planner_plans_the_context_s_arm_and_has_no_default_one(name: str) -> None:
    context = make_context(load_config("robocup", ["robot.model=ur10e"]))
    planner = make_planner(name, context).inner
    assert planner.kin is context.robot.arm and planner.kin.model == "ur10e"
    # without a context there is no arm to plan for: the constructor requires one (no silent UR5e)
    param = inspect.signature(type(planner).__init__).parameters["context"]
    assert param.default is inspect.Parameter.empty
    with pytest.raises(TypeError):
        type(planner)(None)  # type: ignore[call-arg]


def test_ur5e_is_a_deprecated_alias_of_the_arm() -> None:
    import twin
    import twin.plugin
    from twin.robot import URArm

    for module in (twin, twin.plugin):
        with pytest.warns(DeprecationWarning, match="use .*URArm"):
            assert module.UR5e is URArm


def test_the_planning_scene_takes_the_robot_s_model_and_sphere_cover() -> None:
    from twin.collision import PlanningScene

    robot = Robot.from_settings(load_config("robocup"))
    scene = PlanningScene.from_settings(load_config("robocup"), robot=robot)
    assert scene.model is robot.model
    body = scene._body  # the robot's collision body: its covers are the robot's, not made again
    assert len(body._shape_covers) == len(robot.sphere_cover) > 0
    assert all(a is b for a, b in zip(body._shape_covers, robot.sphere_cover, strict=True))
    assert all(a is b for a, b in zip(scene.padded(0.01)._body._shape_covers, robot.sphere_cover, strict=True))
