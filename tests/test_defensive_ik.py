"""Defensive IK (issue 4): the seed's cost over every analytic branch, jump protection, typed failures.

The stress test is the seed's: 1000 targets over the workspace, including the z-axis singularity column;
no exception, every accepted solution reproduces its target within 1e-6, every rejection has a reason.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.robot.kinematics import DH_D, URArm
from twin.types import Pose
from twin_motion.ik import DefensiveIK, DefensiveIKParams, condition_numbers

HOME = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
TOP_DOWN = np.diag([1.0, -1.0, -1.0])  # tcp z axis pointing down


@pytest.fixture(scope="module")
def kin() -> URArm:
    return URArm()


@pytest.fixture(scope="module")
def ik(kin: URArm) -> DefensiveIK:
    return DefensiveIK(kin)


def _pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return Pose(np.zeros(3), q / np.linalg.norm(q)).matrix()[:3, :3]


def _pose_error(kin: URArm, q: np.ndarray, T: np.ndarray, frame: str = "tcp") -> tuple[float, float]:
    F = kin.fk(q, frame)
    return float(np.linalg.norm(F[:3, 3] - T[:3, 3])), float(np.linalg.norm(F[:3, :3] - T[:3, :3]))


def _stress_targets(kin: URArm, rng: np.random.Generator) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(kind, target pose, continuity seed) x 1000, spread over and around the workspace."""
    out: list[tuple[str, np.ndarray, np.ndarray]] = []
    for _ in range(450):  # reachable by construction, arbitrary orientation
        q = rng.uniform(-math.pi, math.pi, 6)
        seed = q + rng.normal(scale=0.3, size=6) if rng.random() < 0.5 else rng.uniform(-math.pi, math.pi, 6)
        out.append(("fk", kin.fk(q), seed))
    for _ in range(200):  # anywhere in a box around the robot, random orientation (many unreachable)
        p = rng.uniform([-1.0, -1.0, -0.4], [1.0, 1.0, 1.2])
        out.append(("box", _pose(_random_rotation(rng), p), HOME))
    for k in range(200):  # the z-axis singularity column and its rim, top-down and random orientations
        r = 0.0 if k % 10 == 0 else rng.uniform(0.0, 0.25)
        a = rng.uniform(-math.pi, math.pi)
        p = np.array([r * math.cos(a), r * math.sin(a), rng.uniform(-0.2, 1.0)])
        R = TOP_DOWN if k % 2 == 0 else _random_rotation(rng)
        out.append(("column", _pose(R, p), HOME))
    for _ in range(150):  # top-down grasps over the table (the work area is at negative x)
        p = rng.uniform([-0.70, -0.35, 0.02], [-0.25, 0.35, 0.40])
        yaw = rng.uniform(-math.pi, math.pi)
        Rz = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
        out.append(("grasp", _pose(Rz @ TOP_DOWN, p), HOME))
    assert len(out) == 1000
    return out


def test_ik_stress_1000_targets(kin: URArm, ik: DefensiveIK) -> None:
    rng = np.random.default_rng(2002)
    p = ik.params
    accepted: dict[str, int] = {}
    column_inside = 0
    for kind, T, seed in _stress_targets(kin, rng):
        res = ik.solve(T, seed, HOME)  # must never raise
        if res.ok:
            assert res.q is not None
            accepted[kind] = accepted.get(kind, 0) + 1
            dp, dr = _pose_error(kin, res.q, T)
            assert dp <= 1e-6 and dr <= 1e-6, (kind, dp, dr)
            assert kin.within_limits(res.q)
            assert abs(res.q[0] - seed[0]) <= p.max_base_jump_rad + 1e-12
            assert np.abs(res.q[3:] - seed[3:]).max() <= p.max_wrist_jump_rad + 1e-12
            assert res.reason.startswith("ok")
            assert math.isfinite(res.cost) and res.candidates >= 1
        else:
            assert res.q is None
            assert isinstance(res.reason, str) and len(res.reason) > 10, res.reason
            assert res.reason.split(":")[0] in ("unreachable", "rejected", "near a singularity"), res.reason
        if kind == "column" and np.allclose(T[:3, :3], TOP_DOWN):
            # top-down: the wrist centre is straight above the tcp; inside radius d4 there is no IK
            wc = T[:3, 3] - ik.tool("tcp")[2, 3] * T[:3, 2] - DH_D[5] * T[:3, 2]
            if math.hypot(wc[0], wc[1]) < DH_D[3] - 1e-6:
                column_inside += 1
                assert not res.ok and "singularity column" in res.reason, res.reason
    assert column_inside >= 20
    assert accepted.get("fk", 0) >= 0.9 * 450  # reachable by construction: only jump protection may refuse
    assert accepted.get("grasp", 0) >= 0.9 * 150
    assert 0 < accepted.get("box", 0) < 200


