"""twin_croc's horizon problem, one CSQP solve of the seed formulation: over the warehouse wall from an
over-the-box guess, the plan keeps every proxy sphere out of the margin-grown wall at the knots and clear of
the wall itself between them, holds the step and acceleration bounds and the joint limits, and ends at the
goal; the same problem, re-targeted, solves another query, and warm-started from its own solution shifted by
a step it is done in a few iterations."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("crocoddyl")
pytest.importorskip("mim_solvers")

from twin.planning.proxy_spheres import TCP_FRAME, robot_spheres
from twin.plugin import URArm
from twin_croc.ocp import HorizonProblem
from twin_croc.rows import close_pairs, sphere_bounds
from twin_nmpc.params import NMPCParams

WALL = (np.array([-0.48, 0.09, 0.0]), np.array([-0.36, 0.39, 0.20]))  # the warehouse obstacle


def _down(p: np.ndarray) -> np.ndarray:
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[:3, 3] = p
    return T


def _over_the_box(kin: URArm, q0: np.ndarray, goal: np.ndarray, height: float, n: int) -> np.ndarray:
    """The joints (n, 6) of a lift, a move across at `height` and a descent, through IK waypoints."""
    qs = [q0]
    p0 = kin.fk(q0)[:3, 3]
    for w in ([p0[0], p0[1], height], [goal[0], goal[1], height], goal):
        sols = kin.ik(_down(np.array(w)))
        qs.append(sols[int(np.argmin(np.abs(sols - qs[-1]).sum(axis=1)))])
    knots, t = np.linspace(0.0, 1.0, len(qs)), np.linspace(0.0, 1.0, n)
    Q = np.array(qs)
    return np.array([np.interp(t, knots, Q[:, j]) for j in range(6)]).T


def _clearance(prob: HorizonProblem, qs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    c = prob.centres(qs)
    outside = np.linalg.norm(np.maximum(np.maximum(lo - c, c - hi), 0.0), axis=-1)
    return float((outside - prob.radii).min())


def _rows(prob: HorizonProblem, qs: np.ndarray, margin: float = 0.01) -> np.ndarray:
    c = prob.centres(qs)
    boxes = [("wall", *WALL)]
    pairs = close_pairs(c, prob.radii, boxes, margin, None)
    return sphere_bounds(c, prob.radii, boxes, pairs, margin=margin, tighten=0.002)


def test_a_solve_over_the_wall_keeps_every_sphere_out_and_reaches_the_goal():
    kin = URArm()
    p = NMPCParams()
    sph = robot_spheres(p.tool_spheres, p.wrist_spheres)
    prob = HorizonProblem(kin, sph, tcp_index=TCP_FRAME)
    home = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
    step, accel = np.full(6, 0.15), np.full(6, 0.05)
    for start, goal in (([-0.57, 0.15, 0.275], [-0.28, 0.32, 0.105]), ([-0.62, 0.30, 0.275], [-0.28, 0.18, 0.105])):
        sols = kin.ik(_down(np.array(start)))
        q0 = sols[int(np.argmin(np.abs(sols - home).sum(axis=1)))]
        goal_p = np.array(goal)
        guess = _over_the_box(kin, q0, goal_p, 0.33, prob.horizon + 1)
        r = prob.solve(
            q0,
            np.zeros(6),
            goal_p,
            _rows(prob, guess),
            step_bound=step,
            accel_bound=accel,
            guess=guess,
            max_iterations=2,
        )
        for _ in range(20):  # rounds, the faces chosen again on each iterate (as twin_croc.planner does)
            if r.converged and np.array_equal(_rows(prob, r.qs), prob._bounds):
                break
            r = prob.solve(
                q0, np.zeros(6), goal_p, _rows(prob, r.qs), step_bound=step, accel_bound=accel, max_iterations=2
            )
        lo, hi = WALL
        assert _clearance(prob, r.qs, lo - 0.01, hi + 0.01) > -1e-4  # the hard rows, to CSQP's tolerance
        t = np.linspace(0.0, 1.0, 11)[:, None]
        dense = np.concatenate([a + t * (b - a) for a, b in zip(r.qs[:-1], r.qs[1:], strict=True)])
        assert _clearance(prob, dense, lo, hi) > 0.0  # between the knots too: clear of the wall itself
        assert np.abs(np.diff(r.qs, axis=0)).max() <= 0.15 + 1e-5
        assert np.abs(np.diff(np.vstack([np.zeros(6), np.diff(r.qs, axis=0)]), axis=0)).max() <= 0.05 + 1e-5
        assert np.all(r.qs >= kin.joint_limits[:, 0] - 1e-6) and np.all(r.qs <= kin.joint_limits[:, 1] + 1e-6)
        assert np.linalg.norm(kin.fk(r.qs[-1])[:3, 3] - goal_p) < 0.03, r.iterations
        shifted = np.vstack([r.qs[1:], r.qs[-1:]])
        w = prob.solve(
            r.qs[1],
            r.steps[1],
            goal_p,
            _rows(prob, shifted),
            step_bound=step,
            accel_bound=accel,
            shift=1,
            max_iterations=6,
        )
        assert w.iterations <= 6
        assert np.linalg.norm(kin.fk(w.qs[-1])[:3, 3] - goal_p) < 0.03
        assert _clearance(prob, w.qs, lo - 0.01, hi + 0.01) > -1e-4


def test_sphere_bounds_keep_each_sphere_beyond_a_face_of_every_near_box_over_both_knots_of_a_step():
    """Two boxes side by side, a sphere moving over both: each knot bounds z from below by the higher need
    (one row for both boxes), and a knot holds the bounds of the steps on both sides."""
    boxes = [
        ("a", np.array([0.0, 0.0, 0.0]), np.array([0.1, 0.1, 0.1])),
        ("b", np.array([0.1, 0.0, 0.0]), np.array([0.2, 0.1, 0.3])),
    ]
    xs = np.array([0.05, 0.15, 0.25])
    c = np.stack([xs, np.full(3, 0.05), np.full(3, 0.4)], axis=1)[:, None, :]  # (3 knots, 1 sphere, 3)
    b = sphere_bounds(c, np.array([0.05]), boxes, {(0, 0), (0, 1)}, margin=0.01, tighten=0.0)
    assert np.all(b[0, 0, 0] == -np.inf) and np.all(b[0, 0, 1] == np.inf)  # the measured state: free
    assert b[1, 0, 0, 2] == pytest.approx(0.3 + 0.01 + 0.05)  # box b's top, from both steps
    assert b[2, 0, 0, 2] == pytest.approx(0.3 + 0.01 + 0.05)  # step 1 (over b and past it) still over b
    assert np.all(b[:, 0, 1] == np.inf) and np.all(b[:, 0, 0, :2] == -np.inf)  # nothing else bounded


def test_sphere_bounds_always_leave_room_however_the_boxes_and_spheres_lie():
    """Random plans, boxes and spheres (walls closer than a sphere, plans through boxes): every lower bound is
    below its upper bound, which crocoddyl requires of a constraint row."""
    rng = np.random.default_rng(1)
    for _ in range(200):
        c = rng.uniform(-0.5, 0.5, (7, 3, 3))
        boxes = []
        for b in range(4):
            lo = rng.uniform(-0.5, 0.3, 3)
            boxes.append((str(b), lo, lo + rng.uniform(0.01, 0.3, 3)))
        pairs = {(s, b) for s in range(3) for b in range(4)}
        out = sphere_bounds(c, rng.uniform(0.01, 0.1, 3), boxes, pairs, margin=0.01, tighten=0.002)
        assert np.all(out[:, :, 0] < out[:, :, 1])


def test_a_sphere_passing_over_a_box_stays_above_its_top_on_the_way_there():
    """Before the plan is over the box, a sphere already above the top is bounded by the top face, not by the
    side it is farther out of (which would let the cost pull it down against that side)."""
    box = [("wall", np.array([0.0, -1.0, 0.0]), np.array([0.1, 1.0, 0.2]))]
    xs = np.array([-0.5, -0.4, -0.3, 0.05, 0.4])  # in front (far, above the top), over, behind
    c = np.stack([xs, np.zeros(5), np.array([0.1, 0.3, 0.3, 0.3, 0.3])], axis=1)[:, None, :]
    b = sphere_bounds(c, np.array([0.05]), box, {(0, 0)}, margin=0.01, tighten=0.0)
    top = 0.2 + 0.01 + 0.05
    assert b[2, 0, 0, 2] == pytest.approx(top) and b[3, 0, 0, 2] == pytest.approx(top)  # approaching, above
    assert b[1, 0, 1, 0] == pytest.approx(-0.01 - 0.05)  # step 0 starts low in front: the front face


def test_a_sphere_starting_within_a_margin_may_stay_as_deep_but_not_go_deeper():
    """A held can lifted 8 mm into the margin of the bottle beside it: its bounds give way by exactly what the
    start lacks, and the loop's check (`path_gaps`) lets a path stay that deep but not go deeper."""
    from twin.planning.proxy_spheres import path_gaps
    from twin.plugin import URArm

    box = [("bottle", np.array([0.0, -0.1, 0.0]), np.array([0.1, 0.1, 0.2]))]
    r, margin = 0.05, 0.01
    c = np.array([[-0.052, 0.0, 0.1], [-0.06, 0.0, 0.1], [-0.2, 0.0, 0.1]])[:, None, :]  # 8 mm short, then away
    b = sphere_bounds(c, np.array([r]), box, {(0, 0)}, margin=margin, tighten=0.0)
    assert b[1, 0, 1, 0] == pytest.approx(-0.052)  # x <= where it starts, not -0.06
    kin = URArm()
    q0 = np.array([0.0, -1.2, 1.4, -1.77, -1.57, 0.0])
    sph = np.array([[7.0, 0.0, 0.0, 0.0, r]])
    tcp = kin.fk(q0)[:3, 3]
    near = [("b", tcp + np.array([r + margin - 0.008, -0.1, -0.1]), tcp + np.array([0.3, 0.1, 0.1]))]
    still = np.vstack([q0, q0])
    assert path_gaps(kin, still, sph, near, box_margin_m=margin, substeps=2)[0] == pytest.approx(0.0, abs=1e-9)
    towards = next(q for q in (q0 + d for d in np.eye(6)[:3] * 0.02) if kin.fk(q)[0, 3] > tcp[0] + 0.002)  # +x
    deeper = np.vstack([q0, towards])
    assert path_gaps(kin, deeper, sph, near, box_margin_m=margin, substeps=2)[0] < -0.001
