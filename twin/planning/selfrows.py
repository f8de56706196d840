"""The self-collision rows of a horizon: which sphere pairs of the arm a knot keeps apart, and how far.

Neither MPC formulation of the seeds keeps the arm from itself; the loop's FCL check then stops a plan that
folds the elbow until the upper arm meets wrist 1 (a warehouse drop close to the base, bench scene 8 of seed
000) or swings the gripper into the forearm. So croc keeps a set of spheres on every link from the shoulder
to the fingertips (whole_arm mode's, which cover the links with the box margin; the held object's are part of
the tool) apart pairwise, for pairs on links that are not neighbours (neighbours touch by construction, as
`twin.collision.rules` excludes them).

The distance of two points is not a row crocoddyl has: it is a Python residual, ~35 us per knot and row per
SQP iteration, so a knot gets at most `slots` rows, for its nearest pairs, and only pairs that come within
`within` of touching on the plan a round starts from get one (a horizon with no pair near carries no self
rows at all: the planner then solves a problem without them). A pair must stay `extra` beyond touching: each
sphere covers its link only to within the box margin (`twin_croc.params`), so two links are kept apart by
twice the margin, plus the row tightening (one margin let the gripper base 0.5 mm into the forearm with their
spheres 12 mm apart: warehouse seed 105); a pair that starts closer may not come closer than it started.

The rows are a few slots per knot, chosen on the plan a round starts from, and a warm solve is one SQP
iteration: a plan can still bring a pair without a row together, or one with a row closer than its bound
(warehouse seed 108 under the stress faults: a cold plan, with no pair near on its guess, folded the gripper
to 7 mm of the forearm, and the next warm iteration 6 mm into it). So `self_violation` judges every pair of a
plan, between its knots too, as the loop judges the sphere rows against the boxes: a plan that fails is not
executed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.planning.proxy_spheres import TCP_FRAME

__all__ = ["SelfRows", "link_groups", "pair_gaps", "self_pairs", "self_rows", "self_violation"]

_TOOL_GROUP = 6  # the tool's spheres (wrist 3, gripper, fingers, held object) after DH frames 1..5
_SHORT_M = 1e-3  # a start nearer its bound than this is not relaxed (the QP holds bounds to ~its tolerance)


@dataclass(frozen=True)
class SelfRows:
    """A horizon's self rows: `pairs` (H+1, slots, 2) sphere indices (-1: the row is open), their lower bounds on
    the centres' distance `lo` (H+1, slots), and `deficit`, m: how much closer than its bound the nearest pair of
    the plan they were chosen on is (held or not; <= 0: none is)."""

    pairs: np.ndarray
    lo: np.ndarray
    deficit: float

    def same_rows(self, other: SelfRows | None) -> bool:
        """Whether `other` holds the same pairs to the same bounds."""
        return other is not None and np.array_equal(self.pairs, other.pairs) and np.array_equal(self.lo, other.lo)


def link_groups(sph: np.ndarray) -> np.ndarray:
    """(n,) the link of each sphere (n, 5): its DH frame 1..5, or 6 for the tool (tcp frame)."""
    frame = np.asarray(sph, dtype=float)[:, 0].astype(int)
    return np.where(frame == TCP_FRAME, _TOOL_GROUP, frame)


def self_pairs(sph: np.ndarray) -> np.ndarray:
    """(P, 2) the sphere pairs on links that are not neighbours in the chain."""
    g = link_groups(sph)
    i, j = np.triu_indices(len(g), 1)
    keep = np.abs(g[i] - g[j]) >= 2
    return np.ascontiguousarray(np.column_stack([i[keep], j[keep]]), dtype=np.int64)


def pair_gaps(centres: np.ndarray, radii: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """(m, P) how far apart the spheres (centres (m, n, 3), radii (n,)) of each pair (P, 2) are (< 0: overlapping)."""
    from twin.planning.mpc_kernel import pair_gaps_into  # lazy: numba (compiled on first use)

    gap = np.empty((centres.shape[0], pairs.shape[0]))
    pair_gaps_into(np.ascontiguousarray(centres), np.ascontiguousarray(radii, dtype=float), pairs, gap)
    return gap


def self_violation(gaps: np.ndarray, *, bound: float, tol: float) -> str | None:
    """Why a path's pair gaps (m, P) (row 0: the measured state, then points along the path) break the self rows'
    rule, or None: every pair stays `bound` m apart (the covers' shortfall: the rows hold it plus their
    tightening), or, when it starts closer, no closer than it started; `tol` m below is accepted (the QP's slack)."""
    if gaps.shape[1] == 0 or gaps.shape[0] < 2:
        return None
    need = np.minimum(bound, gaps[0]) - tol
    short = need[None] - gaps[1:]
    worst = float(short.max())
    if worst <= 0.0:
        return None
    return f"two of the arm's own spheres come {worst:.4f} m closer than their bound of {bound:.3f} m apart"


def self_rows(
    centres: np.ndarray, radii: np.ndarray, pairs: np.ndarray, *, slots: int, within: float, extra: float
) -> SelfRows | None:
    """The rows of each knot of the plan `centres` (H+1, n, 3) (knot 0, the measured state, has none): its
    `slots` nearest pairs of `pairs` (P, 2) that come within `within` m of touching there, each to stay
    `extra` m beyond touching (or, if the start is closer, as close as it started); None if no knot has one."""
    if slots <= 0 or pairs.shape[0] == 0:
        return None
    gap = pair_gaps(centres, radii, pairs)
    near = gap < within
    near[0] = False
    if not near.any():
        return None
    k, p = np.nonzero(near)  # the near pairs only (few): nearest first within each knot
    order = np.lexsort((gap[k, p], k))
    k, p = k[order], p[order]
    first = np.searchsorted(k, k)  # where each knot's run starts
    keep = np.arange(k.size) - first < slots
    k, p, slot = k[keep], p[keep], (np.arange(k.size) - first)[keep]
    rr = radii[pairs[:, 0]] + radii[pairs[:, 1]]
    short = extra - gap[0]
    lo = rr + extra - np.where(short > _SHORT_M, short, 0.0)  # a pair the start has closer stays as close
    deficit = float(np.max(lo[None] - rr[None] - gap[1:]))
    H1 = centres.shape[0]
    out_pairs = np.full((H1, slots, 2), -1, dtype=int)
    out_lo = np.full((H1, slots), -np.inf)
    out_pairs[k, slot] = pairs[p]
    out_lo[k, slot] = lo[p]
    return SelfRows(out_pairs, out_lo, deficit)