def test_cost_is_the_seed_formula(kin: URArm, ik: DefensiveIK) -> None:
    q = np.array([0.3, -1.2, 1.4, -1.8, -1.5, 0.4])
    seed = q + 0.05
    res = ik.solve(kin.fk(q), seed, HOME)
    assert res.ok and res.q is not None
    np.testing.assert_allclose(res.q, q, atol=1e-9)
    expected = 0.3 * np.linalg.norm(q - seed) + 0.6 * np.linalg.norm(q - HOME)
    assert res.cost == pytest.approx(expected, rel=1e-9)
    assert res.candidates == 8
    assert res.condition == pytest.approx(kin.condition_number(q), rel=1e-9)


def test_every_analytic_branch_is_a_candidate(kin: URArm, ik: DefensiveIK) -> None:
    """The candidates are the 8 analytic branches (a superset of the seed's 4 seeds), each a solution of
    UR5e.ik up to 2*pi wraps, wrapped to the value nearest the seed inside the limits."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        q = rng.uniform(-math.pi, math.pi, 6)
        T = kin.fk(q)
        S, why = ik.branches(T)
        assert why == "" and 1 <= S.shape[0] <= 8
        full = kin.ik(T)

        def wrapped(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return np.abs((a - b + math.pi) % (2 * math.pi) - math.pi).max(axis=-1)

        for s in S:  # every branch is a solution of the core IK (up to 2*pi) ...
            if ik.accurate(s, T):
                assert wrapped(full, s).min() < 1e-6
        for f in full:  # ... and every core solution is one of the branches
            assert wrapped(S, f).min() < 1e-6
        seed = rng.uniform(-5, 5, 6)
        W = ik.wrap_near(S, seed)
        lo, hi = kin.joint_limits[:, 0], kin.joint_limits[:, 1]
        for k in (-2, -1, 0, 1, 2):  # no 2*pi wrap inside the limits is nearer the seed
            alt = S + 2 * math.pi * k
            inside = (alt >= lo) & (alt <= hi)
            assert np.all(np.abs(W - seed)[inside] <= np.abs(alt - seed)[inside] + 1e-12)
        assert np.all((W >= lo - 1e-12) & (W <= hi + 1e-12))


def test_flip_penalty_keeps_the_base_frontal(kin: URArm, ik: DefensiveIK) -> None:
    """Whenever some acceptable branch has |base| <= 1.57 rad, the chosen one has too."""
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(200):
        q = rng.uniform(-math.pi, math.pi, 6)
        T = kin.fk(q)
        res = ik.solve(T, HOME, HOME)
        S, _ = ik.branches(T)
        W = ik.wrap_near(S, HOME)
        frontal = [w for w in W if abs(w[0]) <= 1.57 and abs(w[0] - HOME[0]) <= 3.0]
        if frontal and res.ok:
            checked += 1
            assert res.q is not None and abs(res.q[0]) <= 1.57
    assert checked > 50


def test_jump_protection_rejects_with_reason(kin: URArm) -> None:
    strict = DefensiveIK(kin, DefensiveIKParams(max_base_jump_rad=0.1))
    q = np.array([0.3, -1.2, 1.4, -1.8, -1.5, 0.4])
    res = strict.solve(kin.fk(q), q + np.array([1.5, 0, 0, 0, 0, 0]), HOME)
    assert not res.ok and res.q is None
    assert "jump protection" in res.reason and res.rejected.get("jump protection") == 8
    # the default thresholds (3.0 / 5.0 rad) accept the same query
    assert DefensiveIK(kin).solve(kin.fk(q), q + np.array([1.5, 0, 0, 0, 0, 0]), HOME).ok


def test_singular_branches_are_penalised_or_rejected(kin: URArm) -> None:
    q = np.array([0.3, -1.2, 1.4, -1.8, 0.0, 0.4])  # wrist singular (q5 = 0)
    T = kin.fk(q)
    # every non-singular branch here has the base behind (+100 flip): the seed's cost keeps the singular
    # one, and says so
    res = DefensiveIK(kin).solve(T, q, HOME)
    assert res.ok and res.condition > 500 and "near-singular" in res.reason
    # without the flip penalty the singularity penalty decides: a non-singular branch wins
    res = DefensiveIK(kin, DefensiveIKParams(flip_penalty=0.0)).solve(T, q, HOME)
    assert res.ok and res.condition <= 500
    # reject_singular never returns a singular branch; with tight jump protection nothing is left
    res = DefensiveIK(kin, DefensiveIKParams(reject_singular=True)).solve(T, q, HOME)
    assert res.ok and res.condition <= 500
    res = DefensiveIK(kin, DefensiveIKParams(reject_singular=True, max_base_jump_rad=0.5)).solve(T, q, HOME)
    assert not res.ok and "singular" in res.reason and "jump protection" in res.reason


def test_bad_and_unreachable_targets_never_raise(kin: URArm, ik: DefensiveIK) -> None:
    T = np.full((4, 4), np.nan)
    assert not ik.solve(T, HOME).ok
    far = _pose(TOP_DOWN, np.array([1.5, 0.0, 0.3]))
    res = ik.solve(far, HOME)
    assert not res.ok and res.reason.startswith("unreachable") and "out of reach" in res.reason
    res = ik.solve(Pose.from_matrix(kin.fk(HOME)), HOME)  # Pose objects work too
    assert res.ok and res.q is not None and np.abs(res.q - HOME).max() < 1e-6


def test_flange_frame_and_validity_filter(kin: URArm, ik: DefensiveIK) -> None:
    q = np.array([0.3, -1.2, 1.4, -1.8, -1.5, 0.4])
    res = ik.solve(kin.fk(q, "flange"), q, frame="flange")
    assert res.ok and res.q is not None
    assert max(_pose_error(kin, res.q, kin.fk(q, "flange"), "flange")) <= 1e-6
    # a validity filter (e.g. "not in collision") that refuses the best branch makes the next one win
    first = res.q.copy()
    res2 = ik.solve(kin.fk(q, "flange"), q, frame="flange", is_valid=lambda c: np.abs(c - first).max() > 1e-9)
    assert res2.ok and res2.q is not None and np.abs(res2.q - first).max() > 1e-3
    res3 = ik.solve(kin.fk(q), q, is_valid=lambda c: False)
    assert not res3.ok and "invalid" in res3.reason


def test_fast_jacobians_match_core(kin: URArm, ik: DefensiveIK) -> None:
    rng = np.random.default_rng(9)
    qs = rng.uniform(-math.pi, math.pi, (10, 6))
    conds = condition_numbers(kin, qs, "tcp")
    np.testing.assert_allclose(ik.tool("tcp"), kin.tool_transform("tcp"), atol=1e-12)
    for q, c in zip(qs, conds, strict=True):
        assert c == pytest.approx(kin.condition_number(q), rel=1e-9)
        assert ik.condition(q) == pytest.approx(kin.condition_number(q), rel=1e-9)
