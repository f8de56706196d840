"""The compiled half of the sphere check (`twin.collision.spheres` explains the model): link frames,
sphere placement and exact sphere-primitive distances in one numba loop per batch of configurations.

A module of its own so that numba (its import and its cached machine code, ~0.3 s) is loaded only by a
process that checks collisions. Arrays must be C-contiguous float64 (int64 for indices), as the scene
passes them, or numba compiles another specialisation.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

import numpy as np
from numba import njit

__all__ = [
    "clearance_bounds",
    "first_flagged",
    "first_flagged_motion",
    "first_touch_on_motion",
    "first_unproven_on_polyline",
    "flag_configurations",
    "new_scratch",
    "no_runtime_njit",
    "sphere_bounds",
    "sphere_evaluate",
]

_MARGIN_CAP_M = 0.25  # margins are not measured beyond this (farther pairs cost no square root), m
# conservative advancement (`first_touch_on_motion`) refines the distance bounds below this, m: coarser bounds
# (bounding spheres) make its steps short, finer ones cost more per configuration
_ADVANCE_REFINE_M = 0.03
_Fn = TypeVar("_Fn", bound=Callable[..., Any])


def no_runtime_njit(*, inline: bool = False) -> Callable[[_Fn], _Fn]:
    """numba's `njit` (cached, without the GIL) for compiled code that allocates nothing, compiled without
    numba's runtime (`_nrt=False`, the switch numba's own developers use to show its cost): with the runtime,
    each array taken out of a tuple or sliced is reference-counted by an atomic call, which was 60 % of a
    configuration's cost here (3.3 -> 1.3 us on MBM scenes). Callers with the runtime call such functions as
    any compiled function. Every kernel here but `new_scratch` is one; so is `twin_compiled`'s search loop."""

    def wrap(fn: _Fn) -> _Fn:
        jit = njit(cache=True, nogil=True, _nrt=False, inline="always" if inline else "never")  # type: ignore[call-overload]
        return cast(_Fn, jit(fn))

    return wrap


@no_runtime_njit(inline=True)
def _point_distance(kind: int, M: np.ndarray, d: np.ndarray, x: float, y: float, z: float) -> float:
    """Signed distance of the world point (x, y, z) from one primitive (negative inside)."""
    px = M[0, 0] * x + M[0, 1] * y + M[0, 2] * z + M[0, 3]
    py = M[1, 0] * x + M[1, 1] * y + M[1, 2] * z + M[1, 3]
    pz = M[2, 0] * x + M[2, 1] * y + M[2, 2] * z + M[2, 3]
    if kind == 0:  # box
        qx, qy, qz = abs(px) - d[0], abs(py) - d[1], abs(pz) - d[2]
        ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
        return math.sqrt(ox * ox + oy * oy + oz * oz) + min(max(qx, qy, qz), 0.0)
    if kind == 1:  # cylinder about local z
        qr = math.sqrt(px * px + py * py) - d[0]
        qz = abs(pz) - d[1]
        o1, o2 = max(qr, 0.0), max(qz, 0.0)
        return math.sqrt(o1 * o1 + o2 * o2) + min(max(qr, qz), 0.0)
    if kind == 3:  # capsule about local z
        cz = min(max(pz, -d[1]), d[1])
        return math.sqrt(px * px + py * py + (pz - cz) ** 2) - d[0]
    return math.sqrt(px * px + py * py + pz * pz) - d[0]


