"""twin_croc's seed formulation, one CSQP solve (issue 28, in progress): over the warehouse wall from an
over-the-box guess, the plan keeps every proxy sphere out of the margin-grown wall at the knots and clear of
the wall itself between them, holds the step bound and the joint limits, and ends at the goal; the same
problem, re-targeted, solves another query."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("crocoddyl")
pytest.importorskip("mim_solvers")

from twin.plugin import UR5e
from twin_croc.ocp import SeedProblem
from twin_nmpc.model import TCP_FRAME
from twin_nmpc.params import NMPCParams
from twin_nmpc.spheres import robot_spheres

WALL = (np.array([-0.48, 0.09, 0.0]), np.array([-0.36, 0.39, 0.20]))  # the warehouse obstacle


def _down(p: np.ndarray) -> np.ndarray:
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[:3, 3] = p
    return T


def _over_the_box(kin: UR5e, q0: np.ndarray, goal: np.ndarray, height: float, n: int) -> np.ndarray:
    """The joints (n, 6) of a lift, a move across at `height` and a descent, through IK waypoints."""
    qs = [q0]
    p0 = kin.fk(q0)[:3, 3]
    for w in ([p0[0], p0[1], height], [goal[0], goal[1], height], goal):
        sols = kin.ik(_down(np.array(w)))
        qs.append(sols[int(np.argmin(np.abs(sols - qs[-1]).sum(axis=1)))])
    knots, t = np.linspace(0.0, 1.0, len(qs)), np.linspace(0.0, 1.0, n)
    Q = np.array(qs)
    return np.array([np.interp(t, knots, Q[:, j]) for j in range(6)]).T


def _clearance(prob: SeedProblem, qs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    c = prob.centres(qs)
    outside = np.linalg.norm(np.maximum(np.maximum(lo - c, c - hi), 0.0), axis=-1)
    return float((outside - prob.radii).min())


def test_a_solve_over_the_wall_keeps_every_sphere_out_and_reaches_the_goal():
    kin = UR5e()
    p = NMPCParams()
    prob = SeedProblem(kin, robot_spheres(p.tool_spheres, p.wrist_spheres), n_boxes=1, tcp_index=TCP_FRAME)
    home = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
    for start, goal in (([-0.57, 0.15, 0.275], [-0.28, 0.32, 0.105]), ([-0.62, 0.30, 0.275], [-0.28, 0.18, 0.105])):
        sols = kin.ik(_down(np.array(start)))
        q0 = sols[int(np.argmin(np.abs(sols - home).sum(axis=1)))]
        goal_p = np.array(goal)
        r = prob.solve(q0, np.zeros(6), goal_p, [WALL], _over_the_box(kin, q0, goal_p, 0.33, prob.horizon + 1))
        lo, hi = WALL
        assert _clearance(prob, r.qs, lo - prob.margin, hi + prob.margin) > -1e-4  # the hard rows, to CSQP's tolerance
        t = np.linspace(0.0, 1.0, 11)[:, None]
        dense = np.concatenate([a + t * (b - a) for a, b in zip(r.qs[:-1], r.qs[1:], strict=True)])
        assert _clearance(prob, dense, lo, hi) > 0.0  # between the knots too: clear of the wall itself
        assert np.abs(np.diff(r.qs, axis=0)).max() <= 0.15 + 1e-5
        assert np.all(r.qs >= kin.joint_limits[:, 0] - 1e-6) and np.all(r.qs <= kin.joint_limits[:, 1] + 1e-6)
        assert np.linalg.norm(kin.fk(r.qs[-1])[:3, 3] - goal_p) < 0.03, r.iterations
        assert r.converged and r.iterations < 50, r.iterations  # to CSQP's tolerance, not the iteration cap


def test_more_boxes_than_the_problem_has_rows_for_is_an_error():
    kin = UR5e()
    prob = SeedProblem(kin, robot_spheres([(0.0, 0.0, 0.0, 0.05)]), n_boxes=1, tcp_index=TCP_FRAME, horizon=5)
    q0 = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
    with pytest.raises(ValueError, match="2 boxes, the problem has rows for 1"):
        prob.solve(q0, np.zeros(6), np.zeros(3), [WALL, WALL], np.tile(q0, (6, 1)))
