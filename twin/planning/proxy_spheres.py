"""The proxy spheres the MPCs keep out of the obstacle boxes, and the numpy check of a plan's hard constraints.

Both MPCs (`twin_nmpc.nlp`'s NLP, `twin_croc`'s OCP) model the gripper, the wrist and a held box as spheres
(frame, x, y, z, r): `robot_spheres` from the parameters, `object_spheres` covering the held box, `with_object`
both together. Every plan is checked again here, independently of the solver's own view, before a step of it
is executed (`violation`): joint steps, their change and the change of that (acceleration, jerk), joint
limits, the spheres' pairwise box rows at the NLP's check points (`pair_clearance`, the numeric twin of nmpc's
rows), and the joint-linear path between knots densely against the boxes.

A box is (name, lo (3,), hi (3,)) in the base frame, m, without the margin.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from twin.plugin import URArm

__all__ = [
    "CHECK_TOL_M",
    "CHORD_EPS2",
    "DISTANCE_EPS2",
    "TCP_FRAME",
    "Box",
    "box_gaps",
    "clearance",
    "drop_covered",
    "object_spheres",
    "pair_clearance",
    "path_gaps",
    "robot_spheres",
    "segment_box_distance",
    "sphere_box_clearance",
    "sphere_centres",
    "sphere_positions",
    "subdivide",
    "violation",
    "with_object",
]

log = logging.getLogger("twin")

Box = tuple[str, np.ndarray, np.ndarray]

CHECK_TOL_M = 5e-4  # the numpy re-check of the hard constraints accepts this much below the margin
TCP_FRAME = 7  # sphere frame code of the TCP (DH frames are 0..6)
# the smoothing of the box rows, shared by every MPC's rows (`twin_nmpc.nlp`) and their numeric twins here:
DISTANCE_EPS2 = 1e-10  # (10 um)^2 under the distance's square root (feasible distances are >= r anyway)
# under the chord's square root: (1 cm)^2. A robot standing still (the horizon's tail, once at the goal)
# has zero chords, where sqrt(x^2 + eps) has curvature 1/sqrt(eps): with (10 um)^2 that was 1e5, IPOPT
# regularised heavily and cycled for ~100 iterations. 1 cm costs at most 5 mm of extra clearance there.
CHORD_EPS2 = 1e-4


def sphere_centres(frames: np.ndarray, tcp_offset_m: float, spheres: np.ndarray) -> np.ndarray:
    """Numeric twin of the NLP's sphere model: centres (m, n, 3) of spheres (n, 5) = (frame, x, y, z, r)
    for DH frames (m, 7, 4, 4) from `URArm.dh_frames`; frame TCP_FRAME is the TCP (`twin.planning.mpc_kernel`)."""
    from twin.planning.mpc_kernel import sphere_centres_into  # lazy: numba (compiled on first use)

    tool = np.eye(4)
    tool[2, 3] = tcp_offset_m
    spheres = np.asarray(spheres, dtype=float)
    out = np.empty((frames.shape[0], spheres.shape[0], 3))
    frame = spheres[:, 0].astype(np.int64)
    if np.any((frame < 0) | (frame > TCP_FRAME)):
        raise ValueError(f"sphere frames must be DH frames 0..6 or the tcp ({TCP_FRAME}), got {sorted(set(frame))}")
    sphere_centres_into(np.ascontiguousarray(frames), tool, frame, np.ascontiguousarray(spheres[:, 1:4]), out)
    return out


def sphere_box_clearance(centres: np.ndarray, radii: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Signed clearance (m) of spheres (n, 3), radii (n,) from the box [lo, hi]: distance from each centre to
    the box minus its radius; negative when the sphere enters the box (centres inside give -radius or less)."""
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    d = np.abs(centres - c) - h
    outside = np.linalg.norm(np.maximum(d, 0.0), axis=-1)
    inside = np.minimum(d.max(axis=-1), 0.0)
    return outside + inside - radii