# The model, one tuple handed to every kernel (`twin.collision.robot_body.RobotBody.kernel_model` builds it):
# revolute, A, B, C, chain (the kinematic chain, `twin.collision.chain`); per object (robot shapes, then a held
# box): frame, pose in that frame (4, 4; its origin is the centre of its bounding sphere), primitive kind, half
# dimensions (as `EnvPrimitives`), bounding radius, whether it is tested against the environment, and its
# spheres sph[sph_start[o]:sph_start[o + 1]] (x, y, z in the frame, r); self pairs pair_a[p], pair_b[p]; the
# environment (`EnvPrimitives`: kind, to_local, dims, bound); the joints' reach and the pairs' moving joints
# (`_near_anchor`); the touch distance; per object and joint how far the joint moves its points per radian,
# and per self pair how far it moves one part relative to the other (`first_touch_on_motion`).
(_REVOLUTE, _A, _B, _C, _CHAIN, _OBJ_FRAME, _OBJ_CONST, _OBJ_KIND, _OBJ_DIMS, _OBJ_RADIUS, _OBJ_ENV) = range(11)
(_SPH_START, _SPH_FRAME, _SPH, _PAIR_A, _PAIR_B, _ENV_KIND, _ENV_TO_LOCAL, _ENV_DIMS, _ENV_BOUND) = range(11, 20)
_REACH, _PAIR_MOVES, _TOUCH, _OBJ_REACH, _PAIR_REACH = 20, 21, 22, 23, 24
TOUCH_SLOT = _TOUCH  # where the model tuple holds the touch distance (`SphereModel.with_touch`)
# what a compiled caller in another file must be rebuilt for: numba's on-disk cache of a function is keyed by
# its own file only, so a caller cached before this file changed would keep calling the old kernels
# (`twin_compiled.search` flushes its cache when this changes)
KERNEL_FINGERPRINT = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]
# the scratch tuple (`new_scratch`)
_F, _L, _OC, _INV, _SC, _PLACED, _POSED, _GAP_NOW, _ANCHOR_GAP, _W, _ANCHOR_Q, _QK, _OBJ_GAP = range(13)
_BUDGET, _SPEED = 13, 14


@njit(cache=True, nogil=True)  # allocates: the one function with numba's runtime
def new_scratch(n_obj: int, n_sph: int, n_pairs: int) -> tuple:  # type: ignore[type-arg]
    """Work arrays of one caller: link frames, a joint transform, object centres, inverted object poses,
    placed sphere centres, which objects are placed and posed, the self pairs' gaps now and at the anchor,
    the joints' share of a motion, the anchor configuration, a configuration on a motion, each object's
    distance bound, each part's and pair's budget and speed along a polyline. Made once per model, reused by
    every call (one caller at a time)."""
    F = np.zeros((7, 4, 4))
    F[:, 3, 3] = 1.0
    return (
        F,
        np.empty((4, 4)),
        np.empty((3, n_obj)),
        np.empty((n_obj, 3, 4)),
        np.empty((n_sph, 3)),
        np.zeros(n_obj, dtype=np.bool_),
        np.zeros(n_obj, dtype=np.bool_),
        np.zeros(n_pairs),
        np.zeros(n_pairs),
        np.zeros(6),
        np.zeros(6),
        np.zeros(6),
        np.zeros(n_obj),
        np.zeros(n_obj + n_pairs),
        np.zeros(n_obj + n_pairs),
    )


@no_runtime_njit()
def sphere_evaluate(K: tuple, S: tuple, q: np.ndarray) -> tuple[bool, float]:  # type: ignore[type-arg]
    """(flagged, env bound) of configuration q (6,): flagged unless the spheres prove it free (see the
    module docstring); when free, a lower bound on every robot-environment distance (capped at
    `_MARGIN_CAP_M`), each object's in S[_OBJ_GAP] and each self pair's gap in S[_GAP_NOW]. The bounds are
    the cheapest that prove the configuration free (`sphere_bounds` with refine = the touch distance)."""
    return sphere_bounds(K, S, q, K[_TOUCH])


