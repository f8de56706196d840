"""How far a trajectory may go (limits, time slack, sameness), apart from the check's machinery, so a test
can judge a trajectory exactly as the check does (tests/test_nmpc.py does)."""

from __future__ import annotations

import numpy as np

from twin.types import Limits, MotionResult, Trajectory

__all__ = ["LIMIT_TOLERANCE", "START_TOLERANCE_RAD", "limit_violations", "time_slack_s"]

START_TOLERANCE_RAD = 1e-6  # what CheckedPlanner accepts as "starts at the start / measured state"
# Relative excess over a limit that is still float round-off, not a violation: Ruckig and the quintic hit
# their limits exactly, TOPP-RA's samples are kept under them, and 0.1 % of pi rad/s is 3 mrad/s.
LIMIT_TOLERANCE = 1e-3
# The divided differences of q are taken over samples at least this far apart (s): closer samples (a
# trajectory's last sample 1e-12 s after the previous one) would turn round-off into huge "jerk".
_MIN_DIFF_DT_S = 5e-4
_TRAJ_ATOL = 1e-9  # two trajectories are "the same" when t and q agree within this


def time_slack_s(time_limit_s: float) -> float:
    """How far past `time_limit_s` a planning call may return: 25 % of the limit plus 0.3 s.

    Why: a planner stops searching at its deadline, but the work after the search (shortcutting,
    retiming, the final collision check of the trajectory) cannot be cut short without returning
    nothing; Python cannot pre-empt a native call at an exact instant; and a loaded CI machine adds
    scheduling noise of a few 100 ms. A planner that ignores its limit overshoots by far more."""
    return 0.25 * time_limit_s + 0.3


def _thinned(t: np.ndarray, min_dt: float) -> np.ndarray:
    """Indices of samples at least `min_dt` apart (the first and, if far enough, the last kept)."""
    keep = [0]
    for i in range(1, t.shape[0]):
        if t[i] - t[keep[-1]] >= min_dt:
            keep.append(i)
    return np.array(keep)


def limit_violations(
    traj: Trajectory,
    limits: Limits,
    *,
    tolerance: float = LIMIT_TOLERANCE,
    from_rest: bool = True,
    to_rest: bool = True,
) -> dict[str, str]:
    """{'velocity' | 'acceleration' | 'jerk': why} for every limit `traj` exceeds by more than `tolerance`
    (relative). Judged on the declared qd and qdd (jerk: differences of qdd between samples) and on the
    divided differences of q, which a motion that keeps a limit cannot exceed (mean value theorem).

    `from_rest`: the arm stands still before the first sample (a request has no start velocity), so a
    trajectory that begins moving jumps from rest; `to_rest`: it holds the last sample afterwards."""
    out: dict[str, str] = {}
    if traj.t.shape[0] < 2:
        return out
    i = _thinned(traj.t, _MIN_DIFF_DT_S)
    t, q, qd, qdd = traj.t[i], traj.q[i], traj.qd[i], traj.qdd[i]
    if t.shape[0] >= 2:  # standing still: three samples of rest before and after, at the first/last spacing
        k = np.arange(3, 0, -1)[:, None]
        if from_rest:
            h = t[1] - t[0]
            t = np.concatenate([t[0] - h * k[:, 0], t])
            q, qd, qdd = (
                np.vstack([np.repeat(q[:1], 3, 0), q]),
                np.vstack([np.zeros((3, 6)), qd]),
                np.vstack([np.zeros((3, 6)), qdd]),
            )
        if to_rest:
            h = t[-1] - t[-2]
            t = np.concatenate([t, t[-1] + h * k[::-1, 0]])
            q, qd, qdd = (
                np.vstack([q, np.repeat(q[-1:], 3, 0)]),
                np.vstack([qd, np.zeros((3, 6))]),
                np.vstack([qdd, np.zeros((3, 6))]),
            )
    dt = np.diff(t)[:, None]
    d1 = np.diff(q, axis=0) / dt
    d2 = 2.0 * np.diff(d1, axis=0) / (t[2:] - t[:-2])[:, None] if t.shape[0] > 2 else np.zeros((0, 6))
    d3 = 3.0 * np.diff(d2, axis=0) / (t[3:] - t[:-3])[:, None] if t.shape[0] > 3 else np.zeros((0, 6))
    jerk_declared = np.diff(qdd, axis=0) / dt
    checks = (
        ("velocity", limits.max_joint_vel, "rad/s", (("declared qd", qd), ("differences of q", d1))),
        ("acceleration", limits.max_joint_acc, "rad/s^2", (("declared qdd", qdd), ("second differences of q", d2))),
        (
            "jerk",
            limits.max_joint_jerk,
            "rad/s^3",
            (("differences of qdd", jerk_declared), ("third differences of q", d3)),
        ),
    )
    for name, lim, unit, sources in checks:
        worst: tuple[float, str, int, float] | None = None
        for src, values in sources:
            if values.size == 0:
                continue
            ratio = np.abs(values) / lim[None, :]
            k2 = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
            r = float(ratio[k2])
            if worst is None or r > worst[0]:
                worst = (r, src, int(k2[1]), float(np.abs(values[k2])))
        if worst is not None and worst[0] > 1.0 + tolerance:
            r, src, j, v = worst
            out[name] = f"joint {j + 1} reaches {v:.4g} {unit} ({src}), limit {lim[j]:.4g} ({r:.2f}x)"
    return out


def _same(a: MotionResult | None, b: MotionResult | None) -> str | None:
    """Why two results differ (status, or trajectory beyond _TRAJ_ATOL), or None."""
    if a is None or b is None:
        return None if a is b else "one call returned no result"
    if a.status is not b.status:
        return f"{a.status.value} then {b.status.value}"
    ta, tb = a.trajectory, b.trajectory
    if ta is None or tb is None:
        return None if ta is tb else "a trajectory only once"
    return _same_traj(ta, tb)


def _same_traj(ta: Trajectory, tb: Trajectory) -> str | None:
    if ta.t.shape != tb.t.shape:
        return f"{ta.t.shape[0]} then {tb.t.shape[0]} samples"
    dq = float(np.abs(ta.q - tb.q).max())
    dt = float(np.abs(ta.t - tb.t).max())
    if dq > _TRAJ_ATOL or dt > _TRAJ_ATOL:
        return f"trajectories differ by up to {dq:.3g} rad, {dt:.3g} s"
    return None
