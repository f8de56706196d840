"""The first (cold) solve's initial guess of the MPCs (`nmpc`, `croc`): knots the solver starts from when there
is no plan to shift.

A straight initial guess through the perceived box starts IPOPT where the box distance has zero gradient
(the smooth-outside distance of the MPCs' box rows, `twin.planning.proxy_spheres`), so when the straight
Cartesian line to the goal crosses a box the guess goes over it: lift, transfer, lower, through
continuity-seeded IK at constant tool orientation (measured on the bench scenes: ~35 IPOPT iterations from
this guess, ~180 from the straight one). Without a continuous IK along the way, the guess heads straight for
the goal configuration nearest in the arm joints. The path is then resampled into the horizon's knots from
rest, under the step bound and, with an acceleration bound, coming to rest at every corner.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from twin.planning.proxy_spheres import TCP_FRAME, Box, sphere_positions
from twin.planning.receding_params import RecedingParams

if TYPE_CHECKING:
    from twin.plugin import URArm

__all__ = ["guess_slack", "initial_guess", "resample", "segment_hits_box"]

log = logging.getLogger("twin")


def segment_hits_box(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Slab test: does the segment a-b meet the box [lo, hi]?"""
    t0, t1 = 0.0, 1.0
    d = b - a
    for i in range(3):
        if abs(d[i]) < 1e-12:
            if a[i] < lo[i] or a[i] > hi[i]:
                return False
            continue
        u, v = (lo[i] - a[i]) / d[i], (hi[i] - a[i]) / d[i]
        t0, t1 = max(t0, min(u, v)), min(t1, max(u, v))
        if t0 > t1:
            return False
    return True