def pair_clearance(centres: np.ndarray, radii: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Numeric twin of the NLP's box rows: for consecutive check points (m, n, 3) of n spheres, the
    guaranteed clearance (m-1, n) along the way, (d(a) + d(b) - |c(b) - c(a)|) / 2 - r (m; >= 0 is clear)."""
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    d = np.sqrt(np.sum(np.maximum(np.abs(centres - c) - h, 0.0) ** 2, axis=-1) + DISTANCE_EPS2)
    chord = np.sqrt(np.sum(np.diff(centres, axis=0) ** 2, axis=-1) + CHORD_EPS2)
    return 0.5 * (d[:-1] + d[1:] - chord) - radii


@functools.lru_cache(maxsize=64)
def _warn_large_spheres(size: tuple[float, ...], r: float, r_max: float, n: int) -> None:
    """Say once per process and box (not at every receding-horizon step) that its spheres are coarse: at info
    level (`-v`), a detail of the model that explains a conservative plan, not a fault to act on."""
    log.info("nmpc: held box %s needs spheres of %.3f m (> %.3f m) with %d spheres", list(size), r, r_max, n)


def object_spheres(size: np.ndarray, T_tcp_obj: np.ndarray, *, r_min: float, r_max: float, max_n: int) -> np.ndarray:
    """(n, 4) spheres (x, y, z, r) in the TCP frame covering a held box of full extents `size`.

    The box is cut into n equal pieces along its longest axis, each covered by its circumscribed
    sphere; n is the smallest count whose radius is <= r_max (capped at max_n, radius then larger).
    """
    half = 0.5 * np.asarray(size, dtype=float)
    ax = int(np.argmax(half))
    rest = float(np.sum(np.delete(half, ax) ** 2))
    n = 1
    while n < max_n and math.sqrt((half[ax] / n) ** 2 + rest) > r_max:
        n += 1
    r = max(math.sqrt((half[ax] / n) ** 2 + rest), r_min)
    if r > r_max + 1e-12:
        _warn_large_spheres(tuple(float(v) for v in size), round(r, 4), r_max, n)
    offs = np.zeros((n, 3))
    offs[:, ax] = (np.arange(n) + 0.5) / n * 2 * half[ax] - half[ax]
    centres = (T_tcp_obj[:3, :3] @ offs.T).T + T_tcp_obj[:3, 3]
    return np.hstack([centres, np.full((n, 1), r)])


def robot_spheres(
    tool: np.ndarray | Sequence[Sequence[float]], wrist: np.ndarray | Sequence[Sequence[float]] = ()
) -> np.ndarray:
    """(n, 5) spheres (frame, x, y, z, r): `tool` (x, y, z, r) in the TCP frame, then `wrist` as given."""
    t = np.asarray(tool, dtype=float).reshape(-1, 4)
    w = np.asarray(wrist, dtype=float).reshape(-1, 5)
    return np.vstack([np.hstack([np.full((t.shape[0], 1), TCP_FRAME), t]), w])


def drop_covered(obj: np.ndarray, robot_sph: np.ndarray) -> np.ndarray:
    """The held-object spheres (n, 4) that no tool sphere of `robot_sph` (k, 5) contains.

    A held-object sphere inside a tool sphere adds constraints but no protection (a 50 mm cube held at the
    TCP sits inside the TCP sphere): dropping it makes solves cheaper."""
    tool = robot_sph[robot_sph[:, 0] == TCP_FRAME, 1:5]
    gap = np.linalg.norm(obj[:, None, :3] - tool[None, :, :3], axis=2) + obj[:, None, 3] - tool[None, :, 3]
    return obj[~np.any(gap <= 1e-9, axis=1)]


def with_object(robot_sph: np.ndarray, obj: np.ndarray) -> np.ndarray:
    """(n, 5) all proxy spheres: the robot's (k, 5), then the held object's (m, 4) in the TCP frame."""
    if not obj.size:
        return robot_sph.copy()
    return np.vstack([robot_sph, np.hstack([np.full((obj.shape[0], 1), TCP_FRAME), obj])])


def sphere_positions(kin: URArm, qs: np.ndarray, sph: np.ndarray) -> np.ndarray:
    """Centres (m, n, 3) of the spheres `sph` (n, 5) at configurations `qs` (m, 6) (or one (6,)), base frame."""
    return sphere_centres(kin.dh_frames(np.atleast_2d(qs)), kin.tcp_offset_m, sph)


def subdivide(knots: np.ndarray, n: int) -> np.ndarray:
    """The joint-linear path through knots (m+1, 6) at n points per step, knots[0] excluded: (m*n, 6)."""
    f = np.arange(1, n + 1) / n
    return (knots[:-1, None, :] + f[None, :, None] * (knots[1:] - knots[:-1])[:, None, :]).reshape(-1, 6)


def clearance(kin: URArm, qs: np.ndarray, sph: np.ndarray, boxes: list[Box], *, margin: float) -> np.ndarray:
    """(m, n_boxes * n_spheres) signed clearances of the spheres at qs from the boxes grown by `margin`."""
    if not boxes:
        return np.zeros((qs.shape[0], 0))
    centres = sphere_positions(kin, qs, sph)
    cols = [sphere_box_clearance(centres, sph[None, :, 4], lo - margin, hi + margin) for _, lo, hi in boxes]
    return np.concatenate(cols, axis=1)


def violation(
    kin: URArm,
    knots: np.ndarray,
    sph: np.ndarray,
    boxes: list[Box],
    step: np.ndarray,
    dstep: np.ndarray | None,
    jstep: np.ndarray | None = None,
    *,
    dq_prev: np.ndarray,
    dq_prev2: np.ndarray | None = None,
    box_margin_m: float,
    substeps: int,
) -> str | None:
    """Why the knot path (m+1, 6) (knots[0] = the current state, reached by the step `dq_prev` after the step
    `dq_prev2`) breaks a hard constraint, or None: a joint step beyond `step` (6,), a change of step beyond
    `dstep` (6,), a change of that change beyond `jstep` (6,) (None: not bounded), a knot outside the joint
    limits, a sphere closer than CHECK_TOL_M inside a box grown by `box_margin_m` anywhere on the straight
    lines between `substeps` check points per step (`path_gaps`), or inside a box itself between knots."""
    dq = np.diff(knots, axis=0)
    if np.any(np.abs(dq) > step + 1e-7):
        return f"a joint step of {np.abs(dq).max():.3f} rad exceeds {step.max():.3f} rad"
    hist = np.vstack([np.zeros(6) if dq_prev2 is None else dq_prev2, dq_prev, dq])
    if dstep is not None:
        ddq = np.abs(np.diff(hist[1:], axis=0))
        if np.any(ddq > dstep + 1e-7):
            return f"a joint step changes by {ddq.max():.4f} rad, more than {dstep.max():.4f} rad (acceleration)"
    if jstep is not None:
        dddq = np.abs(np.diff(hist, n=2, axis=0))
        if np.any(dddq > jstep + 1e-7):
            return f"a joint step's change changes by {dddq.max():.4f} rad, more than {jstep.max():.4f} rad (jerk)"
    lim = kin.joint_limits
    if np.any(knots < lim[:, 0] - 1e-9) or np.any(knots > lim[:, 1] + 1e-9):
        return "a knot leaves the joint limits"
    if boxes:
        gaps = path_gaps(kin, knots, sph, boxes, box_margin_m=box_margin_m, substeps=substeps)
        for (name, _, _), gap in zip(boxes, gaps, strict=True):
            if gap < -CHECK_TOL_M:
                return f"proxy spheres may come {-gap:.4f} m into box {name!r} (incl. margin) between check points"
                # (or that much deeper than they started, when they start within its margin)
        # belt and braces: the joint-linear path, densely, against the boxes themselves (a sphere a planner lets
        # start inside one, `RecedingHorizonMPC._refuses_sphere_overlap`, no deeper than it started)
        dense = clearance(kin, subdivide(knots, 8), sph, boxes, margin=0.0)
        start = np.minimum(clearance(kin, knots[:1], sph, boxes, margin=0.0)[0], 0.0)
        if np.any(dense < start - CHECK_TOL_M * (start < 0.0)):
            deepest = float((start - dense).max())
            return f"a proxy sphere enters an obstacle box by {deepest:.4f} m between knots"
    return None


def segment_box_distance(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(...,) the distance of each segment a -> b (..., 3) from the box [lo, hi] (0 where it touches or
    enters): the point-box distance along a line is convex, so a golden-section search finds its minimum
    (to 1e-6 of the segment's length)."""

    def dist(t: np.ndarray) -> np.ndarray:
        p = a + t[..., None] * (b - a)
        return np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=-1)

    g = (math.sqrt(5.0) - 1.0) / 2.0
    x0, x1 = np.zeros(a.shape[:-1]), np.ones(a.shape[:-1])
    for _ in range(30):
        m1, m2 = x1 - g * (x1 - x0), x0 + g * (x1 - x0)
        left = dist(m1) <= dist(m2)
        x0, x1 = np.where(left, x0, m1), np.where(left, m2, x1)
    return np.minimum(np.minimum(dist(a[..., 0] * 0.0), dist(np.ones(a.shape[:-1]))), dist(0.5 * (x0 + x1)))


