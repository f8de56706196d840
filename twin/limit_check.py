"""How far a trajectory goes against the request's joint limits: the one measure the judge
(`twin.planning.CheckedPlanner`), the planner contract (`twin.testing`) and the comparison rows share.

A limit is judged on what the trajectory declares (qd, qdd; jerk as differences of qdd between samples)
and on the divided differences of its q samples, which a motion that keeps a limit cannot exceed (mean
value theorem): a planner cannot pass by declaring small derivatives for large steps. The arm stands
still before a motion that starts from rest and after one that ends at rest, so a trajectory that starts
moving or stops dead jumps from rest. `LIMIT_TOLERANCE` absorbs float round-off and sampling.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.types import Limits, Trajectory

__all__ = [
    "LIMIT_KINDS",
    "LIMIT_TOLERANCE",
    "Q_ROUND_OFF_RAD",
    "RATIO_METRICS",
    "LimitExcess",
    "limit_excess",
    "limit_violations",
    "stitched",
]

# Relative excess over a limit that is still float round-off or sampling, not a violation: Ruckig and the
# quintic hit their limits exactly, TOPP-RA's samples are kept under them, and 0.1 % of pi rad/s is 3 mrad/s.
LIMIT_TOLERANCE = 1e-3
# The divided differences of q are taken over samples at least this far apart (s): closer samples (a
# trajectory's last sample 1e-12 s after the previous one) would turn round-off into huge "jerk".
_MIN_DIFF_DT_S = 5e-4
# How exactly a planner's positions are trusted (rad). The k-th difference of positions that are each off by
# up to this much is off by up to 2^k times it over h^k, so the k-th differences of q are taken over samples
# at least 2 (Q_ROUND_OFF_RAD / (LIMIT_TOLERANCE * limit))^(1/k) apart (jerk 100 rad/s^3: 9 ms; acceleration
# 8 rad/s^2: 2 ms). Measured: a path timed by the Ruckig retimer, sampled every 1 ms, read 1.10x its jerk
# limit in the third differences of those samples while its declared jerk kept the limit exactly (3e-9 rad of
# position error does that at 1 ms). Declared qd and qdd are judged at every sample.
Q_ROUND_OFF_RAD = 1e-8
LIMIT_KINDS: tuple[str, ...] = ("velocity", "acceleration", "jerk")
# the metric each kind's worst ratio is reported as (compare rows, a run's per-planner metrics)
RATIO_METRICS: dict[str, str] = {"velocity": "max_vel_ratio", "acceleration": "max_acc_ratio", "jerk": "max_jerk_ratio"}
_UNITS = {"velocity": "rad/s", "acceleration": "rad/s^2", "jerk": "rad/s^3"}
_Source = tuple[str, tuple[np.ndarray, np.ndarray]]  # what a limit is judged on: (name, (values (n, 6), times (n,)))


@dataclass(frozen=True)
class LimitExcess:
    """The worst sample of one kind of limit: `ratio` = |value| / limit of joint `joint` (0-based), seen in
    `source` ('declared qd', 'differences of q', ...) at `t_s` (s, the trajectory's time; a difference's:
    the middle of the samples it spans; before 0 or after the end: the jump from or to rest)."""

    kind: str
    ratio: float
    joint: int
    value: float
    limit: float
    source: str
    t_s: float | None = None

    def reason(self) -> str:
        """'joint 2 reaches 5.17 rad/s (declared qd) at t=0.420 s, limit 3.14 (1.65x)'."""
        at = "" if self.t_s is None else f" at t={self.t_s:.3f} s"
        return (
            f"joint {self.joint + 1} reaches {self.value:.4g} {_UNITS[self.kind]} ({self.source}){at}, "
            f"limit {self.limit:.4g} ({self.ratio:.2f}x)"
        )


def _thinned(t: np.ndarray, min_dt: float) -> np.ndarray:
    """Indices of samples at least `min_dt` apart, the first and the last always among them (a motion judged
    without its end would stop where it had not stopped)."""
    n = t.shape[0]
    if n < 2 or float(np.diff(t).min()) >= min_dt:
        return np.arange(n)
    # each sample's successor (the first at least min_dt later) looked up for all at once, then followed from
    # the first: the same samples as a search after each kept one (a judge looks at ~330 trajectories a run)
    successor = np.searchsorted(t, t + min_dt, side="left").tolist()
    keep = [0]
    while (j := successor[keep[-1]]) < n:
        keep.append(j)
    if keep[-1] != n - 1:  # the end, in place of the last kept sample when that is too close to it
        if len(keep) > 1 and t[-1] - t[keep[-1]] < min_dt:
            keep[-1] = n - 1
        else:
            keep.append(n - 1)
    return np.array(keep)


def _at_rest(
    traj: Trajectory, i: np.ndarray, *, from_rest: bool, to_rest: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """t, q, qd, qdd of the samples `i` of `traj`, with three samples of rest before (`from_rest`) and after
    (`to_rest`) them at the first and last spacing: standing still, q held and qd, qdd zero."""
    t, q, qd, qdd = traj.t[i], traj.q[i], traj.qd[i], traj.qdd[i]
    if t.shape[0] >= 2:
        k = np.arange(3, 0, -1)
        if from_rest:
            t = np.concatenate([t[0] - (t[1] - t[0]) * k, t])
            q, qd = _rest(q, 3, before=True, hold=True), _rest(qd, 3, before=True, hold=False)
            qdd = _rest(qdd, 3, before=True, hold=False)
        if to_rest:
            t = np.concatenate([t, t[-1] + (t[-1] - t[-2]) * k[::-1]])
            q, qd = _rest(q, 3, before=False, hold=True), _rest(qd, 3, before=False, hold=False)
            qdd = _rest(qdd, 3, before=False, hold=False)
    return t, q, qd, qdd


def _rest(arr: np.ndarray, n: int, *, before: bool, hold: bool) -> np.ndarray:
    """`arr` with `n` samples of rest added before or after it: the end sample held (q) or zeros (qd, qdd)."""
    end = arr[:1] if before else arr[-1:]
    pad = np.repeat(end, n, 0) if hold else np.zeros((n, arr.shape[1]))
    return np.vstack([pad, arr]) if before else np.vstack([arr, pad])


def limit_excess(
    traj: Trajectory, limits: Limits, *, from_rest: bool = True, to_rest: bool = True, jerk: bool = True
) -> dict[str, LimitExcess]:
    """{'velocity' | 'acceleration' | 'jerk': its worst sample} of `traj` against `limits` (jerk only with
    `jerk=True`); a kind with nothing to measure (one sample) is left out.

    `from_rest`: the arm stands still before the first sample (a request has no start velocity), so a
    trajectory that begins moving jumps from rest; `to_rest`: it holds the last sample afterwards."""
    out: dict[str, LimitExcess] = {}
    if traj.t.shape[0] < 2:
        return out
    t, _, qd, qdd = _at_rest(traj, _thinned(traj.t, _MIN_DIFF_DT_S), from_rest=from_rest, to_rest=to_rest)

    def differences(order: int, lim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The order-th divided differences of q (times order!), over samples far enough apart that the
        positions' round-off stays within the tolerance of the smallest limit; and the middle of the time each
        spans."""
        spacing = max(_MIN_DIFF_DT_S, 2.0 * (Q_ROUND_OFF_RAD / (LIMIT_TOLERANCE * float(lim.min()))) ** (1.0 / order))
        ts, d, _, _ = _at_rest(traj, _thinned(traj.t, spacing), from_rest=from_rest, to_rest=to_rest)
        for k in range(1, order + 1):
            if ts.shape[0] <= k:
                return np.zeros((0, 6)), np.zeros(0)
            d = k * np.diff(d, axis=0) / (ts[k:] - ts[:-k])[:, None]
        return d, 0.5 * (ts[order:] + ts[:-order])

    checks: list[tuple[str, np.ndarray, tuple[_Source, ...]]] = [
        (
            "velocity",
            limits.max_joint_vel,
            (("declared qd", (qd, t)), ("differences of q", differences(1, limits.max_joint_vel))),
        ),
        (
            "acceleration",
            limits.max_joint_acc,
            (("declared qdd", (qdd, t)), ("second differences of q", differences(2, limits.max_joint_acc))),
        ),
    ]
    if jerk:
        jerk_declared = np.diff(qdd, axis=0) / np.diff(t)[:, None]
        checks.append(
            (
                "jerk",
                limits.max_joint_jerk,
                (
                    ("differences of qdd", (jerk_declared, 0.5 * (t[1:] + t[:-1]))),
                    ("third differences of q", differences(3, limits.max_joint_jerk)),
                ),
            )
        )
    for kind, lim, sources in checks:
        worst: LimitExcess | None = None
        for src, (values, times) in sources:
            if values.size == 0:
                continue
            ratio = np.abs(values) / lim[None, :]
            at = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
            r = float(ratio[at])
            if worst is None or r > worst.ratio:
                j = int(at[1])
                worst = LimitExcess(kind, r, j, float(np.abs(values[at])), float(lim[j]), src, float(times[at[0]]))
        if worst is not None:
            out[kind] = worst
    return out


