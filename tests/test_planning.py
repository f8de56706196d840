"""The planning API's own guarantees: trajectory checks at the promised resolution, typed results."""

from __future__ import annotations

import numpy as np
import pytest

from twin.collision import PlanningScene
from twin.config import settings_from_dict
from twin.errors import InvalidRequestError
from twin.planning import densify, first_collision
from twin.robot.kinematics import URArm
from twin.types import Limits, MotionRequest, MotionResult, Status, Trajectory

KIN = URArm()


def quintic(a: np.ndarray, b: np.ndarray, T: float, n: int) -> Trajectory:
    t = np.linspace(0.0, T, n)
    s = t / T
    pos = 10 * s**3 - 15 * s**4 + 6 * s**5
    vel = (30 * s**2 - 60 * s**3 + 30 * s**4) / T
    acc = (60 * s - 180 * s**2 + 120 * s**3) / T**2
    d = b - a
    return Trajectory(t, a + np.outer(pos, d), np.outer(vel, d), np.outer(acc, d))


@pytest.mark.parametrize("n_samples", [2, 40, 3000])
def test_densify_keeps_joint_and_tcp_steps_within_the_resolution(n_samples):
    rng = np.random.default_rng(n_samples)
    for _ in range(10):
        a, b = rng.uniform(-2, 2, 6), rng.uniform(-2, 2, 6)
        traj = quintic(a, b, 2.0, n_samples)
        qs = densify(traj, KIN, max_step_rad=0.01, max_step_m=0.01)
        np.testing.assert_allclose(qs[0], a, atol=1e-12)
        np.testing.assert_allclose(qs[-1], b, atol=1e-12)
        assert np.abs(np.diff(qs, axis=0)).max() <= 0.01 + 1e-9
        p = KIN.fk_batch(qs)[:, :3, 3]
        assert np.linalg.norm(np.diff(p, axis=0), axis=1).max() <= 0.01 + 1e-9
        # thinning: a dense trajectory is not checked sample by sample
        assert len(qs) <= max(n_samples, np.abs(b - a).max() / 0.01 * 2 + 50)


def test_first_collision_agrees_with_a_much_finer_check():
    scene = PlanningScene.from_settings(settings_from_dict({}))
    rng = np.random.default_rng(3)
    agree = hits = 0
    for _ in range(30):
        a, b = rng.uniform(-2.5, 2.5, 6), rng.uniform(-2.5, 2.5, 6)
        traj = quintic(a, b, 2.0, 2001)
        coarse = first_collision(traj, scene, KIN, max_step_rad=0.01, max_step_m=0.01)
        fine = scene.in_collision_batch(densify(traj, KIN, max_step_rad=0.002, max_step_m=0.002)).any()
        agree += (coarse is not None) == bool(fine)
        hits += bool(fine)
    assert hits > 3
    assert agree >= 29  # a grazing contact thinner than 1 cm of travel may slip through once


def test_requests_and_results_reject_malformed_input():
    lim = Limits.uniform(3.14, 8.0, 100.0)
    with pytest.raises(InvalidRequestError, match="start"):
        MotionRequest(np.zeros(5), None, lim)  # type: ignore[arg-type]
    with pytest.raises(InvalidRequestError, match="goal"):
        MotionRequest(np.zeros(6), np.zeros(6), lim)  # type: ignore[arg-type]
    with pytest.raises(InvalidRequestError, match="positive"):
        Limits.uniform(-1.0, 8.0, 100.0)
    with pytest.raises(InvalidRequestError, match="trajectory"):
        MotionResult(Status.SUCCESS, "no trajectory")
    with pytest.raises(InvalidRequestError, match="increasing"):
        Trajectory(np.array([0.0, 0.0]), np.zeros((2, 6)), np.zeros((2, 6)), np.zeros((2, 6)))


def test_trajectory_sampling_hits_knots_and_clamps_at_the_ends():
    a, b = np.zeros(6), np.ones(6)
    traj = quintic(a, b, 1.0, 11)
    q, qd, _ = traj.sample(traj.t)
    np.testing.assert_allclose(q, traj.q, atol=1e-12)
    np.testing.assert_allclose(qd, traj.qd, atol=1e-12)
    np.testing.assert_allclose(traj.sample(5.0)[0], b)
    np.testing.assert_allclose(traj.sample(-1.0)[0], a)
    r = traj.resampled(0.001)
    assert r.t[-1] == pytest.approx(1.0) and len(r.t) == 1001