@no_runtime_njit()
def sphere_bounds(K: tuple, S: tuple, q: np.ndarray, refine: float) -> tuple[bool, float]:  # type: ignore[type-arg]
    """`sphere_evaluate`, with every distance bound below `refine` m made as tight as the model allows.

    A bound comes from the cheapest level that exceeds `refine`: bounding sphere against bounding sphere, then
    the bounding sphere against the exact primitive, then the object's cover against the exact primitive (a
    self pair: each part's bounding sphere, then its cover, against the other's primitive, the larger). A
    bounding sphere encloses its primitive (not its cover), so every level is a lower bound on the exact
    distance; only the covers call a configuration touching. Refining further costs more per configuration
    and buys larger steps where a motion is checked by the bounds (`first_touch_on_motion`)."""
    obj_frame, obj_radius, obj_env = K[_OBJ_FRAME], K[_OBJ_RADIUS], K[_OBJ_ENV]
    sph_start, sph = K[_SPH_START], K[_SPH]
    env_kind, env_to_local, env_dims, env_bound = K[_ENV_KIND], K[_ENV_TO_LOCAL], K[_ENV_DIMS], K[_ENV_BOUND]
    pair_a, pair_b, touch = K[_PAIR_A], K[_PAIR_B], K[_TOUCH]
    F, oc, sc, placed, posed, gap_now = S[_F], S[_OC], S[_SC], S[_PLACED], S[_POSED], S[_GAP_NOW]
    _link_frames(q, K[_REVOLUTE], K[_A], K[_B], K[_C], K[_CHAIN], F, S[_L])
    _object_centres(F, obj_frame, K[_OBJ_CONST], oc, placed, posed)
    n_obj = obj_frame.shape[0]
    cx, cy, cz = oc[0], oc[1], oc[2]
    obj_gap = S[_OBJ_GAP]
    for o in range(n_obj):
        obj_gap[o] = _MARGIN_CAP_M
    # robot (and held box) against the environment, one primitive at a time: every object's bounding sphere
    # against the primitive's in one branch-free pass over the objects (SIMD), then the few within `refine`
    # again, tighter: the bounding sphere against the exact primitive, then the object's spheres
    for e in range(env_kind.shape[0]):
        ex, ey, ez, er = env_bound[e, 0], env_bound[e, 1], env_bound[e, 2], env_bound[e, 3]
        near = 0
        for o in range(n_obj):
            dx, dy, dz = cx[o] - ex, cy[o] - ey, cz[o] - ez
            gap = math.sqrt(dx * dx + dy * dy + dz * dz) - obj_radius[o] - er
            tested = obj_env[o]
            near += tested and gap <= refine
            obj_gap[o] = min(obj_gap[o], gap if tested and gap > refine else _MARGIN_CAP_M)
        if near == 0:
            continue
        for o in range(n_obj):
            if not obj_env[o]:
                continue
            dx, dy, dz = cx[o] - ex, cy[o] - ey, cz[o] - ez
            if math.sqrt(dx * dx + dy * dy + dz * dz) - obj_radius[o] - er > refine:
                continue
            gap = _point_distance(env_kind[e], env_to_local[e], env_dims[e], cx[o], cy[o], cz[o]) - obj_radius[o]
            if gap <= refine:
                if not placed[o]:
                    _place(F, sph_start[o], sph_start[o + 1], K[_SPH_FRAME], sph, sc)
                    placed[o] = True
                gap = max(
                    gap,
                    _spheres_gap(sc, sph, sph_start[o], sph_start[o + 1], env_kind[e], env_to_local[e], env_dims[e]),
                )
                if gap < touch:
                    return True, 0.0
            obj_gap[o] = min(obj_gap[o], gap)
    m = _MARGIN_CAP_M
    for o in range(n_obj):
        m = min(m, obj_gap[o])
    # self pairs, each with its own bound (the joints between its parts move them apart): bounding spheres in
    # one branch-free pass, then the pairs within `refine` again, tighter
    near = 0
    for p in range(pair_a.shape[0]):
        a, b = pair_a[p], pair_b[p]
        dx, dy, dz = cx[a] - cx[b], cy[a] - cy[b], cz[a] - cz[b]
        gap = math.sqrt(dx * dx + dy * dy + dz * dz) - obj_radius[a] - obj_radius[b]
        near += gap <= refine
        gap_now[p] = min(gap, _MARGIN_CAP_M)
    if near == 0:
        return False, m
    obj_kind, obj_dims, obj_const, inv = K[_OBJ_KIND], K[_OBJ_DIMS], K[_OBJ_CONST], S[_INV]
    for p in range(pair_a.shape[0]):
        best = gap_now[p]
        if best > refine:
            continue
        a, b = pair_a[p], pair_b[p]
        if sph_start[a + 1] - sph_start[a] > sph_start[b + 1] - sph_start[b]:
            a, b = b, a  # the part with fewer spheres against the other's primitive first: cheaper, as exact
        for a2, b2 in ((a, b), (b, a)):  # each part's bounding sphere against the other's primitive
            if not posed[b2]:
                _pose_inverse(F[obj_frame[b2]], obj_const[b2], inv[b2], S[_L])
                posed[b2] = True
            gap = _point_distance(obj_kind[b2], inv[b2], obj_dims[b2], cx[a2], cy[a2], cz[a2]) - obj_radius[a2]
            best = max(best, gap)
            if best > refine:
                break
        if best > refine:
            gap_now[p] = best
            continue
        for a2, b2 in ((a, b), (b, a)):  # each part's cover against the other's primitive
            if not placed[a2]:
                _place(F, sph_start[a2], sph_start[a2 + 1], K[_SPH_FRAME], sph, sc)
                placed[a2] = True
            gap = _spheres_gap(sc, sph, sph_start[a2], sph_start[a2 + 1], obj_kind[b2], inv[b2], obj_dims[b2])
            best = max(best, gap)
            if best > refine:
                break
        if best < touch:
            return True, 0.0
        gap_now[p] = best
    return False, m


