"""The NMPC optimal-control problem (CasADi + IPOPT), built once and solved again and again.

Why this shape (see LIBRARY-NOTES, CasADi 3.8): every joint configuration of the horizon is a decision
variable ("multiple shooting" over the trivial integrator q_{j+1} = q_j + dq_j), so IPOPT sees a sparse,
exactly differentiated NLP; `nlpsol` is called once per problem shape and reused with new parameters
(start, goal, boxes, held-object spheres) every solve. One stage (its box and table rows and its cost, from
q_{j-1} and q_j) is an SX function mapped over the horizon: building that is ~0.1 s whatever the number of
boxes. `expand=True` turns the mapped graph into one SX graph before CasADi generates the derivatives:
~1.5 s to build with one box and ~2 s more per box, but evaluated about twice as fast, so the shapes a
planner expects are built expanded at its construction and a shape first met inside a step (another count
of perceived boxes or of held-object spheres) is built mapped. Both give the same NLP (solutions agree to
1e-10).

Decision variables, stage-major so a solution (and its multipliers) can be shifted by whole stages:
    x = [q_1, s_1, q_2, s_2, ..., q_N, s_N, s_down]
q_j (6) joint angles, s_j (1) table-clearance slack of stage j, s_down (1) terminal facing-down slack.

Constraints, stage-major as well (block j), with the step d_j = q_j - q_{j-1}:
    d_j                                    in [-step, step]           (6, linear)
    d_j - d_{j-1}                          in [-a dt^2, a dt^2]      (6, linear; d_0 = the last executed
                                                                       step; a: the request's acceleration
                                                                       limit, or none)
    d_j - 2 d_{j-1} + d_{j-2}              in [-J dt^3, J dt^3]      (6, linear; d_{-1} = the step before
                                                                       it; J: the request's jerk limit,
                                                                       or none)
    sphere-outside-box between consecutive check points a, b (q_{j-1}, `substeps - 1` points between,
    q_j; joint-linear), every box x every sphere:  d(a) + d(b) - |c(b) - c(a)| >= 2 r   (hard)
    z_sphere - r_sphere + s_j - z_table    >= clearance                (one per sphere, soft through s_j)
and after the last block the terminal facing-down row  -R_N[2, 2] + s_down >= cos(tol).

d(p) is the distance of a sphere centre p from an axis-aligned box (centre c, half extents h incl. the
margin): sqrt(sum_i max(|p_i - c_i| - h_i, 0)^2), the smooth-outside formulation of LIBRARY-NOTES (zero
gradient inside, so a solve must never start inside: the planner seeds the first solve over the box).
Why pairs rather than d(a) >= r at each point: at 0.15 rad per step the TCP moves up to ~15 cm per step,
and a sphere passing over a box edge between two check points dipped 2 cm below them. d is 1-Lipschitz,
so if the centre travels an arc of about |c(b) - c(a)| between a and b, every point on it is at least
(d(a) + d(b) - |c(b) - c(a)|) / 2 >= r from the box: the sphere stays out along the whole step, and the
robot slows down or passes higher only where it is close to the box.

Building an NLP costs more than a solve, so `cached_problem` keeps every NLP built in this process, keyed
by everything that changes its structure or its constants (shape, spheres, kinematics, weights, soft-row
bounds, IPOPT options, expanded or not): planner instances with the same parameters share them, and a
planner builds the shapes it expects at construction.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

# the NLP's rows and their numeric twins (`pair_clearance`, the loop's check) share the sphere model and its
# smoothing constants (why these values: `twin.planning.proxy_spheres`)
from twin.plugin import CHORD_EPS2 as _CHORD_EPS2
from twin.plugin import DISTANCE_EPS2 as _EPS2
from twin.plugin import TCP_FRAME, Weights

if TYPE_CHECKING:
    from twin.plugin import DHParameters

__all__ = [
    "NMPCProblem",
    "ProblemShape",
    "SolveOutput",
    "cached_problem",
    "fk_frames_sx",
    "fk_tcp_sx",
]

log = logging.getLogger("twin")

_PAIR_SCALE = 1.0 / 0.05  # sphere-box rows in units of 5 cm
N_FIXED_PARAMS = 25  # q0, last step, the step before, goal, tracked point, table z (see NMPCProblem)


def _exact(v: float) -> float:
    """cos/sin of the DH twist angles rounded to exact 0/+-1, so SX drops the zero terms."""
    for e in (-1.0, 0.0, 1.0):
        if abs(v - e) < 1e-12:
            return e
    return v


def fk_tcp_sx(q: ca.SX, tcp_offset_m: float, dh: DHParameters) -> tuple[ca.SX, ca.SX]:
    """Symbolic forward kinematics (standard DH parameters `dh`, `URArm.dh`): TCP position (3,) and rotation (3, 3)."""
    frames = fk_frames_sx(q, tcp_offset_m, dh)
    return frames[TCP_FRAME][:3, 3], frames[TCP_FRAME][:3, :3]


def fk_frames_sx(q: ca.SX, tcp_offset_m: float, dh: DHParameters) -> dict[int, ca.SX]:
    """Symbolic DH frames 2 to 6 (elbow, wrist_1, wrist_2, wrist_3 joints, flange) and the TCP (key TCP_FRAME),
    (4, 4) each in the base frame, for the standard DH parameters `dh` (`URArm.dh`)."""
    T = ca.SX.eye(4)
    out: dict[int, ca.SX] = {}
    d, a, alpha = (np.asarray(v, dtype=float) for v in (dh.d, dh.a, dh.alpha))
    for i in range(6):
        ct, st = ca.cos(q[i]), ca.sin(q[i])
        cal, sal = _exact(math.cos(alpha[i])), _exact(math.sin(alpha[i]))
        A = ca.SX.zeros(4, 4)
        A[0, 0], A[0, 1], A[0, 2], A[0, 3] = ct, -st * cal, st * sal, a[i] * ct
        A[1, 0], A[1, 1], A[1, 2], A[1, 3] = st, ct * cal, -ct * sal, a[i] * st
        A[2, 1], A[2, 2], A[2, 3] = sal, cal, d[i]
        A[3, 3] = 1.0
        T = ca.mtimes(T, A)
        if i + 1 >= 2:
            out[i + 1] = T
    tool = ca.SX.eye(4)
    tool[2, 3] = tcp_offset_m
    out[TCP_FRAME] = ca.mtimes(T, tool)
    return out


@dataclass(frozen=True)
class ProblemShape:
    """What fixes the NLP's structure: a new shape means a new `nlpsol` (cached by the planner)."""

    horizon: int
    n_boxes: int
    n_object_spheres: int
    substeps: int
    self_slots: int = 0  # self rows per stage (`twin.planning.selfrows`): a tool sphere from an arm sphere


