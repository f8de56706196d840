"""The sphere rows of a horizon: per knot and sphere, the axis-aligned region its centre must stay in so that the
sphere stays beyond one face of every (margin-grown) box near it.

A sphere outside a box is beyond at least one of its six faces; "beyond face f" is a bound on one coordinate
of the sphere's centre. Beyond a face of box A and a face of box B is still an axis-aligned region (the
tighter bound where two faces bound the same coordinate the same way), so each sphere needs one
frame-translation row per knot, however many boxes there are: crocoddyl has no sphere-box distance residual,
a Python residual costs ms per iteration, and the rows of the QP, not the boxes, set a solve's price.

The face is the one the sphere is farthest out of at the middle of the step on the plan the solve starts
from, and the bound holds at both knots of the step, so the sphere's straight way between them stays beyond
it too (bounding only the knots let the path cut 44 mm into the warehouse wall in the issue's spike); a knot
holds the bounds of the step ending there and of the one starting there. Only pairs that come within `within`
of each other somewhere along the plan are bounded (a RoboCup cell has ~15 boxes); the loop's independent
check judges every pair, and a solution that comes close to a pair without bounds is solved again with it.

A box is (name, lo (3,), hi (3,)) without the margin, as `twin.plugin.Box`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["FREE", "Pairs", "close_pairs", "gaps", "sphere_bounds"]

FREE = np.inf  # the bound of a coordinate nothing bounds (CSQP gives a row open on both sides no weight)

_SHORT_M = 1e-3  # a start nearer a bound than this is not relaxed (the QP holds bounds to ~its tolerance)

Pairs = set[tuple[int, int]]  # (sphere, box) pairs that are bounded


def gaps(centres: np.ndarray, radii: np.ndarray, lo: np.ndarray, hi: np.ndarray, margin: float) -> np.ndarray:
    """(m, n, B) distances of the spheres (centres (m, n, 3), radii (n,)) from the boxes grown by `margin`
    (lo, hi (B, 3)); 0 or less when a sphere touches or enters one (how deep is not measured)."""
    c = centres[:, :, None, :]
    out = np.maximum(np.maximum(lo[None, None] - margin - c, c - hi[None, None] - margin), 0.0)
    return np.linalg.norm(out, axis=-1) - radii[None, :, None]


def close_pairs(
    centres: np.ndarray,
    radii: np.ndarray,
    boxes: Sequence[tuple[str, np.ndarray, np.ndarray]],
    margin: float,
    within: float | None,
) -> Pairs:
    """The pairs within `within` m at some knot of the path (centres (m, n, 3)); every pair when None."""
    n = centres.shape[1]
    if not boxes:
        return set()
    if within is None:
        return {(s, b) for s in range(n) for b in range(len(boxes))}
    lo = np.array([b[1] for b in boxes], dtype=float)
    hi = np.array([b[2] for b in boxes], dtype=float)
    near = (gaps(centres, radii, lo, hi, margin) < within).any(axis=0)
    return {(int(s), int(b)) for s, b in zip(*np.nonzero(near), strict=True)}


def sphere_bounds(
    centres: np.ndarray,
    radii: np.ndarray,
    boxes: Sequence[tuple[str, np.ndarray, np.ndarray]],
    pairs: Pairs,
    *,
    margin: float,
    tighten: float,
) -> np.ndarray:
    """(H+1, n, 2, 3) lower and upper bounds on each sphere's centre at each knot of the plan `centres`
    (H+1, n, 3) (knot 0, the measured state: free): beyond, by `tighten` m more (CSQP holds bounds to ~1e-3),
    the face of each paired box the sphere is farthest out of at the middle of each step, for both knots of
    the step. Where a knot's two steps bound a coordinate from opposite sides with no room between (the plan
    crosses a box there), the later step's bound is kept; where two boxes of one step do (the sphere passes
    between walls closer than its size), that coordinate is not bounded in the step. Every lower bound is
    below its upper bound (crocoddyl refuses others)."""
    H, n = centres.shape[0] - 1, centres.shape[1]
    step = np.empty((H, n, 2, 3))
    step[:, :, 0], step[:, :, 1] = -FREE, FREE
    mid = 0.5 * (centres[:-1] + centres[1:])  # (H, n, 3)
    by_box: dict[int, list[int]] = {}
    for sphere, box in pairs:
        by_box.setdefault(box, []).append(sphere)
    for b, members in by_box.items():
        s = np.array(sorted(members))
        lo_m = np.asarray(boxes[b][1], dtype=float) - margin
        hi_m = np.asarray(boxes[b][2], dtype=float) + margin
        c = mid[:, s]  # (H, k, 3)
        outside = np.concatenate([c - hi_m, lo_m - c], axis=-1)  # +x +y +z -x -y -z
        face = np.argmax(outside, axis=-1)  # (H, k)
        r = radii[s][None, :]
        # on the way to passing over the box, a sphere above its top stays above it: the side face it is
        # farthest out of would let the position cost pull it down beside the box, where it waits pressed
        # against that face until the face changes (over the warehouse wall: the tcp sat at the wall for 9 of
        # 20 steps); after it has passed over, the side faces let it come down behind the box
        knots = centres[:, s]  # (H+1, k, 3)
        over = np.all(
            (knots[..., :2] >= lo_m[:2] - r[..., None]) & (knots[..., :2] <= hi_m[:2] + r[..., None]), axis=-1
        )
        above = knots[..., 2] >= hi_m[2] + r
        first = np.where(over.any(axis=0), np.argmax(over, axis=0), -1)  # first knot over the box, per sphere
        approach = (np.arange(H)[:, None] < first[None, :]) & above[:-1]
        face = np.where(approach, 2, face)
        axis, upper = face % 3, face < 3
        kk, ss = np.meshgrid(np.arange(H), s, indexing="ij")
        up_k, up_s, up_a = kk[upper], ss[upper], axis[upper]
        value = hi_m[up_a] + np.broadcast_to(r, upper.shape)[upper] + tighten
        # a sphere that starts within the box's margin (not the box: the loop refuses that start) may not go
        # deeper than it started, and the loop's check holds it to the same: every face bound of the pair gives
        # way by how far the start falls short of it (a can lifted beside a bottle has nowhere else to start)
        start = centres[0]  # (n, 3)
        dist = np.linalg.norm(np.maximum(np.maximum(lo_m - start, start - hi_m), 0.0), axis=-1)
        short = radii + tighten - dist  # (n,); a sphere the last plan left on its bound, short by round-off,
        short = np.where(short > _SHORT_M, short, 0.0)  # keeps its bounds (and its duals: warm starts)
        value = value - short[up_s]
        # (one face per step and sphere for this box: the indices are unique, so no ufunc.at is needed)
        at = (up_k, up_s, np.zeros_like(up_k), up_a)
        step[at] = np.maximum(step[at], value)
        dn = ~upper
        dn_k, dn_s, dn_a = kk[dn], ss[dn], axis[dn]
        value = lo_m[dn_a] - np.broadcast_to(r, upper.shape)[dn] - tighten
        value = value + short[dn_s]
        at = (dn_k, dn_s, np.ones_like(dn_k), dn_a)
        step[at] = np.minimum(step[at], value)
    # two boxes bounding a coordinate from opposite sides with no room for the sphere between them (it passes
    # between two walls too close for it): that coordinate is left to the loop's check in this step
    shut = step[:, :, 0] >= step[:, :, 1]
    step[:, :, 0] = np.where(shut, -FREE, step[:, :, 0])
    step[:, :, 1] = np.where(shut, FREE, step[:, :, 1])
    out = np.empty((H + 1, n, 2, 3))
    out[0, :, 0], out[0, :, 1] = -FREE, FREE
    out[1:] = step  # the step ending at knot k (k = 1..H)
    later = step[1:]  # the step starting at knot k (k = 1..H-1)
    lo = np.maximum(out[1:H, :, 0], later[:, :, 0])
    hi = np.minimum(out[1:H, :, 1], later[:, :, 1])
    crossed = lo >= hi
    out[1:H, :, 0] = np.where(crossed, later[:, :, 0], lo)
    out[1:H, :, 1] = np.where(crossed, later[:, :, 1], hi)
    return out
