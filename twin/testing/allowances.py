"""How far a trajectory may go (limits, time slack, sameness), apart from the check's machinery, so a test
can judge a trajectory exactly as the check does (tests/test_nmpc.py does)."""

from __future__ import annotations

import numpy as np

from twin.limit_check import LIMIT_TOLERANCE, limit_violations
from twin.types import MotionResult, Trajectory

__all__ = ["LIMIT_TOLERANCE", "START_TOLERANCE_RAD", "limit_violations", "time_slack_s"]

START_TOLERANCE_RAD = 1e-6  # what CheckedPlanner accepts as "starts at the start / measured state"
_TRAJ_ATOL = 1e-9  # two trajectories are "the same" when t and q agree within this


def time_slack_s(time_limit_s: float) -> float:
    """How far past `time_limit_s` a planning call may return: 25 % of the limit plus 0.3 s.

    Why: a planner stops searching at its deadline, but the work after the search (shortcutting,
    retiming, the final collision check of the trajectory) cannot be cut short without returning
    nothing; Python cannot pre-empt a native call at an exact instant; and a loaded CI machine adds
    scheduling noise of a few 100 ms. A planner that ignores its limit overshoots by far more."""
    return 0.25 * time_limit_s + 0.3


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