@dataclass(frozen=True)
class SolveOutput:
    """One IPOPT solve: the knots q (N+1, 6) including the start, the raw primal/dual vectors and stats."""

    q: np.ndarray
    x: np.ndarray
    lam_x: np.ndarray
    lam_g: np.ndarray
    cost: float
    status: str
    converged: bool
    iterations: int
    solve_time_s: float
    warm: bool


# ---- the NLP's terms: each builds one named piece of the formulation (NMPCProblem reads as their list) ------
_SphereSX = tuple[int, "ca.DM | ca.SX", "float | ca.SX"]  # (frame, centre in that frame, radius)
_Points = list[tuple[ca.SX, "float | ca.SX"]]  # sphere centres (3,) and radii at one check point


@dataclass(frozen=True)
class _StageParameters:
    """The solve's parameters (`NMPCProblem`'s vector p) as a stage reads them: goal (3), tracked point in the
    TCP frame (3), table z, per box (centre, half extents) and per held-object sphere (TCP-frame offset, r)."""

    goal: ca.SX
    track: ca.SX
    table_z: ca.SX
    boxes: list[tuple[ca.SX, ca.SX]]
    objects: list[tuple[ca.SX, ca.SX]]


@dataclass(frozen=True)
class _Stage:
    """One stage as an SX function, (qa, qb, s, p, w, self slots) -> (box, table and self rows, cost residuals,
    R(qb) column-major), and how many rows of each kind it has (the NLP's row layout needs them)."""

    function: ca.Function
    n_box_rows: int
    n_table_rows: int
    n_self_rows: int


