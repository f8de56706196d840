"""`nmpc`: the warehouse system's (seeds 000/001) receding-horizon NMPC as a planner plugin.

Per solve: from the measured joint state, the latest obstacle boxes of the planning scene and the held
object, optimise N = 30 joint steps (dt 0.08 s; seed 001: 0.1 s) under per-step increments of +-0.15 rad,
proxy spheres around the gripper (and around the held box) outside every obstacle box at every step and
between steps (hard), table clearance (soft, slack) and a terminal facing-down tool (soft, slack); cost:
TCP position error, terminal weight x10, a lighter joint-step penalty. Execute the first k steps (seed 000:
k = 1; seed 001: k = 3), replan. Stop within 3 cm of the goal (SUCCESS) or after 40 solves (NO_SOLUTION).
Beyond the seed (each can be switched off): the step may change by at most the request's joint
acceleration limit x dt^2 per step, and two spheres guard the wrist links.

Why these choices:
* The NLP is built once per problem shape (number of boxes, number of held-object spheres) and kept;
  each solve only changes parameters and is warm-started from the previous solution shifted by the
  executed steps, primal and dual (see `twin_nmpc.model`).
* The perceived box is extended over the whole workspace in y, so the only way is over it, and a straight
  initial guess through the box starts IPOPT where the box distance has zero gradient. The first solve is
  therefore seeded over the box: lift, transfer, lower, through IK waypoints (measured on the bench
  scenes: ~35 IPOPT iterations from this guess, ~180 from the straight one, which only the chord terms of
  the pairwise box rows pull out of the box at all).
* A solve that fails, or whose steps do not pass an independent numpy check of the hard constraints, is
  never executed: the remaining steps of the last feasible plan are (after the same check; when the very
  first solve of a goal fails, its checked initial guess is that plan), else the planner stops with a
  typed failure and a reason. The solve after a failure starts cold, from a fresh guess.
* NMPC tracks a position and stops within a tolerance of it (`goal_tolerance_m`, or the goal's own
  `position_tolerance_m` when that is tighter); it does not track an orientation (only a soft terminal
  facing-down term) and it does not reach joint goals. So it declares `goal_kinds = {"position"}`: a
  config that asks it for joint or oriented pose goals fails before anything runs, and `twin.planning`
  judges its end like every planner's, against the goal's tolerances.
* Segments that follow an earlier plan or the initial guess after a failed solve are marked
  `Segment.fallback`; the checked loop FCL-checks and counts them like any other segment.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from twin.errors import PlanningError
from twin.planning import Segment
from twin.types import JointGoal, MotionRequest, MotionResult, PoseGoal, Status, Trajectory, as_q
from twin_nmpc.model import (
    TCP_FRAME,
    NMPCProblem,
    ProblemShape,
    SolveOutput,
    Weights,
    pair_clearance,
    sphere_box_clearance,
    sphere_centres,
)

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.kinematics import UR5e
    from twin.registry import PluginContext

__all__ = ["NMPCPlanner", "NMPCParams", "DEFAULT_TOOL_SPHERES", "DEFAULT_WRIST_SPHERES", "object_spheres", "robot_spheres"]

log = logging.getLogger("twin")

# (x, y, z, radius) in the TCP frame (z along the tool, pointing out of the gripper; the flange is at
# z = -0.135): fingertips/held object, fingers, the two halves of the 0.14 x 0.06 x 0.07 m gripper body,
# flange + wrist_3. With the default 1 cm box margin every sphere covers its part of the URDF collision
# geometry (a half gripper body needs 0.058 m), so the FCL check of the whole arm passes too.
DEFAULT_TOOL_SPHERES: tuple[tuple[float, float, float, float], ...] = (
    (0.0, 0.0, 0.0, 0.05),
    (0.0, 0.0, -0.06, 0.05),
    (0.035, 0.0, -0.088, 0.05),
    (-0.035, 0.0, -0.088, 0.05),
    (0.0, 0.0, -0.15, 0.05),
)
# (DH frame, x, y, z, radius): one sphere on each of the wrist_1 (frame 4) and wrist_2 (frame 5) link
# housings; with the box margin they cover the r 0.045 m x 0.13 / 0.11 m cylinders (0.079 / 0.071 m
# needed). Not in the seed (it models the end effector only), but without them the wrist, tilted on the
# way, clipped the perceived box while the gripper spheres stayed clear; `wrist_spheres: []` is the seed's
# model. They sit 0.2 m or more above the TCP of a tool facing down, so their size costs little room.
DEFAULT_WRIST_SPHERES: tuple[tuple[int, float, float, float, float], ...] = (
    (4, 0.0, -0.02, 0.0, 0.07),
    (5, 0.0, 0.005, 0.0, 0.062),
)

_CHECK_TOL_M = 5e-4  # the numpy re-check of the hard constraints accepts this much below the margin


class NMPCParams(BaseModel):
    """Parameters of `nmpc` (defaults: SPEC, seed 000; seed 001 is dt=0.1, execute_steps=3)."""

    model_config = ConfigDict(extra="forbid")

    horizon: int = Field(30, ge=2, le=200, description="steps per solve")
    dt: float = Field(0.08, gt=0, le=1.0, description="s per step (seed 001: 0.1)")
    execute_steps: int = Field(1, ge=1, description="steps executed per solve (seed 001: 3)")
    max_step_rad: float = Field(0.15, gt=0, le=1.0, description="per-step joint increment bound")
    limit_acceleration: bool = Field(
        True,
        description="bound the change of the step by the request's max_joint_acc * dt^2 (not in the seed, which"
        " jumps to full speed in one step; the simulated grasp shook the cube loose that way)",
    )
    goal_tolerance_m: float = Field(0.03, gt=0, description="stop when the TCP is this close to the goal (or the goal's tighter tolerance)")
    max_solves: int = Field(40, ge=1, description="give up after this many solves")
    tool_spheres: list[tuple[float, float, float, float]] = Field(
        default_factory=lambda: [tuple(s) for s in DEFAULT_TOOL_SPHERES],
        description="proxy spheres (x, y, z, r) in the TCP frame",
        min_length=1,
    )
    wrist_spheres: list[tuple[int, float, float, float, float]] = Field(
        default_factory=lambda: [tuple(s) for s in DEFAULT_WRIST_SPHERES],
        description="proxy spheres (DH frame 4..6, x, y, z, r) on the wrist",
    )
    object_sphere_min_radius_m: float = Field(0.03, gt=0)
    object_sphere_max_radius_m: float = Field(0.05, gt=0)
    max_object_spheres: int = Field(4, ge=1, le=16)
    box_margin_m: float = Field(0.01, ge=0, le=0.1, description="boxes are grown by this on every side")
    constraint_substeps: int = Field(2, ge=1, le=8, description="box constraint points per step (1 = knots only)")
    table_z_m: float = Field(0.0, description="table top height")
    table_clearance_m: float = Field(0.0, ge=0, description="sphere bottoms above the table (soft)")
    facing_down: bool = Field(True, description="terminal facing-down term (soft)")
    facing_down_tol_rad: float = Field(0.05, ge=0, le=math.pi / 2)
    position_weight: float = Field(1.0, gt=0)
    terminal_weight_factor: float = Field(10.0, gt=0)
    step_weight: float = Field(0.02, ge=0, description="per rad^2 of joint step (lighter than position)")
    table_slack_weight: float = Field(1e4, gt=0)
    facing_down_weight: float = Field(1e3, gt=0)
    initial_guess: Literal["over_box", "straight"] = Field(
        "over_box",
        description="cold-solve guess when the straight line to the goal crosses a box: lift/transfer/lower over it,"
        " or the straight line anyway (only to show the local-minimum trap)",
    )
    lift_clearance_m: float = Field(0.05, ge=0, description="extra height of the over-the-box initial guess")
    guess_step_fraction: float = Field(0.9, gt=0, le=1.0, description="initial guess steps, fraction of max")
    ipopt_tol: float = Field(
        1e-3, gt=0, description="IPOPT tol of warm-started solves (the shifted plan is usually 1-5 iterations away)"
    )
    ipopt_max_iter: int = Field(100, ge=1, description="IPOPT iteration limit of warm-started solves")
    solve_time_limit_s: float = Field(1.0, gt=0, description="CPU-time limit of a warm-started solve")
    cold_ipopt_tol: float = Field(
        1e-3, gt=0, description="IPOPT tol of a cold solve (looser left the first warm solve with more to do)"
    )
    cold_mu_init: float = Field(1e-3, gt=0, description="IPOPT mu_init of a cold solve (the guess is good)")
    cold_max_iter: int = Field(300, ge=1)
    cold_solve_time_limit_s: float = Field(5.0, gt=0, description="CPU-time limit of a cold solve")
    ipopt_options: dict[str, float | int | str] = Field(
        default_factory=dict, description="extra IPOPT options for every solve, e.g. {linear_solver: mumps}"
    )

    @model_validator(mode="after")
    def _consistent(self) -> "NMPCParams":
        if self.execute_steps > self.horizon:
            raise ValueError(f"execute_steps ({self.execute_steps}) must not exceed horizon ({self.horizon})")
        if self.object_sphere_min_radius_m > self.object_sphere_max_radius_m:
            raise ValueError("object_sphere_min_radius_m must not exceed object_sphere_max_radius_m")
        for s in self.tool_spheres:
            if s[3] <= 0:
                raise ValueError(f"tool sphere radii must be positive, got {s}")
        for w in self.wrist_spheres:
            if w[0] not in (4, 5, 6) or w[4] <= 0:
                raise ValueError(f"wrist spheres need a DH frame 4, 5 or 6 and a positive radius, got {w}")
        return self


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
        log.warning("nmpc: held box %s needs spheres of %.3f m (> %.3f m) with %d spheres", size.tolist(), r, r_max, n)
    offs = np.zeros((n, 3))
    offs[:, ax] = (np.arange(n) + 0.5) / n * 2 * half[ax] - half[ax]
    centres = (T_tcp_obj[:3, :3] @ offs.T).T + T_tcp_obj[:3, 3]
    return np.hstack([centres, np.full((n, 1), r)])


def robot_spheres(tool: np.ndarray | list, wrist: np.ndarray | list = ()) -> np.ndarray:
    """(n, 5) spheres (frame, x, y, z, r): `tool` (x, y, z, r) in the TCP frame, then `wrist` as given."""
    t = np.asarray(tool, dtype=float).reshape(-1, 4)
    w = np.asarray(wrist, dtype=float).reshape(-1, 5)
    return np.vstack([np.hstack([np.full((t.shape[0], 1), TCP_FRAME), t]), w])


def _subdivide(knots: np.ndarray, n: int) -> np.ndarray:
    """The joint-linear path through knots (m+1, 6) at n points per step, knots[0] excluded: (m*n, 6)."""
    f = np.arange(1, n + 1) / n
    return (knots[:-1, None, :] + f[None, :, None] * (knots[1:] - knots[:-1])[:, None, :]).reshape(-1, 6)


def _segment_hits_box(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
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


def _resample(path: np.ndarray, step: float, n: int, dstep: float | None = None, *, stops: Sequence[int] = ()) -> np.ndarray:
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
            v = min(v + dstep, max(float(np.interp(pos, s, vmax)), dstep), max(math.sqrt(2.0 * dstep * d) - dstep, dstep))
            if v >= d:  # arrive at a rest point (at most dstep away) and leave it from rest
                v, pos = 0.0, stop
            else:
                pos += v
            targets[i] = pos
    out = np.empty((n, 6))
    for j in range(6):
        out[:, j] = np.interp(targets, s, path[:, j])
    return out


class NMPCPlanner:
    """Receding-horizon NMPC over CasADi/IPOPT: `reset(request, scene)`, then `step(q)` until a MotionResult."""

    Params = NMPCParams
    goal_kinds = frozenset({"position"})  # see the module docstring

    def __init__(self, params: NMPCParams | None, context: "PluginContext"):
        self.params = params if params is not None else NMPCParams()
        self.context = context
        self.kin: "UR5e" = context.kinematics
        self._robot_sph = robot_spheres(self.params.tool_spheres, self.params.wrist_spheres)
        self._problems: dict[ProblemShape, NMPCProblem] = {}
        self._request: MotionRequest | None = None
        self._scene: "PlanningScene | None" = None

    # ---- the NLPs ---------------------------------------------------------------------------------
    def problem(self, shape: ProblemShape) -> NMPCProblem:
        """The NLP for `shape`, built on first use and kept for the planner's lifetime."""
        prob = self._problems.get(shape)
        if prob is None:
            P = self.params
            prob = NMPCProblem(
                shape,
                robot_spheres=self._robot_sph,
                tcp_offset_m=self.kin.tcp_offset_m,
                weights=Weights(P.position_weight, P.terminal_weight_factor, P.step_weight, P.table_slack_weight, P.facing_down_weight),
                table_clearance_m=P.table_clearance_m,
                facing_down_cos=math.cos(P.facing_down_tol_rad),
                cold_options=self._ipopt_options(cold=True),
                warm_options=self._ipopt_options(cold=False),
            )
            self._problems[shape] = prob
        return prob

    @property
    def build_time_s(self) -> float:
        """Seconds spent building NLPs so far (once per problem shape, then reused)."""
        return sum(p.build_time_s for p in self._problems.values())

    def _ipopt_options(self, *, cold: bool) -> dict[str, Any]:
        """nlpsol options. Constraint violation is held to 1e-6 (scaled rows: ~micrometres) even when a solve
        stops at IPOPT's "acceptable" level; CPU time, not wall time, so a busy machine does not fail solves."""
        P = self.params
        tol = P.cold_ipopt_tol if cold else P.ipopt_tol
        opts: dict[str, Any] = {
            "ipopt.tol": tol,
            "ipopt.acceptable_tol": 10 * tol,
            "ipopt.acceptable_iter": 5,
            "ipopt.constr_viol_tol": 1e-6,
            "ipopt.acceptable_constr_viol_tol": 1e-6,
            "ipopt.max_iter": P.cold_max_iter if cold else P.ipopt_max_iter,
            "ipopt.max_cpu_time": P.cold_solve_time_limit_s if cold else P.solve_time_limit_s,
        }
        if cold:
            opts["ipopt.mu_init"] = P.cold_mu_init
        else:  # LIBRARY-NOTES: dual warm start from the previous (shifted) solution
            opts.update(
                {
                    "ipopt.warm_start_init_point": "yes",
                    "ipopt.warm_start_bound_push": 1e-6,
                    "ipopt.warm_start_mult_bound_push": 1e-6,
                    "ipopt.mu_init": 1e-3,
                }
            )
        opts.update({f"ipopt.{k}": v for k, v in P.ipopt_options.items()})
        return opts

    # ---- geometry helpers -------------------------------------------------------------------------
    def spheres(self) -> np.ndarray:
        """(n, 5) all proxy spheres (frame, x, y, z, r): tool, wrist, then held object (TCP frame)."""
        return self._all_spheres(self._object_spheres())

    def _all_spheres(self, obj: np.ndarray) -> np.ndarray:
        if not obj.size:
            return self._robot_sph.copy()
        return np.vstack([self._robot_sph, np.hstack([np.full((obj.shape[0], 1), TCP_FRAME), obj])])

    def _centres(self, qs: np.ndarray, sph: np.ndarray) -> np.ndarray:
        return sphere_centres(self.kin.dh_frames(np.atleast_2d(qs)), self.kin.tcp_offset_m, sph)

    def proxy_spheres(self, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centres (m, n, 3) and radii (n,) of the proxy spheres at configurations qs (m, 6), base frame."""
        sph = self.spheres()
        return self._centres(qs, sph), sph[:, 4].copy()

    def _object_spheres(self) -> np.ndarray:
        att = self._scene.attached_box() if self._scene is not None else None
        if att is None:
            return np.zeros((0, 4))
        _, size, T = att
        P = self.params
        obj = object_spheres(size, T, r_min=P.object_sphere_min_radius_m, r_max=P.object_sphere_max_radius_m, max_n=P.max_object_spheres)
        # a held-object sphere inside a tool sphere adds constraints but no protection (a 50 mm cube held at
        # the TCP sits inside the TCP sphere): drop it, solves get cheaper
        tool = self._robot_sph[self._robot_sph[:, 0] == TCP_FRAME, 1:5]
        gap = np.linalg.norm(obj[:, None, :3] - tool[None, :, :3], axis=2) + obj[:, None, 3] - tool[None, :, 3]
        return obj[~np.any(gap <= 1e-9, axis=1)]

    def _boxes(self) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """The scene's run-time (perceived) boxes, read fresh for every solve: (name, lo, hi)."""
        if self._scene is None:
            return []
        return [(n, b.lo, b.hi) for n, b in sorted(self._scene.box_bounds().items())]

    def _tracked(self, q: np.ndarray) -> np.ndarray:
        T = self.kin.fk(q, "tcp")
        return T[:3, 3] + T[:3, :3] @ self._track

    # ---- receding horizon -------------------------------------------------------------------------
    def reset(self, request: MotionRequest, scene: "PlanningScene") -> None:
        """Start a new goal: resolve the goal's TCP target and forget the previous plan (keep the NLPs)."""
        self._request = request
        self._scene = scene
        self._solves = 0
        self._fallbacks = 0
        self._braking_steps = 0
        self._solve_log: list[dict[str, Any]] = []
        self._plan: np.ndarray | None = None  # (N+1, 6) knots of the last feasible plan
        self._plan_idx = 0  # index of the knot the robot should be at now
        self._ws: tuple[ProblemShape, SolveOutput] | None = None  # last converged solve, for warm start
        self._ws_offset = 0
        self._q_end: np.ndarray | None = None  # where the last segment ended, and its velocity
        self._qd_end = np.zeros(6)
        self._dq_prev = np.zeros(6)  # the last executed step (knot to knot): the start is at rest
        self._guess_kind = ""
        self._done: MotionResult | None = None
        self._pending: MotionResult | None = None
        self._goal_candidates = np.zeros((0, 6))
        goal = request.goal
        self._tolerance = self.params.goal_tolerance_m
        if isinstance(goal, PoseGoal):
            self._tolerance = min(self._tolerance, goal.position_tolerance_m)
        if isinstance(goal, JointGoal):
            self._track = np.zeros(3)
            self._target = self.kin.fk(goal.q, "tcp")[:3, 3]
            self._goal_candidates = goal.q[None].copy()
            if not self.kin.within_limits(goal.q):
                self._pending = self._final(Status.INVALID_GOAL, f"joint goal {np.round(goal.q, 3).tolist()} is outside the joint limits")
        elif isinstance(goal, PoseGoal):
            if goal.frame not in ("tcp", "flange"):
                self._pending = self._final(Status.INVALID_GOAL, f"unknown goal frame {goal.frame!r}; allowed: tcp, flange")
                self._track = np.zeros(3)
                self._target = np.asarray(goal.pose.position, dtype=float)
                return
            self._track = np.zeros(3) if goal.frame == "tcp" else np.array([0.0, 0.0, -self.kin.tcp_offset_m])
            self._target = np.asarray(goal.pose.position, dtype=float)
            self._goal_candidates = self._goal_ik(goal)
            if self._goal_candidates.shape[0] == 0:
                self._pending = self._final(Status.INVALID_GOAL, f"goal position {np.round(self._target, 3).tolist()} is out of reach (no IK)")
        else:  # pragma: no cover - MotionRequest already rejects other goal types
            raise PlanningError(f"unsupported goal {goal!r}")
        if self._pending is None and self._target[2] < self.params.table_z_m:
            self._pending = self._final(Status.INVALID_GOAL, f"goal z {self._target[2]:.3f} m is below the table top ({self.params.table_z_m} m)")

    def _goal_ik(self, goal: PoseGoal) -> np.ndarray:
        """Joint solutions for the goal pose; when the orientation is out of reach, for the goal position
        with the tool facing down at a few yaws (NMPC tracks the position; orientation is a soft term)."""
        T = goal.pose.matrix()
        sols = self.kin.ik(T, goal.frame)
        if sols.shape[0]:
            return sols
        out = []
        for yaw in np.linspace(0, 2 * math.pi, 8, endpoint=False):
            Td = np.eye(4)
            c, s = math.cos(yaw), math.sin(yaw)
            Td[:3, :3] = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])
            Td[:3, 3] = T[:3, 3]
            sol = self.kin.ik(Td, goal.frame)
            if sol.shape[0]:
                out.append(sol)
        return np.vstack(out) if out else np.zeros((0, 6))

    def _final(self, status: Status, reason: str, q: np.ndarray | None = None) -> MotionResult:
        info: dict[str, Any] = {
            "goal_tolerance_m": getattr(self, "_tolerance", self.params.goal_tolerance_m),
            "nmpc_solves": getattr(self, "_solves", 0),
            "nmpc_fallbacks": getattr(self, "_fallbacks", 0),
            "nmpc_braking_steps": getattr(self, "_braking_steps", 0),
            "nmpc_solve_log": list(getattr(self, "_solve_log", [])),
            "initial_guess": getattr(self, "_guess_kind", ""),
        }
        traj = None
        if q is not None:
            info["position_error_m"] = float(np.linalg.norm(self._tracked(q) - self._target))
            if self._request is not None and isinstance(self._request.goal, PoseGoal):
                R = self.kin.fk(q, self._request.goal.frame)[:3, :3]
                G = self._request.goal.pose.matrix()[:3, :3]
                info["orientation_error_rad"] = float(np.arccos(np.clip((np.trace(R.T @ G) - 1) / 2, -1, 1)))
            if status is Status.SUCCESS:
                traj = Trajectory(np.zeros(1), q[None], np.zeros((1, 6)), np.zeros((1, 6)))
        return MotionResult(status, reason, traj, info=info)

    def step(self, q: np.ndarray) -> Segment | MotionResult:
        """The next k steps from measured joint state `q` (6,) rad, or the final MotionResult."""
        if self._request is None:
            raise PlanningError("NMPCPlanner.step() called before reset()")
        if self._done is not None:
            return self._done
        q = as_q(q, "q")
        P = self.params
        if self._pending is not None:
            self._done = self._pending
            return self._done
        err = float(np.linalg.norm(self._tracked(q) - self._target))
        boxes = self._boxes()
        obj = self._object_spheres()
        sph = self._all_spheres(obj)
        step = np.minimum(P.max_step_rad, self._request.limits.max_joint_vel * P.dt)
        dstep = self._request.limits.max_joint_acc * P.dt**2 if P.limit_acceleration else None
        if err <= self._tolerance:
            # within the tolerance the NMPC stops solving; an arm still moving faster than it can stop in one
            # step first brakes along the last plan (which heads for the goal and comes to rest there)
            if dstep is not None and np.any(np.abs(self._dq_prev) > dstep + 1e-9):
                knots = self._braking_knots(q, sph, boxes, step, dstep)
                if knots is not None:
                    self._braking_steps += knots.shape[0] - 1
                    return self._execute(knots, dstep, {"solve": self._solves, "braking": True, "fallback": False}, 0.0, err)
                log.info("nmpc: at the goal but no plan to brake along; stopping from %.3f rad/step", float(np.abs(self._dq_prev).max()))
            self._done = self._final(Status.SUCCESS, f"TCP within {err:.4f} m of the goal after {self._solves} solves", q)
            return self._done
        if self._solves >= P.max_solves:
            self._done = self._final(
                Status.NO_SOLUTION, f"goal not reached after {self._solves} solves: TCP {err:.3f} m away (tolerance {self._tolerance} m)", q
            )
            return self._done

        for name, lo, hi in boxes:
            if np.any(np.all((self._target >= lo) & (self._target <= hi))):
                self._done = self._final(Status.INVALID_GOAL, f"the goal lies inside obstacle box {name!r}", q)
                return self._done
        clear = self._clearance(q[None], sph, boxes, margin=0.0)
        if clear.size and clear.min() < 0.0:
            when = "at the start" if self._solves == 0 else f"at the state measured for solve {self._solves + 1}"
            self._done = self._final(Status.INVALID_START, f"a proxy sphere is {-clear.min():.3f} m inside an obstacle box {when}", q)
            return self._done

        shape = ProblemShape(P.horizon, len(boxes), obj.shape[0], P.constraint_substeps)
        prob = self.problem(shape)
        p = self._parameters(q, boxes, obj)
        bounds = prob.bounds(self.kin.joint_limits[:, 0], self.kin.joint_limits[:, 1], step, dstep, facing_down=P.facing_down)
        if self._ws is not None and self._ws[0] == shape:
            prev = self._ws[1]
            k = self._ws_offset
            x0 = prob.shift(prev.x, prob.block_x, k)
            lam_x0 = prob.shift(prev.lam_x, prob.block_x, k)
            lam_g0 = prob.shift(prev.lam_g, prob.block_g, k)
            sol = prob.solve(x0, p, bounds, lam_x0=lam_x0, lam_g0=lam_g0)
        else:
            guess = self._initial_guess(q, boxes, sph, step, dstep)
            x0 = prob.pack_x(guess, self._guess_slack(guess, sph))
            sol = prob.solve(x0, p, bounds)
        self._solves += 1
        entry = {"solve": self._solves, "warm": sol.warm, "time_s": sol.solve_time_s, "status": sol.status, "iterations": sol.iterations}
        self._solve_log.append(entry)

        k = P.execute_steps
        problem = None if sol.converged else f"IPOPT: {sol.status}"
        if problem is None:
            problem = self._violation(sol.q, sph, boxes, step, dstep)
        if problem is None:
            self._plan, self._plan_idx = sol.q, 0
            self._ws, self._ws_offset = (shape, sol), 0
            knots = sol.q[: k + 1].copy()
            fallback = False
        else:
            entry["rejected"] = problem
            log.info("nmpc: solve %d rejected (%s)", self._solves, problem)
            if self._plan is None and not sol.warm:
                # the first solve of a goal failed: its initial guess is itself a plan over the box, at
                # reduced speed; it is followed (as the "last feasible plan") only if it passes the same check
                path = np.vstack([q[None], guess])
                if self._violation(path, sph, boxes, step, dstep) is None:
                    self._plan, self._plan_idx = path, 0
                    entry["following"] = "initial guess"
            self._ws = None  # the next solve starts cold, from a fresh guess at the state reached
            knots, fallback = self._fallback_knots(q, sph, boxes, step, dstep, k), True
            if knots is None:
                self._done = self._final(Status.NO_SOLUTION, f"solve {self._solves} failed ({problem}) and no feasible plan is left to follow", q)
                return self._done
            self._fallbacks += 1
        knots[0] = q
        entry["fallback"] = fallback
        return self._execute(knots, dstep, dict(entry, cost=sol.cost), sol.solve_time_s, err)

    def _execute(self, knots: np.ndarray, dstep: np.ndarray | None, info: dict[str, Any], solve_time_s: float, err: float) -> Segment:
        """Command `knots` (m+1, 6), knots[0] = the measured state: advance the plan and return the segment."""
        self._dq_prev = knots[-1] - knots[-2]
        self._plan_idx += knots.shape[0] - 1
        self._ws_offset += knots.shape[0] - 1
        traj = self._segment(knots, dstep)
        return Segment(traj, solve_time_s, dict(info, position_error_m=err), fallback=bool(info.get("fallback", False)))

    # ---- pieces of step() ---------------------------------------------------------------------------
    def _parameters(self, q: np.ndarray, boxes: list[tuple[str, np.ndarray, np.ndarray]], obj: np.ndarray) -> np.ndarray:
        m = self.params.box_margin_m
        parts = [q, self._dq_prev, self._target, self._track, [self.params.table_z_m]]
        for _, lo, hi in boxes:
            parts += [0.5 * (lo + hi), 0.5 * (hi - lo) + m]
        for s in obj:
            parts += [s[:3], [s[3]]]
        return np.concatenate([np.asarray(a, dtype=float).reshape(-1) for a in parts])

    def _clearance(self, qs: np.ndarray, sph: np.ndarray, boxes: list[tuple[str, np.ndarray, np.ndarray]], *, margin: float) -> np.ndarray:
        """(m, n_boxes * n_spheres) signed clearances of the spheres at qs from the boxes grown by `margin`."""
        if not boxes:
            return np.zeros((qs.shape[0], 0))
        centres = self._centres(qs, sph)
        cols = [sphere_box_clearance(centres, sph[None, :, 4], lo - margin, hi + margin) for _, lo, hi in boxes]
        return np.concatenate(cols, axis=1)

    def _violation(
        self,
        knots: np.ndarray,
        sph: np.ndarray,
        boxes: list[tuple[str, np.ndarray, np.ndarray]],
        step: np.ndarray,
        dstep: np.ndarray | None,
    ) -> str | None:
        """Why the knot path (m+1, 6) (knots[0] = the current state) breaks a hard constraint, or None."""
        dq = np.diff(knots, axis=0)
        if np.any(np.abs(dq) > step + 1e-7):
            return f"a joint step of {np.abs(dq).max():.3f} rad exceeds {step.max():.3f} rad"
        if dstep is not None:
            ddq = np.abs(np.diff(np.vstack([self._dq_prev[None], dq]), axis=0))
            if np.any(ddq > dstep + 1e-7):
                return f"a joint step changes by {ddq.max():.4f} rad, more than {dstep.max():.4f} rad (acceleration)"
        lim = self.kin.joint_limits
        if np.any(knots < lim[:, 0] - 1e-9) or np.any(knots > lim[:, 1] + 1e-9):
            return "a knot leaves the joint limits"
        if boxes:
            m = self.params.box_margin_m
            seq = np.vstack([knots[:1], _subdivide(knots, self.params.constraint_substeps)])
            centres = self._centres(seq, sph)
            for name, lo, hi in boxes:
                c = pair_clearance(centres, sph[:, 4], lo - m, hi + m)
                if c.min() < -_CHECK_TOL_M:
                    return f"proxy spheres may come {-c.min():.4f} m into box {name!r} (incl. margin) between check points"
            # belt and braces: the joint-linear path, densely, against the boxes themselves
            dense = self._clearance(_subdivide(knots, 8), sph, boxes, margin=0.0)
            if dense.min() < 0.0:
                return f"a proxy sphere enters an obstacle box by {-dense.min():.4f} m between knots"
        return None

    def _fallback_knots(
        self,
        q: np.ndarray,
        sph: np.ndarray,
        boxes: list[tuple[str, np.ndarray, np.ndarray]],
        step: np.ndarray,
        dstep: np.ndarray | None,
        k: int,
    ) -> np.ndarray | None:
        """Up to k remaining steps of the last feasible plan, from the measured state, if they still pass."""
        if self._plan is None:
            return None
        rest = self._plan[self._plan_idx + 1 : self._plan_idx + 1 + k]
        if rest.shape[0] == 0:
            return None
        knots = np.vstack([q[None], rest])
        why = self._violation(knots, sph, boxes, step, dstep)
        if why is not None:
            log.info("nmpc: the last feasible plan no longer passes (%s)", why)
            return None
        return knots

    def _braking_knots(
        self, q: np.ndarray, sph: np.ndarray, boxes: list[tuple[str, np.ndarray, np.ndarray]], step: np.ndarray, dstep: np.ndarray
    ) -> np.ndarray | None:
        """The last plan's next knots up to the first step small enough to stop after (<= dstep per joint),
        from the measured state, if they pass the constraint check; None without such a plan."""
        if self._plan is None:
            return None
        rest = self._plan[self._plan_idx + 1 :]
        if rest.shape[0] == 0:
            return None
        steps = np.abs(np.diff(np.vstack([q[None], rest]), axis=0))
        small = np.flatnonzero(np.all(steps <= dstep + 1e-9, axis=1))
        if small.size == 0:
            return None
        knots = np.vstack([q[None], rest[: small[0] + 1]])
        return knots if self._violation(knots, sph, boxes, step, dstep) is None else None

    def _segment(self, knots: np.ndarray, dstep: np.ndarray | None = None) -> Trajectory:
        """The executed knots as a trajectory at dt: starts exactly at the measured state (zero velocity at the
        first segment, the previous segment's end velocity after that); velocities are central differences
        over the plan, zero at the end when that end is within the goal tolerance and slow enough to stop."""
        dt = self.params.dt
        m = knots.shape[0] - 1
        t = dt * np.arange(m + 1)
        nxt = self._plan[self._plan_idx + 1] if self._plan is not None and self._plan_idx + 1 < self._plan.shape[0] else knots[-1]
        ext = np.vstack([knots, nxt[None]])
        qd = np.zeros((m + 1, 6))
        if self._q_end is not None:  # the commanded velocity carries over, even when tracking lags
            qd[0] = self._qd_end
        qd[1:] = (ext[2:] - ext[:-2]) / (2 * dt)
        slow = dstep is None or bool(np.all(np.abs(knots[-1] - knots[-2]) <= dstep + 1e-9))
        if slow and np.linalg.norm(self._tracked(knots[-1]) - self._target) <= self._tolerance:
            qd[-1] = 0.0
        qdd = np.zeros_like(qd)
        if m >= 1:
            qdd[:-1] = np.diff(qd, axis=0) / dt
            qdd[-1] = qdd[-2]
        self._q_end, self._qd_end = knots[-1].copy(), qd[-1].copy()
        return Trajectory(t, knots, qd, qdd)

    # ---- initial guess ------------------------------------------------------------------------------
    def _guess_slack(self, knots: np.ndarray, sph: np.ndarray) -> np.ndarray:
        z = self._centres(knots, sph)[:, :, 2]
        need = self.params.table_z_m + self.params.table_clearance_m - (z - sph[None, :, 4])
        return np.maximum(need.max(axis=1), 0.0)

    def _initial_guess(
        self,
        q0: np.ndarray,
        boxes: list[tuple[str, np.ndarray, np.ndarray]],
        sph: np.ndarray,
        step: np.ndarray,
        dstep: np.ndarray | None = None,
    ) -> np.ndarray:
        """(N, 6) knots for a cold solve: a straight Cartesian line to the goal when it clears every box,
        else lift, transfer over the box, lower; both through continuity-seeded IK at constant tool
        orientation, ending in the goal configuration nearest to the path."""
        P = self.params
        T0 = self.kin.fk(q0, "tcp")
        R0 = T0[:3, :3]
        p0 = T0[:3, 3] + R0 @ self._track
        pg = self._target
        m = P.box_margin_m
        tcp_sph = sph[sph[:, 0] == TCP_FRAME, 1:5]
        reach = float(np.max(np.linalg.norm(tcp_sph[:, :3] - self._track, axis=1) + tcp_sph[:, 3]))
        crossed = [(n, lo, hi) for n, lo, hi in boxes if _segment_hits_box(p0, pg, lo - m - reach, hi + m + reach)]
        if crossed and P.initial_guess == "straight":
            log.info("nmpc: the straight initial guess crosses %s; IPOPT may stay stuck below it", [n for n, _, _ in crossed])
            crossed = []
        if crossed:
            below = float(np.max(tcp_sph[:, 3] - (R0 @ (tcp_sph[:, :3] - self._track).T)[2]))
            z_lift = max(hi[2] for _, _, hi in crossed) + m + below + P.lift_clearance_m
            way = [p0, np.array([p0[0], p0[1], max(z_lift, p0[2])]), np.array([pg[0], pg[1], max(z_lift, pg[2])]), pg]
            self._guess_kind = "over_box"
            log.info("nmpc: the straight line to the goal crosses %s; seeding the first solve over it (z %.3f m)", [n for n, _, _ in crossed], z_lift)
        else:
            way = [p0, pg]
            self._guess_kind = "straight"
        pts, corners = [way[0]], []
        for a, b in zip(way[:-1], way[1:]):
            n = max(1, math.ceil(float(np.linalg.norm(b - a)) / 0.02))
            pts += [a + (b - a) * i / n for i in range(1, n + 1)]
            corners.append(len(pts) - 1)  # the guess comes to rest here: joints may turn around
        path = [q0]
        T = np.eye(4)
        T[:3, :3] = R0
        for pt in pts[1:]:
            T[:3, 3] = pt - R0 @ self._track
            sols = self.kin.ik(T, "tcp")
            if sols.shape[0] == 0:
                path = None
                break
            d = np.abs(sols - path[-1]).max(axis=1)
            i = int(np.argmin(d))
            if d[i] > 0.5:
                path = None
                break
            path.append(sols[i])
        if path is None:
            # the Cartesian path already ends at the goal position (orientation is not tracked); only
            # without it does the guess head for a goal configuration, the one nearest in arm joints
            self._guess_kind += "+joint_fallback"
            log.info("nmpc: no continuous IK along the initial-guess path; using a joint-space guess")
            path, corners = [q0], []
            if self._goal_candidates.shape[0]:
                d = np.abs(self._goal_candidates - q0) @ np.array([1.0, 1.0, 1.0, 1.0, 1.0, 0.1])
                path.append(self._goal_candidates[int(np.argmin(d))])
        f = P.guess_step_fraction
        # half the acceleration: the inf-norm arc length bounds the fastest joint, others turn within a leg
        a = None if dstep is None else 0.5 * f * float(np.min(dstep))
        return _resample(np.array(path), f * float(step.min()), P.horizon, a, stops=corners)
