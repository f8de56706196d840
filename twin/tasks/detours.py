"""The ways round a motion the stage's planner refuses: the fixed stages' fallbacks, moved through the cell.

When a stage's planner refuses the direct way because it runs into something (planned, not moved), the cell
goes another way: a wrist-first or arm-first joint move, up and over the planning scene, another IK branch of
the same pose. Each way is chosen in the planning scene before anything moves (`twin.tasks.ways`) and then
followed with the cell's own checked moves, so every motion is planned, executed and recorded as any other.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np

from twin.tasks.stage_failure import PATH_COLLIDES, StageFailed, or_refusal
from twin.tasks.ways import WayDown, other_ways
from twin.types import MotionRequest, MotionResult, Status

if TYPE_CHECKING:
    from twin.tasks.cell import Cell

__all__ = [
    "move_joints_over",
    "move_pose_over",
    "move_pose_turned",
    "reach_hover",
    "reach_posture",
    "rise_to_safe_height",
]

log = logging.getLogger("twin")


def rise_to_safe_height(cell: Cell) -> float:
    """Move the tcp straight up to `safe_height` (no move when it is there already); that height."""
    z = cell.safe_height()
    T = cell.kin.fk(cell.world.joint_positions())
    if T[2, 3] < z:
        T[2, 3] = z
        cell.move_pose("ascent", T)
    return z


def move_joints_over(cell: Cell, stage: str, q: np.ndarray) -> MotionResult:
    """`Cell.move_joints_over`: the direct joint move, else the first of `other_ways` that is clear."""
    q = cell.nearest_turn(np.asarray(q, dtype=float))
    refused = or_refusal(lambda: cell.move_joints(stage, q))
    if isinstance(refused, MotionResult):
        return refused
    q0 = cell.world.joint_positions()
    ways = other_ways(q0, q, cell.ways.raised(q0))
    i = cell.ways.first_clear([[q0, *via, q] for _, via, _ in ways])
    if i is not None:
        name, via, rises = ways[i]
        log.info("%s: the direct way runs into something (%s); going %s", stage, refused.reason, name)
        if rises:
            rise_to_safe_height(cell)
        for qv in via[1:] if rises else via:
            cell.move_joints(stage, qv)
        return cell.move_joints(stage, q)
    log.info(
        "%s: the direct way runs into something and no other way is clear from %s",
        stage,
        np.round(q0, 3).tolist(),
    )
    raise refused


def reach_posture(cell: Cell, stage: str, q: np.ndarray) -> MotionResult:
    """`Cell.reach_posture`: `move_joints_over`, and once more after recovering from a contact on the way."""
    try:
        return cell.move_joints_over(stage, q)
    except StageFailed as e:
        if e.failure != "execution_contact":
            raise
        log.info("%s: stopped on the way (%s); recovering and trying again", stage, e.reason)
    cell.recover()
    return cell.move_joints_over(stage, q)


def reach_hover(cell: Cell, way: WayDown, stage: str = "hover") -> MotionResult:
    """`Cell.reach_hover`: to the hover in the way's IK branch, else over the top in that branch."""
    done = or_refusal(lambda: cell.move_joints_over(stage, way.q_hover))
    if isinstance(done, MotionResult):
        return done
    above = np.array(way.hover, dtype=float)
    above[2, 3] = max(above[2, 3], cell.safe_height())
    sols = [cell.nearest_turn(q) for q in cell.kin.ik(above, all_wraps=False)]
    if above[2, 3] <= way.hover[2, 3] or not sols:
        raise done
    q_above = min(sols, key=lambda q: float(np.abs(q - way.q_hover).max()))
    log.info("%s: no clear way to the chosen hover (%s); over the top", stage, done.reason)
    rise_to_safe_height(cell)
    cell.move_joints_over(stage, q_above)
    return cell.move_pose("descent", way.hover)


def move_pose_over(cell: Cell, stage: str, T_tcp: np.ndarray) -> MotionResult:
    """`Cell.move_pose_over`: the direct move, else a clear IK branch, else over the top, else by way of home."""
    done = or_refusal(lambda: cell.move_pose(stage, T_tcp))
    if isinstance(done, MotionResult):
        return done
    why = done.reason
    q0 = cell.world.joint_positions()
    sols = cell.ways.branches(T_tcp, q0)
    i = cell.ways.first_clear([[q0, q] for q in sols])
    if i is not None:
        log.info("%s: the direct way runs into something (%s); going to a clear configuration", stage, why)
        done = or_refusal(lambda: cell.move_joints(stage, sols[i]))
        if isinstance(done, MotionResult):
            return done
        why = done.reason
    log.info("%s: the direct way runs into something (%s); going over the top", stage, why)
    above = np.array(T_tcp, dtype=float)
    above[2, 3] = max(above[2, 3], cell.safe_height())
    try:
        rise_to_safe_height(cell)
        result = cell.move_pose(stage, above)
    except StageFailed as e:
        if e.moved or e.failure not in PATH_COLLIDES:
            raise
        log.info("%s: over the top runs into something too (%s); by way of home", stage, e.reason)
        cell.move_joints_over("home", np.asarray(cell.settings.robot.home, dtype=float))
        result = cell.move_pose(stage, above)
    if above[2, 3] > T_tcp[2, 3]:
        result = cell.move_pose("descent", T_tcp)
    return result


def move_pose_turned(cell: Cell, stage: str, T_tcp: np.ndarray) -> MotionResult:
    """`Cell.move_pose_turned`: the short straight move, else the arm turned where it is to another IK branch
    of the same pose from which the stage's planner plans the move (both planned before anything moves)."""
    refused = or_refusal(lambda: cell.move_pose(stage, T_tcp))
    if isinstance(refused, MotionResult):
        return refused
    q0 = cell.world.joint_positions()
    turns = [q for q in cell.ways.branches(cell.kin.fk(q0), q0) if float(np.abs(q - q0).max()) > 1e-3]
    planner, goal = cell.stage_planner(stage), cell.pose_goal(stage, T_tcp)
    turns = [
        q
        for q in turns
        if planner.plan(MotionRequest(q, goal, cell.limits, seed=cell.world.seed), cell.scene).status is Status.SUCCESS
    ]
    i = cell.ways.first_clear([[q0, q] for q in turns])
    if i is None:
        raise refused
    log.info("%s: the way runs into something (%s); turning the arm where it is first", stage, refused.reason)
    cell.move_joints("align", turns[i])
    return cell.move_pose(stage, T_tcp)