def _stage_parameters(ps: ca.SX, n_boxes: int, n_object: int) -> _StageParameters:
    """Slices of the parameter symbol `ps`: q0, the last two steps (18) come first and only the horizon reads them."""
    n0 = N_FIXED_PARAMS
    goal, track, table_z = ps[18:21], ps[21:24], ps[24]
    boxes = [(ps[n0 + 6 * b : n0 + 3 + 6 * b], ps[n0 + 3 + 6 * b : n0 + 6 + 6 * b]) for b in range(n_boxes)]
    o0 = n0 + 6 * n_boxes
    objects = [(ps[o0 + 4 * s : o0 + 4 * s + 3], ps[o0 + 4 * s + 3]) for s in range(n_object)]
    return _StageParameters(goal, track, table_z, boxes, objects)


def _sphere_model(robot_spheres: np.ndarray, objects: list[tuple[ca.SX, ca.SX]]) -> list[_SphereSX]:
    """The robot's spheres as constants, then the held object's as parameters on the TCP."""
    spheres: list[_SphereSX] = [(int(s[0]), ca.DM(s[1:4]), float(s[4])) for s in robot_spheres]
    spheres += [(TCP_FRAME, off, r) for off, r in objects]
    return spheres


def _check_points(
    spheres: list[_SphereSX],
    qa: ca.SX,
    dq: ca.SX,
    qb: ca.SX,
    *,
    substeps: int,
    self_frames: bool,
    dh: DHParameters,
    tcp_offset_m: float,
) -> tuple[list[_Points], dict[int, ca.SX]]:
    """The spheres at qa, at the `substeps - 1` joint-linear points between and at qb (what the box rows pair up),
    and the frames at qb (the table, self and cost terms read them). Frames 2 and 3 are placed for the self rows."""
    used = sorted({f for f, _, _ in spheres} | {TCP_FRAME} | ({2, 3} if self_frames else set()))
    qs = ca.SX.sym("q", 6)
    frames = fk_frames_sx(qs, tcp_offset_m, dh)
    fk = ca.Function("fk", [qs], [frames[f] for f in used])

    def at(q: ca.SX) -> tuple[_Points, dict[int, ca.SX]]:
        # `call` returns a list even for one output; `fk(q)` would return the bare matrix when `used`
        # is only the TCP frame (no wrist spheres), and a CasADi matrix is not iterable
        Fs = dict(zip(used, fk.call([q]), strict=True))
        return [(Fs[f][:3, 3] + ca.mtimes(Fs[f][:3, :3], off), r) for f, off, r in spheres], Fs

    seq = [at(qa)[0]]
    for sub in range(1, substeps + 1):
        pts, frames_b = at(qb if sub == substeps else qa + (sub / substeps) * dq)
        seq.append(pts)
    return seq, frames_b


def _box_distance(p: ca.SX, c: ca.SX, h: ca.SX) -> ca.SX:
    """Smooth-outside distance of a point from the box (centre c, half extents h); see the module docstring."""
    d = ca.fmax(ca.fabs(p - c) - h, 0)
    return ca.sqrt(ca.dot(d, d) + _EPS2)


def _box_rows(seq: list[_Points], boxes: list[tuple[ca.SX, ca.SX]]) -> list[ca.SX]:
    """Per box, sphere and pair of consecutive check points a, b: d(a) + d(b) - |c(b) - c(a)| - 2 r >= 0, in 5 cm."""
    rows: list[ca.SX] = []
    for c, h in boxes:
        dist = [[_box_distance(p, c, h) for p, _ in pts] for pts in seq]
        for s in range(len(seq[0])):
            r = seq[0][s][1]
            for a in range(len(seq) - 1):
                chord = ca.sqrt(ca.sumsqr(seq[a + 1][s][0] - seq[a][s][0]) + _CHORD_EPS2)
                rows.append((dist[a][s] + dist[a + 1][s] - chord - 2 * r) * _PAIR_SCALE)
    return rows


def _table_rows(points_b: _Points, slack: ca.SX, table_z: ca.SX) -> list[ca.SX]:
    """Per sphere at qb: its lowest point above the table, softened by the stage's slack (>= the clearance)."""
    return [p[2] - r + slack - table_z for p, r in points_b]