@no_runtime_njit(inline=True)
def _flag_with_anchor(K: tuple, S: tuple, q: np.ndarray, anchor_env: float) -> tuple[bool, float]:  # type: ignore[type-arg]
    """`sphere_evaluate`, skipped when q is clear by the anchor's bounds (anchor_env < 0: no anchor yet); a newly
    cleared q becomes the anchor. Returns (flagged, the anchor's env bound now)."""
    if anchor_env >= 0.0 and _near_anchor(
        q, S[_ANCHOR_Q], K[_REACH], K[_PAIR_MOVES], anchor_env, S[_ANCHOR_GAP], K[_TOUCH], S[_W]
    ):
        return False, anchor_env
    flagged, m = sphere_evaluate(K, S, q)
    if flagged:
        return True, anchor_env
    anchor_q, anchor_gap, gap_now = S[_ANCHOR_Q], S[_ANCHOR_GAP], S[_GAP_NOW]
    for j in range(6):
        anchor_q[j] = q[j]
    for p in range(gap_now.shape[0]):
        anchor_gap[p] = gap_now[p]
    return False, m


@no_runtime_njit()
def flag_configurations(K: tuple, S: tuple, qs: np.ndarray, out: np.ndarray) -> None:  # type: ignore[type-arg]
    """out[i] = True unless the spheres prove configuration qs[i] free (see the module docstring). Along a
    sequence, configurations close to the last cleared one are cleared by its bounds (`_near_anchor`)."""
    anchor_env = -1.0
    for i in range(qs.shape[0]):
        out[i], anchor_env = _flag_with_anchor(K, S, qs[i], anchor_env)


@no_runtime_njit()
def clearance_bounds(K: tuple, S: tuple, qs: np.ndarray, objects: np.ndarray, out: np.ndarray) -> None:  # type: ignore[type-arg]
    """out[i] = a lower bound on the distance from the objects `objects` (indices) to the environment at
    configuration qs[i], as tight as the model allows within `_MARGIN_CAP_M` (capped there); -inf where the
    covers touch (no bound). Every level of `sphere_bounds` is a lower bound on the exact distance between
    the primitives, so what FCL measures is never below it."""
    for i in range(qs.shape[0]):
        flagged, _ = sphere_bounds(K, S, qs[i], _MARGIN_CAP_M)
        if flagged:
            out[i] = -np.inf
            continue
        obj_gap = S[_OBJ_GAP]
        b = _MARGIN_CAP_M
        for k in range(objects.shape[0]):
            b = min(b, obj_gap[objects[k]])
        out[i] = b


@no_runtime_njit()
def first_flagged(K: tuple, S: tuple, qs: np.ndarray) -> int:  # type: ignore[type-arg]
    """The index of the first configuration of qs (n, 6) the spheres do not prove free, or -1."""
    anchor_env = -1.0
    for i in range(qs.shape[0]):
        flagged, anchor_env = _flag_with_anchor(K, S, qs[i], anchor_env)
        if flagged:
            return i
    return -1