def resample(
    path: np.ndarray, step: float, n: int, dstep: float | None = None, *, stops: Sequence[int] = ()
) -> np.ndarray:
    """n knots along the joint polyline `path` (m, 6) (path[0] excluded), from rest, at most `step` apart
    (inf-norm arc length). With `dstep`, every joint's step changes by at most about `dstep` per step:
    the speed along the path ramps by dstep, is capped where the path bends (sqrt(dstep / curvature)) and
    comes to rest at the path indices in `stops` and at the end (a forward-backward pass over a velocity
    limit curve, as in time-optimal path parameterisation). Without it a path shorter than n steps is
    spread evenly. The knots stay at the end once there; a longer path is cut after n steps."""
    seg = np.abs(np.diff(path, axis=0)).max(axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    L = float(s[-1])
    if L < 1e-12:
        return np.repeat(path[-1:], n, axis=0)
    if dstep is None:
        m = math.ceil(L / step - 1e-9)
        targets = np.minimum(np.arange(1, n + 1) * (L / m if m <= n else step), L)
    else:
        # velocity limit curve at the path's points: curvature of q(s), rests, then the backward pass
        vmax = np.full(s.size, step)
        if s.size > 2:
            ds = np.maximum(np.diff(s), 1e-9)
            tang = np.diff(path, axis=0) / ds[:, None]
            curv = np.abs(np.diff(tang, axis=0)).max(axis=1) / np.maximum(0.5 * (ds[:-1] + ds[1:]), 1e-9)
            vmax[1:-1] = np.minimum(step, np.sqrt(dstep / np.maximum(curv, 1e-12)))
        for i in stops:
            if 0 < i < s.size:
                vmax[i] = 0.0
        vmax[-1] = 0.0
        for i in range(s.size - 2, -1, -1):
            vmax[i] = min(vmax[i], math.sqrt(vmax[i + 1] ** 2 + 2.0 * dstep * (s[i + 1] - s[i])))
        rests = sorted({float(s[i]) for i in stops if 0 < i < s.size} | {L})
        targets, pos, v = np.empty(n), 0.0, 0.0
        for i in range(n):
            stop = next((r for r in rests if r > pos + 1e-12), L)
            d = stop - pos
            v = min(
                v + dstep, max(float(np.interp(pos, s, vmax)), dstep), max(math.sqrt(2.0 * dstep * d) - dstep, dstep)
            )
            if v >= d:  # arrive at a rest point (at most dstep away) and leave it from rest
                v, pos = 0.0, stop
            else:
                pos += v
            targets[i] = pos
    out = np.empty((n, 6))
    for j in range(6):
        out[:, j] = np.interp(targets, s, path[:, j])
    return out


def guess_slack(kin: URArm, knots: np.ndarray, sph: np.ndarray, params: RecedingParams) -> np.ndarray:
    """(N,) table-clearance slack per knot (N, 6) that makes the guess feasible for the soft table rows."""
    z = sphere_positions(kin, knots, sph)[:, :, 2]
    need = params.table_z_m + params.table_clearance_m - (z - sph[None, :, 4])
    return np.maximum(need.max(axis=1), 0.0)


def initial_guess(
    kin: URArm,
    params: RecedingParams,
    q0: np.ndarray,
    target: np.ndarray,
    track: np.ndarray,
    goal_candidates: np.ndarray,
    boxes: list[Box],
    sph: np.ndarray,
    step: np.ndarray,
    dstep: np.ndarray | None = None,
    jstep: np.ndarray | None = None,
) -> tuple[np.ndarray, str]:
    """(N, 6) knots for a cold solve from `q0` (6,), and what kind of guess they are ("straight",
    "over_box", either + "+joint_fallback"): a straight Cartesian line that brings the point `track` (3,)
    (TCP frame) to `target` (3,) (base frame) when it clears every box, else lift, transfer over the box,
    lower; both through continuity-seeded IK at constant tool orientation, ending in the goal configuration
    nearest to the path. Without continuous IK, straight towards the nearest of `goal_candidates` (k, 6)."""
    P = params
    T0 = kin.fk(q0, "tcp")
    R0 = T0[:3, :3]
    p0 = T0[:3, 3] + R0 @ track
    pg = target
    m = P.box_margin_m
    tcp_sph = sph[sph[:, 0] == TCP_FRAME, 1:5]
    reach = float(np.max(np.linalg.norm(tcp_sph[:, :3] - track, axis=1) + tcp_sph[:, 3]))
    crossed = [(n, lo, hi) for n, lo, hi in boxes if segment_hits_box(p0, pg, lo - m - reach, hi + m + reach)]
    if crossed and P.initial_guess == "straight":
        log.info(
            "nmpc: the straight initial guess crosses %s; IPOPT may stay stuck below it", [n for n, _, _ in crossed]
        )
        crossed = []
    if crossed:
        below = float(np.max(tcp_sph[:, 3] - (R0 @ (tcp_sph[:, :3] - track).T)[2]))
        z_lift = max(hi[2] for _, _, hi in crossed) + m + below + P.lift_clearance_m
        way = [p0, np.array([p0[0], p0[1], max(z_lift, p0[2])]), np.array([pg[0], pg[1], max(z_lift, pg[2])]), pg]
        kind = "over_box"
        log.info(
            "nmpc: the straight line to the goal crosses %s; seeding the first solve over it (z %.3f m)",
            [n for n, _, _ in crossed],
            z_lift,
        )
    else:
        way = [p0, pg]
        kind = "straight"
    pts, corners = [way[0]], []
    for a, b in itertools.pairwise(way):
        n = max(1, math.ceil(float(np.linalg.norm(b - a)) / 0.02))
        pts += [a + (b - a) * i / n for i in range(1, n + 1)]
        corners.append(len(pts) - 1)  # the guess comes to rest here: joints may turn around
    path = [q0]
    continuous = True
    T = np.eye(4)
    T[:3, :3] = R0
    for pt in pts[1:]:
        T[:3, 3] = pt - R0 @ track
        sols = kin.ik(T, "tcp")
        if sols.shape[0] == 0:
            continuous = False
            break
        d = np.abs(sols - path[-1]).max(axis=1)
        i = int(np.argmin(d))
        if d[i] > 0.5:
            continuous = False
            break
        path.append(sols[i])
    if not continuous:
        # the Cartesian path already ends at the goal position (orientation is not tracked); only
        # without it does the guess head for a goal configuration, the one nearest in arm joints
        kind += "+joint_fallback"
        log.info("nmpc: no continuous IK along the initial-guess path; using a joint-space guess")
        path, corners = [q0], []
        if goal_candidates.shape[0]:
            d = np.abs(goal_candidates - q0) @ np.array([1.0, 1.0, 1.0, 1.0, 1.0, 0.1])
            path.append(goal_candidates[int(np.argmin(d))])
    f = P.guess_step_fraction
    # half the acceleration: the inf-norm arc length bounds the fastest joint, others turn within a leg;
    # the speed ramps switch between +a and -a at most, a change of 2 a: within the jerk bound too
    bound = [float(np.min(b)) for b in (dstep, jstep) if b is not None]
    a = 0.5 * f * min(bound) if bound else None
    return resample(np.array(path), f * float(step.min()), P.horizon, a, stops=corners), kind