def _self_rows(frames_b: dict[int, ca.SX], pself: ca.SX, slots: int) -> list[ca.SX]:
    """Self rows at qb (`twin.planning.selfrows`): per slot a tool sphere (offset in the TCP frame: the gripper's or the
    held object's) and an arm sphere (offset in DH frame 2 if `sel` is 1, else in frame 3), their centres'
    distance in units of 5 cm; which pair a slot holds and its bound are set per solve."""
    rows: list[ca.SX] = []
    for k in range(slots):
        a_off, b_off, sel = pself[7 * k : 7 * k + 3], pself[7 * k + 3 : 7 * k + 6], pself[7 * k + 6]
        Ft, F2, F3 = frames_b[TCP_FRAME], frames_b[2], frames_b[3]
        pa = Ft[:3, 3] + ca.mtimes(Ft[:3, :3], a_off)
        p2 = F2[:3, 3] + ca.mtimes(F2[:3, :3], b_off)
        pb = sel * p2 + (1 - sel) * (F3[:3, 3] + ca.mtimes(F3[:3, :3], b_off))
        rows.append(ca.sqrt(ca.sumsqr(pa - pb) + _EPS2) * _PAIR_SCALE)
    return rows


def _stage_residuals(
    tcp_b: ca.SX, dq: ca.SX, slack: ca.SX, wpos: ca.SX, par: _StageParameters, weights: Weights
) -> ca.SX:
    """The stage's cost as residuals: the cost is sum(res^2), whose Gauss-Newton Hessian 2 J_res^T J_res is cheap
    and positive. Tracking (the tracked point's error from the goal, weight `wpos`), joint step, table slack."""
    e = tcp_b[:3, 3] + ca.mtimes(tcp_b[:3, :3], par.track) - par.goal
    return ca.vertcat(ca.sqrt(wpos) * e, math.sqrt(weights.step) * dq, math.sqrt(weights.table_slack) * slack)


def _stage(
    shape: ProblemShape,
    robot_spheres: np.ndarray,
    *,
    n_params: int,
    dh: DHParameters,
    tcp_offset_m: float,
    weights: Weights,
) -> _Stage:
    """One stage, from q_{j-1} (qa) to q_j (qb), as an SX function: built once, mapped over the horizon (~N times
    cheaper to build and differentiate than the whole horizon in SX; the NLP is the same row for row)."""
    qa, qb, sb = ca.SX.sym("qa", 6), ca.SX.sym("qb", 6), ca.SX.sym("s")
    ps = ca.SX.sym("ps", n_params)  # the solve's parameters, the same for every stage
    wpos = ca.SX.sym("wpos")  # position weight of the stage (the terminal one is heavier)
    par = _stage_parameters(ps, shape.n_boxes, shape.n_object_spheres)
    spheres = _sphere_model(robot_spheres, par.objects)
    dq = qb - qa
    seq, frames_b = _check_points(
        spheres,
        qa,
        dq,
        qb,
        substeps=shape.substeps,
        self_frames=bool(shape.self_slots),
        dh=dh,
        tcp_offset_m=tcp_offset_m,
    )
    box = _box_rows(seq, par.boxes)
    table = _table_rows(seq[-1], sb, par.table_z)
    pself = ca.SX.sym("pself", 7 * shape.self_slots)
    self_ = _self_rows(frames_b, pself, shape.self_slots)
    res = _stage_residuals(frames_b[TCP_FRAME], dq, sb, wpos, par, weights)
    R = ca.reshape(frames_b[TCP_FRAME][:3, :3], 9, 1)
    function = ca.Function("nmpc_stage", [qa, qb, sb, ps, wpos, pself], [ca.vertcat(*box, *table, *self_), res, R])
    return _Stage(function, len(box), len(table), len(self_))