@no_runtime_njit()
def first_flagged_motion(K: tuple, S: tuple, a: np.ndarray, b: np.ndarray, resolution: float) -> int:  # type: ignore[type-arg]
    """The straight joint motion a -> b in n = ceil(max |b - a| / resolution) steps: configurations
    a + k/n (b - a), k = 1..n (a itself is not checked), evaluated coarse to fine (b first, then the
    midpoints of ever finer halvings: `twin_ompl`'s bisection order). Returns the first k flagged, or 0 when
    the spheres prove the whole motion free. One compiled call per motion, nothing allocated."""
    span = 0.0
    for j in range(6):
        span = max(span, abs(b[j] - a[j]))
    n = max(1, int(math.ceil(span / resolution - 1e-9)))
    qk = S[_QK]
    anchor_env = -1.0
    half = 1  # the first halving's step: the largest power of two below n (every k < n is an odd multiple
    while 2 * half < n:  # of exactly one power of two <= half, so each is evaluated once)
        half *= 2
    k, step = n, 0
    while True:
        for j in range(6):
            qk[j] = a[j] + (k / n) * (b[j] - a[j])
        flagged, anchor_env = _flag_with_anchor(K, S, qk, anchor_env)
        if flagged:
            return k
        if step == 0:  # b done: the halvings start
            if n == 1:
                return 0
            step, k = half, half
        else:
            k += 2 * step
        while k >= n:
            step //= 2
            if step == 0:
                return 0
            k = step


@no_runtime_njit()
def first_touch_on_motion(K: tuple, S: tuple, a: np.ndarray, b: np.ndarray, floor: float) -> float:  # type: ignore[type-arg]
    """The straight joint motion a -> b, checked continuously by conservative advancement: -1.0 when the
    spheres prove every configuration of it free (a and b included), else the fraction t in [0, 1] of the
    motion where they could not (a configuration touching, or a moving part within `floor` m of touching,
    where the advancement would crawl).

    b is evaluated first (a blocked extension usually ends inside something). Then from t = 0: a cleared
    configuration bounds each object's distance to the environment and each self pair's gap; over dt of the
    motion no point of object o moves farther than dt * sum_k |b_k - a_k| obj_reach[o, k], and the parts of a
    pair relative to each other no farther than dt * sum_k |b_k - a_k| pair_reach[p, k] (only the joints
    between them), so the motion is free up to the largest dt within every bound, and the next configuration
    evaluated is there. A part the motion does not move keeps its distance, however small. Far from
    everything the bounds are capped at `_MARGIN_CAP_M`: a step then moves no point more than that."""
    for j in range(6):  # one answer for a motion, whichever way it is asked (the same configurations evaluated)
        if a[j] != b[j]:
            if a[j] > b[j]:
                t = _advance(K, S, b, a, floor)
                return t if t < 0.0 else 1.0 - t
            break
    return _advance(K, S, a, b, floor)


@no_runtime_njit()
def _advance(K: tuple, S: tuple, a: np.ndarray, b: np.ndarray, floor: float) -> float:  # type: ignore[type-arg]
    """`first_touch_on_motion` from a to b."""
    touch = K[_TOUCH]
    obj_reach, pair_reach = K[_OBJ_REACH], K[_PAIR_REACH]
    qk, gap_now, obj_gap, dq = S[_QK], S[_GAP_NOW], S[_OBJ_GAP], S[_W]
    for k in range(6):
        dq[k] = abs(b[k] - a[k])
    flagged, _ = sphere_evaluate(K, S, b)
    if flagged:
        return 1.0
    t = 0.0
    while True:
        for j in range(6):
            qk[j] = a[j] + t * (b[j] - a[j])
        flagged, _ = sphere_bounds(K, S, qk, _ADVANCE_REFINE_M)
        if flagged:
            return t
        dt = np.inf
        for o in range(obj_gap.shape[0]):
            speed = 0.0
            for k in range(6):
                speed += obj_reach[o, k] * dq[k]
            if speed > 0.0:
                if obj_gap[o] - touch < floor:
                    return t
                dt = min(dt, (obj_gap[o] - touch) / speed)
        for p in range(gap_now.shape[0]):
            speed = 0.0
            for k in range(6):
                speed += pair_reach[p, k] * dq[k]
            if speed > 0.0:
                if gap_now[p] - touch < floor:
                    return t
                dt = min(dt, (gap_now[p] - touch) / speed)
        t += dt
        if t >= 1.0:
            return -1.0