def path_gaps(
    kin: URArm, knots: np.ndarray, sph: np.ndarray, boxes: list[Box], *, box_margin_m: float, substeps: int
) -> np.ndarray:
    """(n_boxes,) the smallest clearance (m) of the spheres from each box (grown by the margin) along straight
    lines between `substeps` check points per step of the knot path (m+1, 6): what every MPC's box rows must
    keep (nmpc's pairwise rows guarantee it; croc's face rows keep each line beyond one face). A sphere that
    starts inside a box's margin (not the box: that start is refused) is held only to going no deeper than it
    started, so its clearance counts from there (a can lifted beside a bottle has nowhere else to start from).
    Where a line is clear by a conservative bound, the bound is what is counted (>= 0: the line passes).
    The path between the check points curves off these lines by millimetres; `violation` checks it densely
    against the boxes."""
    if not boxes:
        return np.zeros(0)
    m = box_margin_m
    seq = np.vstack([knots[:1], subdivide(knots, substeps)])
    c = sphere_positions(kin, seq, sph)
    r = sph[:, 4]
    chord = np.linalg.norm(np.diff(c, axis=0), axis=-1)  # (M-1, n)
    out = []
    for _, lo, hi in boxes:
        d = np.linalg.norm(np.maximum(np.maximum(lo - m - c, c - hi - m), 0.0), axis=-1)  # (M, n) at the points
        allowed = np.minimum(d[0] - r, 0.0)  # (n,)
        # a line's distance is at least (d(a) + d(b) - |b - a|) / 2: only lines that bound does not clear are
        # searched exactly (a whole-arm plan: ~2300 lines x 15 boxes, of which a few dozen come near a box)
        gap = 0.5 * (d[:-1] + d[1:] - chord) - r - allowed
        near = gap < 0.0
        if near.any():
            a, b = c[:-1][near], c[1:][near]
            gap[near] = segment_box_distance(a, b, lo - m, hi + m) - np.broadcast_to(r, near.shape)[near]
            gap[near] -= np.broadcast_to(allowed, near.shape)[near]
        out.append(float(gap.min()))
    return np.array(out)


def box_gaps(
    kin: URArm, knots: np.ndarray, sph: np.ndarray, boxes: list[Box], *, box_margin_m: float, substeps: int
) -> np.ndarray:
    """(n_boxes,) the smallest guaranteed clearance (m) of the spheres from each box (grown by the margin) along
    the knot path (m+1, 6) at `substeps` check points per step: the NLP's box rows (`pair_clearance`), per box."""
    if not boxes:
        return np.zeros(0)
    m = box_margin_m
    seq = np.vstack([knots[:1], subdivide(knots, substeps)])
    centres = sphere_positions(kin, seq, sph)
    return np.array([float(pair_clearance(centres, sph[:, 4], lo - m, hi + m).min()) for _, lo, hi in boxes])