def _knots(x: ca.MX, q0: ca.MX, horizon: int, block_x: int) -> tuple[ca.MX, ca.MX, ca.MX]:
    """The decision vector's knots q_1..q_N (6, N), table slacks (1, N) and each stage's start q_0..q_{N-1} (6, N)."""
    body = ca.reshape(x[: horizon * block_x], block_x, horizon)  # column j = stage j's block
    Q = body[0:6, :]
    S = body[6, :]
    QA = ca.horzcat(q0, Q[:, : horizon - 1]) if horizon > 1 else q0
    return Q, S, QA


def _position_weights(weights: Weights, horizon: int) -> ca.DM:
    """(1, N) the tracking weight of each stage: the last one `terminal_factor` times heavier (the terminal cost)."""
    wvec = np.full(horizon, weights.position)
    wvec[-1] *= weights.terminal_factor
    return ca.DM(wvec).T


_Rows = tuple[list[ca.MX], list[np.ndarray], list[np.ndarray]]  # g, lbg, ubg


def _motion_rows(d: ca.MX, d_prev: ca.MX, d_prev2: ca.MX) -> list[ca.MX]:
    """The step d_j (bounded by the step bound), its change (acceleration x dt^2) and the change of that (jerk x
    dt^3), from the two steps before."""
    return [d, d - d_prev, d - 2 * d_prev + d_prev2]


def _stage_blocks(
    Q: ca.MX, QA: ca.MX, dq_prev: ca.MX, dq_prev2: ca.MX, stage_rows: ca.MX, stage_lb: np.ndarray
) -> _Rows:
    """Block j of the constraints: the step d_j, its change and the change of that (bounds set per solve: step,
    acceleration and jerk rows), then the stage's box, table and self rows (lower bounds `stage_lb`)."""
    g: list[ca.MX] = []
    lbg: list[np.ndarray] = []
    ubg: list[np.ndarray] = []
    d_prev, d_prev2 = dq_prev, dq_prev2
    for j in range(Q.shape[1]):
        d = Q[:, j] - QA[:, j]
        g += [*_motion_rows(d, d_prev, d_prev2), stage_rows[:, j]]
        lbg.append(np.full(18, -np.inf))  # step, step-change and jerk bounds are set per solve
        ubg.append(np.full(18, np.inf))
        lbg.append(stage_lb.copy())
        ubg.append(np.full(stage_lb.size, np.inf))
        d_prev, d_prev2 = d, d_prev
    return g, lbg, ubg


def _stage_lower_bounds(stage: _Stage, table_clearance_m: float) -> np.ndarray:
    """Box rows >= 0, table rows >= the clearance, self rows open (their bounds are set per solve)."""
    return np.concatenate(
        [
            np.zeros(stage.n_box_rows),
            np.full(stage.n_table_rows, table_clearance_m),
            np.full(stage.n_self_rows, -np.inf),
        ]
    )


def _joined(*terms: _Rows) -> _Rows:
    """Rows of several terms, in the order given."""
    g: list[ca.MX] = []
    lbg: list[np.ndarray] = []
    ubg: list[np.ndarray] = []
    for tg, tl, tu in terms:
        g += tg
        lbg += tl
        ubg += tu
    return g, lbg, ubg


def _facing_down_row(stage_R: ca.MX, s_down: ca.MX, facing_down_cos: float) -> _Rows:
    """The terminal row -R_N[2, 2] + s_down >= cos(tol) (column-major reshape: element 8 is (2, 2))."""
    return [-stage_R[8, stage_R.shape[1] - 1] + s_down], [np.full(1, facing_down_cos)], [np.full(1, np.inf)]


def _cost(stage_res: ca.MX, s_down: ca.MX, weights: Weights) -> ca.MX:
    """Sum of squares of every stage's residuals and the facing-down slack's."""
    return ca.sumsqr(ca.vertcat(ca.vec(stage_res), math.sqrt(weights.facing_down_slack) * s_down))


def _solvers(
    nlp: dict[str, ca.MX], *, expand: bool, cold_options: dict[str, Any], warm_options: dict[str, Any]
) -> tuple[ca.Function, ca.Function]:
    """The cold and the warm-started IPOPT of the NLP. expand: the horizon's graph turned into one SX graph, whose
    derivatives CasADi then generates (~1.5 s with one box, ~2 s more per box) and evaluates ~2x faster than the
    mapped stage calls (~0.1 s to build)."""
    quiet: dict[str, Any] = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "expand": expand}
    cold = ca.nlpsol("nmpc_cold", "ipopt", nlp, dict(quiet, **cold_options))
    warm = ca.nlpsol("nmpc_warm", "ipopt", nlp, dict(quiet, **warm_options))
    return cold, warm


