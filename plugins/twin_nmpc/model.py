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
    """Symbolic forward kinematics (standard DH parameters `dh`, `UR5e.dh`): TCP position (3,) and rotation (3, 3)."""
    frames = fk_frames_sx(q, tcp_offset_m, dh)
    return frames[TCP_FRAME][:3, 3], frames[TCP_FRAME][:3, :3]


def fk_frames_sx(q: ca.SX, tcp_offset_m: float, dh: DHParameters) -> dict[int, ca.SX]:
    """Symbolic DH frames 2 to 6 (elbow, wrist_1, wrist_2, wrist_3 joints, flange) and the TCP (key TCP_FRAME),
    (4, 4) each in the base frame, for the standard DH parameters `dh` (`UR5e.dh`)."""
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


class NMPCProblem:
    """The NLP for one `ProblemShape`, with a cold and a warm-started IPOPT instance built once
    (`cold_options`, `warm_options`: nlpsol options, e.g. {"ipopt.tol": 1e-2}).

    `robot_spheres` (n, 5): (frame, x, y, z, r) with frame a DH frame index (4, 5, 6) or TCP_FRAME; `dh` and
    `tcp_offset_m` the arm's kinematics (`UR5e.dh`, `UR5e.tcp_offset_m`).
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
        N, nb, no, ns_sub = shape.horizon, shape.n_boxes, shape.n_object_spheres, shape.substeps
        self.robot_spheres = np.asarray(robot_spheres, dtype=float).reshape(-1, 5)
        nt = self.robot_spheres.shape[0]
        self.n_spheres = nt + no
        self.block_x = 7
        self.nx = N * self.block_x + 1
        n0 = N_FIXED_PARAMS
        self.n_self = shape.self_slots
        self.n_params = n0 + 6 * nb + 4 * no

        # ---- one stage as an SX function, mapped over the horizon (built once: ~N times cheaper to build and
        # differentiate than the whole horizon in SX; the NLP is the same row for row) ------------------------
        qa, qb, sb = ca.SX.sym("qa", 6), ca.SX.sym("qb", 6), ca.SX.sym("s")
        ps = ca.SX.sym("ps", self.n_params)  # the solve's parameters, the same for every stage
        wpos = ca.SX.sym("wpos")  # position weight of the stage (the terminal one is heavier)
        goal, track, table_z = ps[18:21], ps[21:24], ps[24]
        boxes = [(ps[n0 + 6 * b : n0 + 3 + 6 * b], ps[n0 + 3 + 6 * b : n0 + 6 + 6 * b]) for b in range(nb)]
        o0 = n0 + 6 * nb
        obj = [(ps[o0 + 4 * s : o0 + 4 * s + 3], ps[o0 + 4 * s + 3]) for s in range(no)]
        # (frame, centre in that frame, radius): the robot's are constants, the held object's parameters
        spheres_local: list[tuple[int, ca.DM | ca.SX, float | ca.SX]] = [
            (int(s[0]), ca.DM(s[1:4]), float(s[4])) for s in self.robot_spheres
        ]
        spheres_local += [(TCP_FRAME, off, r) for off, r in obj]
        used = sorted({f for f, _, _ in spheres_local} | {TCP_FRAME} | ({2, 3} if self.n_self else set()))

        qs = ca.SX.sym("q", 6)
        frames = fk_frames_sx(qs, tcp_offset_m, dh)
        fk = ca.Function("fk", [qs], [frames[f] for f in used])

        last_frames: dict[int, ca.SX] = {}

        def sphere_points(q: ca.SX) -> tuple[list[tuple[ca.SX, float | ca.SX]], ca.SX, ca.SX]:
            # `call` returns a list even for one output; `fk(q)` would return the bare matrix when `used`
            # is only the TCP frame (no wrist spheres), and a CasADi matrix is not iterable
            Fs = dict(zip(used, fk.call([q]), strict=True))
            last_frames.clear()
            last_frames.update(Fs)
            pts = [(Fs[f][:3, 3] + ca.mtimes(Fs[f][:3, :3], off), r) for f, off, r in spheres_local]
            T = Fs[TCP_FRAME]
            return pts, T[:3, 3], T[:3, :3]

        def box_distance(p_: ca.SX, c: ca.SX, h: ca.SX) -> ca.SX:
            d = ca.fmax(ca.fabs(p_ - c) - h, 0)
            return ca.sqrt(ca.dot(d, d) + _EPS2)

        dq = qb - qa
        seq = [sphere_points(qa)[0]]
        for sub in range(1, ns_sub + 1):
            qm = qb if sub == ns_sub else qa + (sub / ns_sub) * dq
            pts, pj, Rj = sphere_points(qm)
            seq.append(pts)
        rows: list[ca.SX] = []
        for c, h in boxes:
            dist = [[box_distance(p_, c, h) for p_, _ in pts] for pts in seq]
            for s in range(len(spheres_local)):
                r = seq[0][s][1]
                for a in range(ns_sub):
                    chord = ca.sqrt(ca.sumsqr(seq[a + 1][s][0] - seq[a][s][0]) + _CHORD_EPS2)
                    rows.append((dist[a][s] + dist[a + 1][s] - chord - 2 * r) * _PAIR_SCALE)
        n_box_rows = len(rows)
        for p_, r in seq[-1]:
            rows.append(p_[2] - r + sb - table_z)
        # self rows at q_j (`twin_nmpc.selfrows`): per slot a tool sphere (offset in the TCP frame: the gripper's
        # or the held object's) and an arm sphere (offset in DH frame 2 if `sel` is 1, else in frame 3), their
        # centres' distance in units of 5 cm; which pair a slot holds and its bound are set per solve
        pself = ca.SX.sym("pself", 7 * self.n_self)
        for k in range(self.n_self):
            a_off, b_off, sel = pself[7 * k : 7 * k + 3], pself[7 * k + 3 : 7 * k + 6], pself[7 * k + 6]
            Ft, F2, F3 = last_frames[TCP_FRAME], last_frames[2], last_frames[3]
            pa = Ft[:3, 3] + ca.mtimes(Ft[:3, :3], a_off)
            p2 = F2[:3, 3] + ca.mtimes(F2[:3, :3], b_off)
            pb = sel * p2 + (1 - sel) * (F3[:3, 3] + ca.mtimes(F3[:3, :3], b_off))
            rows.append(ca.sqrt(ca.sumsqr(pa - pb) + _EPS2) * _PAIR_SCALE)
        e = pj + ca.mtimes(Rj, track) - goal
        # the cost is a sum of squares, sum(res^2): its Gauss-Newton Hessian 2 J_res^T J_res is cheap and positive
        res = ca.vertcat(ca.sqrt(wpos) * e, math.sqrt(weights.step) * dq, math.sqrt(weights.table_slack) * sb)
        stage = ca.Function("nmpc_stage", [qa, qb, sb, ps, wpos, pself], [ca.vertcat(*rows), res, ca.reshape(Rj, 9, 1)])
        # (qa, qb, s, p, w, self slots) -> (box, table and self rows, cost residuals, R(qb) column-major): kept for
        # other forms of the same problem (bench/nmpc_alternatives.py)
        self.stage_function = stage
        mapped = stage.map(N, "serial")

        # ---- the NLP over the horizon, stage-major as before --------------------------------------
        x = ca.MX.sym("x", self.nx)
        self.n_self_params = 7 * self.n_self * N  # after the fixed, box and object parameters, stage-major
        p = ca.MX.sym("p", self.n_params + self.n_self_params)
        q0, dq_prev, dq_prev2 = p[0:6], p[6:12], p[12:18]
        body = ca.reshape(x[: N * self.block_x], self.block_x, N)  # column j = stage j's block
        Q = body[0:6, :]
        S = body[6, :]
        QA = ca.horzcat(q0, Q[:, : N - 1]) if N > 1 else q0
        wvec = np.full(N, weights.position)
        wvec[-1] *= weights.terminal_factor
        PS = ca.reshape(p[self.n_params :], 7 * self.n_self, N)
        stage_rows, stage_res, stage_R = mapped(QA, Q, S, ca.repmat(p[: self.n_params], 1, N), ca.DM(wvec).T, PS)
        g: list[ca.MX] = []
        lbg: list[np.ndarray] = []
        ubg: list[np.ndarray] = []
        d_prev, d_prev2 = dq_prev, dq_prev2
        for j in range(N):
            d = Q[:, j] - QA[:, j]
            g += [d, d - d_prev, d - 2 * d_prev + d_prev2, stage_rows[:, j]]
            lbg.append(np.full(18, -np.inf))  # step, step-change and jerk bounds are set per solve
            ubg.append(np.full(18, np.inf))
            lbg.append(
                np.concatenate(
                    [
                        np.zeros(n_box_rows),
                        np.full(len(spheres_local), table_clearance_m),
                        np.full(self.n_self, -np.inf),
                    ]
                )
            )
            ubg.append(np.full(n_box_rows + len(spheres_local) + self.n_self, np.inf))
            d_prev, d_prev2 = d, d_prev
        s_down = x[-1]
        g.append(-stage_R[8, N - 1] + s_down)  # -R_N[2, 2] (column-major reshape: element 8 is (2, 2))
        lbg.append(np.full(1, facing_down_cos))
        ubg.append(np.full(1, np.inf))
        residuals = ca.vertcat(ca.vec(stage_res), math.sqrt(weights.facing_down_slack) * s_down)
        J = ca.sumsqr(residuals)

        self.block_g = sum(int(a.size) for a in lbg[:-1]) // N
        self.ng = sum(int(a.size) for a in lbg)
        self.lbg = np.concatenate(lbg)
        self.ubg = np.concatenate(ubg)
        self._box_rows_per_box = len(spheres_local) * ns_sub
        self._stage_rows_dq = np.concatenate([np.arange(6) + j * self.block_g for j in range(N)])
        self._stage_rows_ddq = self._stage_rows_dq + 6
        self._stage_rows_dddq = self._stage_rows_dq + 12
        first_self = 18 + n_box_rows + len(spheres_local)
        self._self_rows = (np.arange(N)[:, None] * self.block_g + first_self + np.arange(self.n_self)[None]).astype(int)
        nlp = {"x": x, "p": p, "f": J, "g": ca.vertcat(*g)}
        # expand: the horizon's graph turned into one SX graph, whose derivatives CasADi then generates (~1.5 s
        # with one box, ~2 s more per box) and evaluates ~2x faster than the mapped stage calls (~0.1 s to build)
        quiet: dict[str, Any] = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "expand": expand}
        self._cold = ca.nlpsol("nmpc_cold", "ipopt", nlp, dict(quiet, **cold_options))
        self._warm = ca.nlpsol("nmpc_warm", "ipopt", nlp, dict(quiet, **warm_options))
        self.build_time_s = time.perf_counter() - t0
        log.debug("nmpc: built NLP %s (%d vars, %d constraints) in %.2f s", shape, self.nx, self.ng, self.build_time_s)

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
