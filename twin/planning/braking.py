"""How the MPCs' loop (`twin.planning.receding`) brings a moving arm to rest within its step, acceleration and
jerk bounds.

The planner's motion is a sequence of joint steps d_i = q_i - q_{i-1}, one per dt; its bounds are on the
step (velocity), on its change (acceleration x dt^2) and on the change of that (jerk x dt^3). A stop is
a few more steps after which the arm stands still (the steps after it are zero) and every bound holds
across the whole sequence, including the zero steps. `can_stop_now` says whether the very next step may
already be zero; `stopping_steps` finds the shortest stop (a linear programme per joint, solved for all
joints at once), with the least joint travel among the shortest.

Why a linear programme: the bounds are linear in the steps, a stop is at most a handful of steps, and a
greedy "decelerate as hard as you may" overshoots zero velocity under a jerk bound; HiGHS answers the
whole problem in about a millisecond, and a stop is only computed when the planner has to brake.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linprog

__all__ = ["can_stop_now", "slowing_steps", "stopping_steps"]

_TOL = 1e-9


def _bound(b: np.ndarray | None) -> np.ndarray:
    return np.full(6, np.inf) if b is None else np.asarray(b, dtype=float)


def can_stop_now(d2: np.ndarray, d1: np.ndarray, dstep: np.ndarray | None, jstep: np.ndarray | None) -> bool:
    """Whether the arm, having taken the step `d2` (6,) and then `d1` (6,), may stand still from the next step
    on: the change -d1 within `dstep` (acceleration x dt^2), and the changes of change d2 - 2 d1 and d1 within
    `jstep` (jerk x dt^3) (None: unbounded)."""
    A, J = _bound(dstep), _bound(jstep)
    return bool(
        np.all(np.abs(d1) <= A + _TOL) and np.all(np.abs(d2 - 2 * d1) <= J + _TOL) and np.all(np.abs(d1) <= J + _TOL)
    )


def stopping_steps(
    d2: np.ndarray,
    d1: np.ndarray,
    step: np.ndarray,
    dstep: np.ndarray | None,
    jstep: np.ndarray | None,
    *,
    max_steps: int = 40,
) -> np.ndarray | None:
    """(n + 1, 6) steps that bring the arm from its last two steps `d2`, `d1` (6,) to rest: n moving steps,
    then one zero step (the arm standing still, declared at rest). The shortest such stop, with the least
    joint travel; None when none of at most `max_steps` steps exists (a bound too tight for the motion)."""
    d2, d1 = np.asarray(d2, dtype=float), np.asarray(d1, dtype=float)
    if can_stop_now(d2, d1, dstep, jstep):
        return np.zeros((1, 6))
    S, A, J = np.asarray(step, dtype=float), _bound(dstep), _bound(jstep)
    # a lower bound on the length: each step changes the step by at most A (and by at most 2 J in a row)
    lo = max(1, math.ceil(float(np.max(np.abs(d1) / np.minimum(A, 2 * J))) - 1e-9) - 1)
    for n in range(lo, max_steps + 1):
        x = _solve(d2, d1, S, A, J, n)
        if x is not None:
            return np.vstack([x, np.zeros((1, 6))])
    return None


def slowing_steps(
    d2: np.ndarray,
    d1: np.ndarray,
    n: int,
    step: np.ndarray,
    dstep: np.ndarray | None,
    jstep: np.ndarray | None,
) -> np.ndarray:
    """(n, 6) steps that go on from the last two steps `d2`, `d1` (6,), each the one nearest zero that its
    acceleration (`dstep`) and jerk (`jstep`) bounds allow after the two before it, within the step bound: how a
    warm start carries a plan past its horizon. Greedy, so not necessarily a stop within n steps (that is
    `stopping_steps`, an LP); but every step keeps the bounds the two before it kept, where a repeated last
    knot (a zero step) broke the acceleration and jerk rows of a plan still moving at its horizon."""
    A, J, S = _bound(dstep), _bound(jstep), np.asarray(step, dtype=float)
    d2, d1 = np.asarray(d2, dtype=float).copy(), np.asarray(d1, dtype=float).copy()
    out = np.zeros((n, 6))
    for i in range(n):
        lo = np.maximum(d1 - A, 2 * d1 - d2 - J)
        hi = np.minimum(d1 + A, 2 * d1 - d2 + J)
        d = np.clip(np.clip(0.0, lo, hi), -S, S)
        out[i] = d
        d2, d1 = d1, d
    return out


def _solve(d2: np.ndarray, d1: np.ndarray, S: np.ndarray, A: np.ndarray, J: np.ndarray, n: int) -> np.ndarray | None:
    """n steps per joint (then zeros) within the bounds, least travel; None when infeasible.

    Variables per joint: x_1..x_n (steps) and t_1..t_n (|x_i|); the joints are independent (block diagonal)."""
    # the sequence x_{-1}, x_0, x_1..x_n, 0, 0 as (row of coefficients on x_1..x_n, constant)
    m = n + 4
    coef = np.zeros((m, n))
    coef[2 : 2 + n] = np.eye(n)

    def rows(order: int) -> np.ndarray:
        d = coef.copy()
        for _ in range(order):
            d = d[1:] - d[:-1]
        return d

    rows_a = rows(1)[1:]  # changes x_i - x_{i-1}, i = 1..n+1 (the one after the last zero step is zero)
    rows_j = rows(2)  # changes of change, i = 1..n+2
    A_ub, b_ub = [], []
    nv = 2 * n * 6
    for j in range(6):
        hist = np.zeros(m)
        hist[0], hist[1] = d2[j], d1[j]
        const_a = (hist[1:] - hist[:-1])[1:]
        const_j = hist[2:] - 2 * hist[1:-1] + hist[:-2]
        for R, c, bound in ((rows_a, const_a, A[j]), (rows_j, const_j, J[j])):
            if not math.isfinite(bound):
                continue
            for sgn in (1.0, -1.0):
                blk = np.zeros((R.shape[0], nv))
                blk[:, j * 2 * n : j * 2 * n + n] = sgn * R
                A_ub.append(blk)
                b_ub.append(bound - sgn * c)
        # |x_i| <= t_i
        for sgn in (1.0, -1.0):
            blk = np.zeros((n, nv))
            blk[:, j * 2 * n : j * 2 * n + n] = sgn * np.eye(n)
            blk[:, j * 2 * n + n : (j + 1) * 2 * n] = -np.eye(n)
            A_ub.append(blk)
            b_ub.append(np.zeros(n))
    cost = np.zeros(nv)
    bounds = []
    for j in range(6):
        cost[j * 2 * n + n : (j + 1) * 2 * n] = 1.0
        bounds += [(-S[j], S[j])] * n + [(0.0, None)] * n
    res = linprog(cost, A_ub=np.vstack(A_ub), b_ub=np.concatenate(b_ub), bounds=bounds, method="highs")
    if res.status != 0:
        return None
    x = res.x.reshape(6, 2 * n)[:, :n].T
    return x