class NMPCProblem:
    """The NLP for one `ProblemShape`, with a cold and a warm-started IPOPT instance built once
    (`cold_options`, `warm_options`: nlpsol options, e.g. {"ipopt.tol": 1e-2}).

    `robot_spheres` (n, 5): (frame, x, y, z, r) with frame a DH frame index (4, 5, 6) or TCP_FRAME; `dh` and
    `tcp_offset_m` the arm's kinematics (`URArm.dh`, `URArm.tcp_offset_m`).
    Parameters of a solve (vector `p`): q0 (6), the last executed step q0 - q_{-1} (6), the step before it
    q_{-1} - q_{-2} (6), goal (3), tracked point in the TCP frame (3), table z (1),
    then per box centre (3) and half extents incl. margin (3), then per held-object sphere offset in the TCP
    frame (3) and radius (1).
    """

    def __init__(
        self,
        shape: ProblemShape,
        *,
        robot_spheres: np.ndarray,
        dh: DHParameters,
        tcp_offset_m: float,
        weights: Weights,
        table_clearance_m: float,
        facing_down_cos: float,
        cold_options: dict[str, Any],
        warm_options: dict[str, Any],
        expand: bool = True,
    ):
        t0 = time.perf_counter()
        self.expanded = bool(expand)
        self.shape = shape
        N = shape.horizon
        self.robot_spheres = np.asarray(robot_spheres, dtype=float).reshape(-1, 5)
        self.n_spheres = self.robot_spheres.shape[0] + shape.n_object_spheres
        self.block_x = 7
        self.nx = N * self.block_x + 1
        self.n_self = shape.self_slots
        self.n_params = N_FIXED_PARAMS + 6 * shape.n_boxes + 4 * shape.n_object_spheres
        self.n_self_params = 7 * self.n_self * N  # after the fixed, box and object parameters, stage-major

        stage = _stage(
            shape, self.robot_spheres, n_params=self.n_params, dh=dh, tcp_offset_m=tcp_offset_m, weights=weights
        )
        self.stage_function = stage.function  # kept for other forms of the same problem (bench/nmpc_alternatives.py)

        # ---- the NLP over the horizon: the stage mapped over it, its rows stage-major --------------------------
        x = ca.MX.sym("x", self.nx)
        p = ca.MX.sym("p", self.n_params + self.n_self_params)
        q0, dq_prev, dq_prev2, s_down = p[0:6], p[6:12], p[12:18], x[-1]
        Q, S, QA = _knots(x, q0, N, self.block_x)
        stage_rows, stage_res, stage_R = stage.function.map(N, "serial")(
            QA,
            Q,
            S,
            ca.repmat(p[: self.n_params], 1, N),
            _position_weights(weights, N),
            ca.reshape(p[self.n_params :], 7 * self.n_self, N),
        )
        g, lbg, ubg = _joined(
            _stage_blocks(Q, QA, dq_prev, dq_prev2, stage_rows, _stage_lower_bounds(stage, table_clearance_m)),
            _facing_down_row(stage_R, s_down, facing_down_cos),
        )
        J = _cost(stage_res, s_down, weights)

        self._index_rows(lbg, ubg, stage)
        nlp = {"x": x, "p": p, "f": J, "g": ca.vertcat(*g)}
        self._cold, self._warm = _solvers(nlp, expand=expand, cold_options=cold_options, warm_options=warm_options)
        self.build_time_s = time.perf_counter() - t0
        log.debug("nmpc: built NLP %s (%d vars, %d constraints) in %.2f s", shape, self.nx, self.ng, self.build_time_s)

    def _index_rows(self, lbg: list[np.ndarray], ubg: list[np.ndarray], stage: _Stage) -> None:
        """Where the rows of each kind sit in g (N blocks of `block_g`, then the facing-down row), for `bounds`."""
        N = self.shape.horizon
        self.block_g = sum(int(a.size) for a in lbg[:-1]) // N
        self.ng = sum(int(a.size) for a in lbg)
        self.lbg = np.concatenate(lbg)
        self.ubg = np.concatenate(ubg)
        self._box_rows_per_box = stage.n_table_rows * self.shape.substeps  # one per sphere and sub-step
        self._stage_rows_dq = np.concatenate([np.arange(6) + j * self.block_g for j in range(N)])
        self._stage_rows_ddq = self._stage_rows_dq + 6
        self._stage_rows_dddq = self._stage_rows_dq + 12
        first_self = 18 + stage.n_box_rows + stage.n_table_rows
        self._self_rows = (
            np.arange(N)[:, None] * self.block_g + first_self + np.arange(stage.n_self_rows)[None]
        ).astype(int)

    # ---- layout helpers ---------------------------------------------------------------------------
    def pack_x(self, q_knots: np.ndarray, slack: np.ndarray | None = None, s_down: float = 0.0) -> np.ndarray:
        """Decision vector from knots q_1..q_N (N, 6) and optional stage slacks (N,)."""
        N = self.shape.horizon
        x = np.zeros(self.nx)
        blocks = x[:-1].reshape(N, self.block_x)
        blocks[:, :6] = q_knots
        if slack is not None:
            blocks[:, 6] = slack
        x[-1] = s_down
        return x

    def box_rows(self, slots: list[int]) -> np.ndarray:
        """Indices into g of the rows of box slots `slots`, every stage."""
        per, N = self._box_rows_per_box, self.shape.horizon
        within = np.concatenate([18 + b * per + np.arange(per) for b in slots]) if slots else np.zeros(0, int)
        return (np.arange(N)[:, None] * self.block_g + within[None, :]).reshape(-1).astype(int)

    def self_rows(self) -> np.ndarray:
        """Indices into g of the self rows, (N, self_slots)."""
        return self._self_rows

    def with_knots(self, x: np.ndarray, q_knots: np.ndarray) -> np.ndarray:
        """The decision vector `x` with the knots q_1..q_N (N, 6) `q_knots` (its slacks as they are)."""
        out = np.array(x, dtype=float)
        out[:-1].reshape(self.shape.horizon, self.block_x)[:, :6] = q_knots
        return out

    def knots(self, x: np.ndarray) -> np.ndarray:
        """(N, 6) q_1..q_N of a decision vector."""
        return np.asarray(x[:-1]).reshape(self.shape.horizon, self.block_x)[:, :6].copy()

    def shift(self, v: np.ndarray, block: int, k: int) -> np.ndarray:
        """Stage-major vector `v` (N blocks of `block` + tail) shifted k stages earlier; the last stage repeats."""
        N = self.shape.horizon
        body = np.asarray(v[: N * block]).reshape(N, block)
        k = min(k, N - 1)
        out = np.concatenate([body[k:], np.repeat(body[-1:], k, axis=0)]).reshape(-1)
        return np.concatenate([out, np.asarray(v[N * block :])])

    def bounds(
        self,
        q_lo: np.ndarray,
        q_hi: np.ndarray,
        step: np.ndarray,
        step_change: np.ndarray | None = None,
        jerk_change: np.ndarray | None = None,
        *,
        facing_down: bool = True,
        self_lo: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """lbx, ubx (joint limits, slacks >= 0) and lbg, ubg for a solve: per-joint bounds on the step, on
        its change from one step to the next (acceleration x dt^2) and on the change of that change (jerk x
        dt^3) (None: unbounded); the terminal facing-down row switched off when `facing_down` is False; `self_lo`
        (N, self_slots): the lower bound, m, on the centres' distance of each stage's self row (-inf: open)."""
        N = self.shape.horizon
        lbx = np.zeros(self.nx)
        ubx = np.full(self.nx, np.inf)
        bl = lbx[:-1].reshape(N, self.block_x)
        bu = ubx[:-1].reshape(N, self.block_x)
        bl[:, :6] = q_lo
        bu[:, :6] = q_hi
        lbg, ubg = self.lbg.copy(), self.ubg.copy()
        lbg[self._stage_rows_dq] = np.tile(-step, N)
        ubg[self._stage_rows_dq] = np.tile(step, N)
        if step_change is not None:
            lbg[self._stage_rows_ddq] = np.tile(-step_change, N)
            ubg[self._stage_rows_ddq] = np.tile(step_change, N)
        if jerk_change is not None:
            lbg[self._stage_rows_dddq] = np.tile(-jerk_change, N)
            ubg[self._stage_rows_dddq] = np.tile(jerk_change, N)
        if not facing_down:
            lbg[-1] = -np.inf
        if self_lo is not None and self.n_self:
            lbg[self._self_rows] = np.asarray(self_lo, dtype=float) * _PAIR_SCALE
        return lbx, ubx, lbg, ubg

    # ---- solving ----------------------------------------------------------------------------------
    def solve(
        self,
        x0: np.ndarray,
        p: np.ndarray,
        bounds: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        *,
        lam_x0: np.ndarray | None = None,
        lam_g0: np.ndarray | None = None,
    ) -> SolveOutput:
        """Solve from primal guess x0; with multipliers given, the warm-started IPOPT is used."""
        lbx, ubx, lbg, ubg = bounds
        warm = lam_x0 is not None and lam_g0 is not None
        solver = self._warm if warm else self._cold
        args = {"x0": np.clip(x0, lbx, ubx), "p": p, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
        if warm:
            args["lam_x0"] = lam_x0
            args["lam_g0"] = lam_g0
        t0 = time.perf_counter()
        sol = solver(**args)
        dt = time.perf_counter() - t0
        stats = solver.stats()
        status = str(stats.get("return_status", "unknown"))
        converged = status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
        x = np.asarray(sol["x"]).reshape(-1)
        q = np.vstack([p[None, 0:6], self.knots(x)])
        return SolveOutput(
            q=q,
            x=x,
            lam_x=np.asarray(sol["lam_x"]).reshape(-1),
            lam_g=np.asarray(sol["lam_g"]).reshape(-1),
            cost=float(sol["f"]),
            status=status,
            converged=converged,
            iterations=int(stats.get("iter_count", -1)),
            solve_time_s=dt,
            warm=warm,
        )


# ---- the process-wide cache of built NLPs -------------------------------------------------------------
_CACHE: dict[tuple[Any, ...], NMPCProblem] = {}
_CACHE_LOCK = threading.Lock()


def _frozen(options: dict[str, Any]) -> tuple[tuple[str, Any], ...]:
    return tuple(sorted(options.items()))


def cached_problem(
    shape: ProblemShape,
    *,
    robot_spheres: np.ndarray,
    dh: DHParameters,
    tcp_offset_m: float,
    weights: Weights,
    table_clearance_m: float,
    facing_down_cos: float,
    cold_options: dict[str, Any],
    warm_options: dict[str, Any],
    expand: bool = True,
) -> NMPCProblem:
    """The NLP for these arguments (`NMPCProblem`'s), built on first request in this process and shared after.

    Two planners with the same parameters get the same NLP object: a solve changes nothing in it but
    IPOPT's statistics, which `NMPCProblem.solve` reads right after its call (planners in one process
    solve one at a time; the comparison runner uses processes). Building holds a lock, so one shape is
    built once even when threads ask for it together."""
    sph = np.asarray(robot_spheres, dtype=float).reshape(-1, 5)
    key = (
        shape,
        sph.tobytes(),
        tuple(tuple(float(v) for v in np.asarray(a, dtype=float)) for a in (dh.d, dh.a, dh.alpha)),
        float(tcp_offset_m),
        weights,
        float(table_clearance_m),
        float(facing_down_cos),
        _frozen(cold_options),
        _frozen(warm_options),
        bool(expand),
    )
    with _CACHE_LOCK:
        prob = _CACHE.get(key)
        if prob is None:
            prob = NMPCProblem(
                shape,
                robot_spheres=sph,
                dh=dh,
                tcp_offset_m=tcp_offset_m,
                weights=weights,
                table_clearance_m=table_clearance_m,
                facing_down_cos=facing_down_cos,
                cold_options=cold_options,
                warm_options=warm_options,
                expand=expand,
            )
            _CACHE[key] = prob
    return prob
