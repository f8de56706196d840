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

The pieces: `twin_nmpc.params` (the parameter model, the default spheres), `twin_nmpc.model` (the NLP),
`twin_nmpc.spheres` (the proxy spheres and the numpy check of a plan), `twin_nmpc.guess` (the cold solve's
initial guess); this module holds the receding-horizon loop.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.plugin import (
    JointGoal,
    MotionRequest,
    MotionResult,
    PlanningError,
    PoseGoal,
    Segment,
    Status,
    Trajectory,
    as_q,
)
from twin_nmpc.guess import guess_slack, initial_guess
from twin_nmpc.model import NMPCProblem, ProblemShape, SolveOutput, Weights
from twin_nmpc.params import NMPCParams
from twin_nmpc.spheres import (
    Box,
    clearance,
    drop_covered,
    object_spheres,
    robot_spheres,
    sphere_positions,
    violation,
    with_object,
)

if TYPE_CHECKING:
    from twin.plugin import PlanningScene, PluginContext, UR5e

__all__ = ["NMPCPlanner"]

log = logging.getLogger("twin")


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
        self._start_goal()

    # ---- the NLPs ---------------------------------------------------------------------------------
    def problem(self, shape: ProblemShape) -> NMPCProblem:
        """The NLP for `shape`, built on first use and kept for the planner's lifetime."""
        prob = self._problems.get(shape)
        if prob is None:
            P = self.params
            prob = NMPCProblem(
                shape,
                robot_spheres=self._robot_sph,
                dh=self.kin.dh,
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
        return with_object(self._robot_sph, self._object_spheres())

    def proxy_spheres(self, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centres (m, n, 3) and radii (n,) of the proxy spheres at configurations qs (m, 6), base frame."""
        sph = self.spheres()
        return sphere_positions(self.kin, qs, sph), sph[:, 4].copy()

    def _object_spheres(self) -> np.ndarray:
        att = self._scene.attached_box() if self._scene is not None else None
        if att is None:
            return np.zeros((0, 4))
        _, size, T = att
        P = self.params
        obj = object_spheres(size, T, r_min=P.object_sphere_min_radius_m, r_max=P.object_sphere_max_radius_m, max_n=P.max_object_spheres)
        return drop_covered(obj, self._robot_sph)

    def _boxes(self) -> list[Box]:
        """The scene's run-time (perceived) boxes, read fresh for every solve: (name, lo, hi)."""
        if self._scene is None:
            return []
        return [(n, b.lo, b.hi) for n, b in sorted(self._scene.box_bounds().items())]

    def _tracked(self, q: np.ndarray) -> np.ndarray:
        T = self.kin.fk(q, "tcp")
        return T[:3, 3] + T[:3, :3] @ self._track

    # ---- receding horizon -------------------------------------------------------------------------
    def _start_goal(self) -> None:
        """The state of one goal, as before its first solve (the NLPs are kept)."""
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
        self._guess_kind = ""  # what the last cold solve started from (twin_nmpc.guess)
        self._done: MotionResult | None = None
        self._pending: MotionResult | None = None
        self._goal_candidates = np.zeros((0, 6))  # goal configurations, for a joint-space initial guess
        self._track = np.zeros(3)  # the point that goes to the goal, TCP frame
        self._target = np.zeros(3)  # the goal position, base frame
        self._tolerance = self.params.goal_tolerance_m  # or the goal's tighter position tolerance

    def reset(self, request: MotionRequest, scene: "PlanningScene") -> None:
        """Start a new goal: resolve the goal's TCP target and forget the previous plan (keep the NLPs)."""
        self._request = request
        self._scene = scene
        self._start_goal()
        goal = request.goal
        if isinstance(goal, PoseGoal):
            self._tolerance = min(self._tolerance, goal.position_tolerance_m)
        if isinstance(goal, JointGoal):
            self._target = self.kin.fk(goal.q, "tcp")[:3, 3]
            self._goal_candidates = goal.q[None].copy()
            if not self.kin.within_limits(goal.q):
                self._pending = self._final(Status.INVALID_GOAL, f"joint goal {np.round(goal.q, 3).tolist()} is outside the joint limits")
        elif isinstance(goal, PoseGoal):
            if goal.frame not in ("tcp", "flange"):
                self._pending = self._final(Status.INVALID_GOAL, f"unknown goal frame {goal.frame!r}; allowed: tcp, flange")
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
            "nmpc_solves": self._solves,
            "nmpc_fallbacks": self._fallbacks,
            "nmpc_braking_steps": self._braking_steps,
            "nmpc_solve_log": list(self._solve_log),
            "initial_guess": self._guess_kind,
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
        return MotionResult(status, reason, traj, info=info, goal_tolerance_m=self._tolerance)

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
        sph = with_object(self._robot_sph, obj)
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
        clear = clearance(self.kin, q[None], sph, boxes, margin=0.0)
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
            guess, self._guess_kind = initial_guess(
                self.kin, P, q, self._target, self._track, self._goal_candidates, boxes, sph, step, dstep
            )
            x0 = prob.pack_x(guess, guess_slack(self.kin, guess, sph, P))
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
    def _parameters(self, q: np.ndarray, boxes: list[Box], obj: np.ndarray) -> np.ndarray:
        m = self.params.box_margin_m
        parts = [q, self._dq_prev, self._target, self._track, [self.params.table_z_m]]
        for _, lo, hi in boxes:
            parts += [0.5 * (lo + hi), 0.5 * (hi - lo) + m]
        for s in obj:
            parts += [s[:3], [s[3]]]
        return np.concatenate([np.asarray(a, dtype=float).reshape(-1) for a in parts])

    def _violation(self, knots: np.ndarray, sph: np.ndarray, boxes: list[Box], step: np.ndarray, dstep: np.ndarray | None) -> str | None:
        """Why the knot path (m+1, 6) (knots[0] = the current state) breaks a hard constraint, or None."""
        P = self.params
        return violation(
            self.kin, knots, sph, boxes, step, dstep,
            dq_prev=self._dq_prev, box_margin_m=P.box_margin_m, substeps=P.constraint_substeps,
        )

    def _fallback_knots(
        self,
        q: np.ndarray,
        sph: np.ndarray,
        boxes: list[Box],
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
        self, q: np.ndarray, sph: np.ndarray, boxes: list[Box], step: np.ndarray, dstep: np.ndarray
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
