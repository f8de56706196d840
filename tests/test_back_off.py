"""Recovery that recovers (issue 27): a start in collision in the planning scene after a contact (the gripper
inside an obstacle perceived a little off) names the pair and is backed off from along the way that
separates it, bounded, instead of ending the run."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from twin.config import load_config
from twin.tasks.cell import Cell, StageFailed, top_down
from twin.tasks.recovery import back_off
from twin.types import JointGoal, MotionRequest, Status
from twin.world import World

RENDERER = "tiny"
TCP_XYZ = (-0.45, 0.05, 0.15)  # above the table, clear of everything real


def _cell_at(world: World) -> tuple[Cell, np.ndarray]:
    """A cell whose arm stands with the tcp pointing down at TCP_XYZ (the IK solution nearest home)."""
    s = world.settings
    cell = Cell(s, world)
    sols = cell.kin.ik(top_down(TCP_XYZ, 0.0))
    q = sols[int(np.argmin(np.abs(sols - np.array(s.robot.home)).sum(axis=1)))]
    world.reset_joints(q)
    world.step(10)
    return cell, cell.kin.fk(world.joint_positions())


def _box_pose(xyz: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = xyz
    return T


@pytest.fixture
def world():
    s = load_config("robocup", ["world.objects.items=[]"])
    with World(s, seed=0, renderer=RENDERER) as w:
        yield w


def test_a_start_inside_a_perceived_box_is_backed_off_from_and_the_stage_arrives(world, caplog):
    """The gripper 1.6 cm deep in a box the scene holds (what a box perceived 2 cm off looks like after a
    contact): physics is free, the planning scene is not. The home move backs off, says the pair, arrives;
    the back-off went away from the box (it never went deeper) and stayed within a few cm."""
    cell, T0 = _cell_at(world)
    home = np.array(world.settings.robot.home)
    cell.scene.add_box("seen_box", [0.12, 0.06, 0.06], _box_pose(T0[:3, 3] + [0.0, 0.025, 0.03]))
    q0 = world.joint_positions()
    hit = cell.scene.min_distance(q0)
    assert cell.scene.in_collision(q0) and hit.other == "seen_box" and hit.distance < -0.01
    assert not world.unexpected_contacts()
    # the planner names the pair it refuses the start for
    refused = cell.planner("movej").plan(MotionRequest(q0, JointGoal(home), cell.limits), cell.scene)
    assert refused.status is Status.INVALID_START and f"({hit.robot_part} with seen_box)" in refused.reason
    with caplog.at_level(logging.INFO, logger="twin"):
        cell.move_joints("home", home)
    np.testing.assert_allclose(world.joint_positions(), home, atol=1e-3)
    said = caplog.text
    assert f"home: the start was in collision ({hit.robot_part} with seen_box); backed off" in said, said
    backed = [r for r in cell.records if r.stage == "home"]
    assert [r.status for r in backed] == ["invalid_start", "success"]


@pytest.mark.parametrize("lid", [False, True])
def test_the_back_off_moves_out_along_the_separating_direction_and_not_into_anything_else(world, lid):
    """The fingertips 1.75 cm deep in a box the scene holds below and beside them: the back-off goes up,
    the way out. With a lid 1 cm above the wrist, up would hit the lid: it goes away from the box (-y)
    instead. Either way at most 5 cm, one motion, and it ends clear of everything."""
    cell, T0 = _cell_at(world)
    p0 = T0[:3, 3]
    cell.scene.add_box("seen_box", [0.12, 0.12, 0.04], _box_pose(p0 + [0.0, 0.04, -0.01]))
    if lid:
        cell.scene.add_box("lid", [0.12, 0.12, 0.02], _box_pose(p0 + [0.0, 0.0, 0.30]))
        assert cell.scene.min_distance(world.joint_positions(), include_self=False).other == "seen_box"
    result = back_off(cell)
    assert result.clear, result.reason
    assert result.pair.endswith("with seen_box") and result.tries == 1
    q = world.joint_positions()
    assert not cell.scene.in_collision(q)
    moved = cell.kin.fk(q)[:3, 3] - p0
    assert np.linalg.norm(moved) <= 0.0501, moved
    if lid:
        assert moved[1] < -0.02 and moved[2] < 0.01, moved  # away from the box, not up into the lid
    else:
        assert moved[2] > 0.015 and abs(moved[1]) < 0.002, moved  # straight up
    assert not world.unexpected_contacts()


def test_deep_inside_a_big_box_backing_off_fails_in_one_line_naming_the_pair(world, caplog):
    """The whole gripper and wrist inside a 40 cm box: no move of a few cm gets out. The stage fails at
    once, in one line that names the pair and says why backing off failed, and the arm has not moved."""
    cell, T0 = _cell_at(world)
    cell.scene.add_box("big_box", [0.4, 0.4, 0.4], _box_pose(T0[:3, 3] + [0.0, 0.0, 0.1]))
    q0 = world.joint_positions()
    hit = cell.scene.min_distance(q0)
    with caplog.at_level(logging.INFO, logger="twin"), pytest.raises(StageFailed) as err:
        cell.move_joints("capture", np.array(world.settings.camera.capture_pose))
    reason = str(err.value)
    assert "\n" not in reason
    assert reason.startswith(f"capture: ruckig.movej: invalid_start: the start is in collision ({hit.robot_part}")
    assert "with big_box" in reason and "backing off failed: " in reason, reason
    assert err.value.failure == "start_in_collision" and not err.value.moved
    np.testing.assert_allclose(world.joint_positions(), q0, atol=1e-4)
    assert back_off(cell).tries == 0  # no motion was tried: none was checked out


def test_backing_off_is_bounded_by_its_motions_when_the_arm_lags_behind_them():
    """A controller that lags 1 s behind its targets (`robot.tracking_time_constant_s`, a fault model) stops
    each back-off short of clear: the back-off gives up after `max_tries` motions and says so."""
    s = load_config("robocup", ["world.objects.items=[]", "robot.tracking_time_constant_s=1.0"])
    with World(s, seed=0, renderer=RENDERER) as world:
        cell, T0 = _cell_at(world)
        world.step(1000)  # the lagging controller has caught up with the start
        cell.scene.add_box("seen_box", [0.12, 0.12, 0.04], _box_pose(T0[:3, 3] + [0.0, 0.04, -0.01]))
        for max_tries in (1, 2):
            result = back_off(cell, max_tries=max_tries)
            assert not result.clear and result.tries == max_tries, result
            assert result.reason.startswith(f"backing off failed: still in collision after {max_tries} back-off")
            assert "\n" not in result.reason and result.pair.endswith("with seen_box")


def test_a_finger_pressed_onto_a_bin_wall_backs_off_it_without_a_protective_stop(world):
    """The left finger pressed onto the wall of bin_blue (in physics as in the planning scene, as after a
    stop against it): the back-off moves off the wall it touches as it starts; the safety monitor allows
    that retreat (it would stop a move into anything new)."""
    cell = Cell(world.settings, world)
    home = np.array(world.settings.robot.home)
    sols = cell.kin.ik(top_down((-0.29, 0.45, 0.13), 0.0))  # the wall's top is at z 0.12, x -0.25..-0.24
    world.reset_joints(sols[int(np.argmin(np.abs(sols - home).sum(axis=1)))])
    world.step(20)
    assert world.unexpected_contacts() == [("left_finger", "bin_blue")]
    assert cell.scene.in_collision(world.joint_positions())
    result = back_off(cell)
    assert result.clear and result.pair == "left_finger with bin_blue", result
    assert not world.unexpected_contacts() and not cell.scene.in_collision(world.joint_positions())