@no_runtime_njit()
def first_unproven_on_polyline(K: tuple, S: tuple, Q: np.ndarray, floor: float) -> int:  # type: ignore[type-arg]
    """The polyline through the configurations Q (n, 6) (a timed trajectory's samples: what a judge that
    interpolates between them checks), checked continuously by conservative advancement as
    `first_touch_on_motion` checks one segment, but in one pass: the distance bounds of an evaluated
    configuration are spent along as many segments as they cover. Returns the index of the first segment the
    spheres cannot prove free, or -1 when they prove the whole polyline free."""
    touch = K[_TOUCH]
    obj_reach, pair_reach = K[_OBJ_REACH], K[_PAIR_REACH]
    qk, gap_now, obj_gap = S[_QK], S[_GAP_NOW], S[_OBJ_GAP]
    n_obj, n_pairs = obj_gap.shape[0], gap_now.shape[0]
    budget, speed = S[_BUDGET], S[_SPEED]
    i, t = 0, 0.0
    while i < Q.shape[0] - 1:
        for j in range(6):
            qk[j] = Q[i, j] + t * (Q[i + 1, j] - Q[i, j])
        flagged, _ = sphere_bounds(K, S, qk, _ADVANCE_REFINE_M)
        if flagged:
            return i
        for o in range(n_obj):
            budget[o] = obj_gap[o] - touch
        for p in range(n_pairs):
            budget[n_obj + p] = gap_now[p] - touch
        moved = False  # whether this evaluation's bounds carried the walk forward at all
        while i < Q.shape[0] - 1:
            # how far each part moves per unit of segment i, and the fraction of its rest the budgets allow
            f = 1.0 - t
            spent = False  # a moving part's budget is below the floor
            for o in range(n_obj + n_pairs):
                v = 0.0
                for k in range(6):
                    r = obj_reach[o, k] if o < n_obj else pair_reach[o - n_obj, k]
                    v += r * abs(Q[i + 1, k] - Q[i, k])
                speed[o] = v
                if v > 0.0:
                    if budget[o] < floor:
                        spent = True
                        break
                    f = min(f, budget[o] / v)
            if spent:
                break  # evaluate again here (or give up below, if these bounds carried nothing)
            if f >= 1.0 - t:  # the whole rest of the segment: spend and go on to the next
                for o in range(n_obj + n_pairs):
                    budget[o] -= (1.0 - t) * speed[o]
                i += 1
                t = 0.0
                moved = True
                continue
            t += f
            moved = moved or f > 0.0
            break
        if not moved:
            return i
    return -1


@no_runtime_njit(inline=True)
def _near_anchor(
    q: np.ndarray,
    anchor_q: np.ndarray,
    reach: np.ndarray,
    pair_moves: np.ndarray,
    anchor_env: float,
    anchor_gap: np.ndarray,
    touch: float,
    w: np.ndarray,
) -> bool:
    """Conservative advancement: whether q is clear by the bounds of the cleared anchor_q alone.

    A cleared configuration also yields a lower bound on every robot-environment distance (anchor_env,
    capped at `_MARGIN_CAP_M`) and one per self pair (anchor_gap). No point of the robot moves farther
    than sum_k |dq_k| reach[k] between two configurations (reach[k]: how far any robot point can be from
    joint k's axis), and the parts of a self pair move relative to each other only through the joints
    between them (pair_moves[p, k] = 1), so the configurations within all those bounds are clear too,
    without being evaluated. `w` (6,): scratch, each joint's share of the motion."""
    moved = 0.0
    for k in range(6):
        w[k] = abs(q[k] - anchor_q[k]) * reach[k]
        moved += w[k]
    clear = moved < anchor_env - touch
    p = 0
    while clear and p < anchor_gap.shape[0]:
        rel = 0.0
        for k in range(6):
            rel += pair_moves[p, k] * w[k]
        clear = rel < anchor_gap[p] - touch
        p += 1
    return clear