def limit_violations(
    traj: Trajectory,
    limits: Limits,
    *,
    tolerance: float = LIMIT_TOLERANCE,
    from_rest: bool = True,
    to_rest: bool = True,
    jerk: bool = True,
) -> dict[str, str]:
    """{'velocity' | 'acceleration' | 'jerk': why} for every limit `traj` exceeds by more than `tolerance`
    (relative); see `limit_excess`."""
    excess = limit_excess(traj, limits, from_rest=from_rest, to_rest=to_rest, jerk=jerk)
    return {k: e.reason() for k, e in excess.items() if e.ratio > 1.0 + tolerance}


def stitched(before: Trajectory | None, after: Trajectory, *, samples: int = 4) -> Trajectory:
    """The last `samples` samples of `before` followed by `after`, `before` shifted to end where `after`
    starts: a receding-horizon segment judged with the motion that led into it (its velocity and
    acceleration carry over), without the tracking error between the last command and the measured state
    at which the segment starts (a real arm's, not the planner's)."""
    if before is None or before.t.shape[0] < 2:
        return after
    n = min(samples, before.t.shape[0] - 1)  # before's last sample is after's first: dropped
    tail_t = before.t[-1 - n : -1] - before.t[-1] + after.t[0]
    tail_q = before.q[-1 - n : -1] - before.q[-1] + after.q[0]
    return Trajectory(
        np.concatenate([tail_t, after.t]),
        np.vstack([tail_q, after.q]),
        np.vstack([before.qd[-1 - n : -1], after.qd]),
        np.vstack([before.qdd[-1 - n : -1], after.qdd]),
    )