@no_runtime_njit(inline=True)
def _link_frames(
    q: np.ndarray,
    revolute: np.ndarray,
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    chain: np.ndarray,
    F: np.ndarray,
    L: np.ndarray,
) -> None:
    """The link frames at configuration q (6,): F[0] = identity, F[k + 1] = F[chain[k, 1]] @ (A[k] + u B[k]
    + v C[k]) for the joints in chain order (chain[:, 0] = joint index), u = sin q, v = 1 - cos q
    (revolute) or u = q, v = 0. Rigid transforms: only the top three rows are computed (the last stays
    0 0 0 1, as `new_scratch` made it). L (4, 4): scratch."""
    for r in range(3):
        for s in range(4):
            F[0, r, s] = 1.0 if r == s else 0.0
    for c in range(chain.shape[0]):
        j = chain[c, 0]
        f = chain[c, 1]
        qj = q[j]
        if revolute[j]:
            u = math.sin(qj)
            v = 1.0 - math.cos(qj)
        else:
            u = qj
            v = 0.0
        for r in range(3):
            for s in range(4):
                L[r, s] = A[j, r, s] + u * B[j, r, s] + v * C[j, r, s]
        for r in range(3):
            for s in range(3):
                F[j + 1, r, s] = F[f, r, 0] * L[0, s] + F[f, r, 1] * L[1, s] + F[f, r, 2] * L[2, s]
            F[j + 1, r, 3] = F[f, r, 0] * L[0, 3] + F[f, r, 1] * L[1, 3] + F[f, r, 2] * L[2, 3] + F[f, r, 3]


@no_runtime_njit(inline=True)
def _object_centres(
    F: np.ndarray, obj_frame: np.ndarray, obj_const: np.ndarray, oc: np.ndarray, placed: np.ndarray, posed: np.ndarray
) -> None:
    """oc[:, o]: the world centre of object o's bounding sphere; no object's spheres placed or pose inverted yet."""
    for o in range(obj_frame.shape[0]):
        fr = obj_frame[o]
        for r in range(3):
            oc[r, o] = (
                F[fr, r, 0] * obj_const[o, 0, 3]
                + F[fr, r, 1] * obj_const[o, 1, 3]
                + F[fr, r, 2] * obj_const[o, 2, 3]
                + F[fr, r, 3]
            )
        placed[o] = False
        posed[o] = False


@no_runtime_njit(inline=True)
def _spheres_gap(sc: np.ndarray, sph: np.ndarray, lo: int, hi: int, kind: int, M: np.ndarray, d: np.ndarray) -> float:
    """Smallest distance between the placed spheres lo..hi-1 and the primitive (kind, M, d), negative inside."""
    gap = np.inf
    for s in range(lo, hi):
        gap = min(gap, _point_distance(kind, M, d, sc[s, 0], sc[s, 1], sc[s, 2]) - sph[s, 3])
    return gap


@no_runtime_njit(inline=True)
def _pose_inverse(Ff: np.ndarray, const: np.ndarray, out: np.ndarray, P: np.ndarray) -> None:
    """World-to-local (3, 4) of the object at Ff @ const."""
    for r in range(3):
        for s in range(4):
            P[r, s] = Ff[r, 0] * const[0, s] + Ff[r, 1] * const[1, s] + Ff[r, 2] * const[2, s] + Ff[r, 3] * const[3, s]
    for r in range(3):
        for s in range(3):
            out[r, s] = P[s, r]
        out[r, 3] = -(P[0, r] * P[0, 3] + P[1, r] * P[1, 3] + P[2, r] * P[2, 3])


@no_runtime_njit(inline=True)
def _place(F: np.ndarray, lo: int, hi: int, sph_frame: np.ndarray, sph: np.ndarray, sc: np.ndarray) -> None:
    """World centres of spheres lo..hi-1 into sc."""
    for s in range(lo, hi):
        fr = sph_frame[s]
        x, y, z = sph[s, 0], sph[s, 1], sph[s, 2]
        for r in range(3):
            sc[s, r] = F[fr, r, 0] * x + F[fr, r, 1] * y + F[fr, r, 2] * z + F[fr, r, 3]
