"""The receding-horizon loop the MPC planners share (`nmpc` over CasADi/IPOPT, `croc` over Crocoddyl/CSQP):
everything around a solve, so that two MPCs on the same formulation differ only in their solver.

Per step: from the measured joint state, the latest obstacle boxes of the planning scene and the held
object, a subclass solves the horizon (`_solve`: N joint steps under per-step increments, proxy spheres
outside the boxes, its own cost); the first k steps are executed and the loop replans. It stops within the
goal tolerance (SUCCESS) or after `max_solves` solves (NO_SOLUTION).

What the loop does the same for every solver:
* A solve that fails, or whose steps do not pass an independent numpy check of the hard constraints, is
  never executed: the remaining steps of the last feasible plan are (after the same check; when the very
  first solve of a goal fails, its checked initial guess is that plan), else a moving arm brakes to rest on a
  free stop and the loop solves again from there (`_recover`: from a measured state off the commanded one, a
  controller's lag, the rows near a box can leave no plan within the bounds, while from rest there is one),
  and an arm at rest stops with a typed failure and a reason (croc also recovers so from a segment that would
  leave no free way to stop at its end). The solve after a failure starts cold, from a
  fresh guess.
* The model knows the boxes and the table height, not necessarily the cell's fixtures (bins) nor the arm's
  own links: every segment is checked against the whole FCL scene it was given (at the configured
  `collision.check_resolution_*`) before it is returned, and the last plan a little beyond it (its next
  knots, as far as the arm needs to stop, coarsely). When either collides the arm brakes, as a real
  controller's protective stop does: a shortest stop within the step, acceleration and jerk bounds
  (`twin.planning.braking`), returned only if it is free itself, then Status.COLLISION naming the pair. A start
  in collision is refused with INVALID_START naming the pair. Every other end while the arm moves (no plan
  left, `max_solves` solves) brakes the same way before its status.
* A way to stop is planned clear before it is needed: a moving segment is commanded only when a stop from
  its end (the shortest stop, or the last plan up to where it may stop) is free in the FCL scene, and that
  stop is kept (`_safe_stop`). So every state the loop reaches has a checked way to rest: a brake, or the
  stop at the goal, that would collide from there takes the kept stop instead (from a measured state off the
  commanded one, its steps from there, checked again). Without the rule a RoboCup position query reached its
  goal tolerance moving towards the table, and both its stops collided (left_finger with table): "no free
  way to brake".
* A segment's samples are the knots, dt apart, and their derivatives are the knots' backward differences:
  qd_i = (q_i - q_{i-1}) / dt, qdd_i = (qd_i - qd_{i-1}) / dt, the first sample's from the steps that
  brought the arm to the measured state (zero at rest). So a segment starts with the state the previous
  one ended in, and what it declares is exactly what its positions measure. Within the goal tolerance a
  moving arm comes to rest as soon as its bounds allow (along its last plan or on the shortest stop,
  whichever is shorter and still ends within the tolerance, as the seed stops as soon as it is within it),
  and the last segment ends with a zero step: declared at rest.
* The loop tracks a position and stops within a tolerance of it (`goal_tolerance_m`, or the goal's own
  `position_tolerance_m` when that is tighter); it does not track an orientation (only a soft terminal
  facing-down term) and it does not reach joint goals. So it declares `goal_kinds = {"position"}`: a
  config that asks it for joint or oriented pose goals fails before anything runs, and `twin.planning`
  judges its end like every planner's, against the goal's tolerances.
* Segments that follow an earlier plan or the initial guess after a failed solve are marked
  `Segment.fallback`; the checked loop FCL-checks and counts them like any other segment. Braking
  segments (no solve) have `info["braking"]` and a solve time of 0. The result's info counts them
  (`nmpc_solves`, `nmpc_fallbacks`, `nmpc_braking_steps`, `nmpc_solve_log`: the names of the first MPC).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.errors import PlanningError
from twin.planning.braking import slowing_steps
from twin.planning.checked import Segment, colliding_pair
from twin.planning.guess import initial_guess
from twin.planning.proxy_spheres import (
    Box,
    clearance,
    drop_covered,
    object_spheres,
    robot_spheres,
    sphere_positions,
    with_object,
)
from twin.planning.receding_params import RecedingParams, Weights
from twin.planning.stops import WaysToStop
from twin.types import JointGoal, MotionRequest, MotionResult, PoseGoal, Status, Trajectory, as_q

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.registry import PluginContext
    from twin.robot.kinematics import URArm

__all__ = ["RecedingHorizonMPC", "Solved"]

log = logging.getLogger("twin")


@dataclass
class Solved:
    """What one solve (`RecedingHorizonMPC._solve`) brings back: its plan (N+1, 6) from the measured state, or
    None; why it is not a plan (`problem`, None when the solver says it is one: the loop still checks it);
    the initial guess of a cold solve (followed when the first solve of a goal fails and the guess passes the
    check); the solver's time, cost and log entry; and what the solver keeps to warm-start the next solve
    (`warm_start`, kept only while its plans are accepted)."""

    plan: np.ndarray | None
    problem: str | None
    time_s: float
    cost: float
    log: dict[str, Any]
    guess: np.ndarray | None = None
    warm_start: Any = None
    warm: bool = False


class RecedingHorizonMPC(WaysToStop):
    """The loop around a solve: `reset(request, scene)`, then `step(q)` until a MotionResult. A subclass
    provides `_solve` and its `Params` (a `RecedingParams`); the commanded motion and its ways to stop are
    `WaysToStop`'s (`twin.planning.stops`)."""

    Params: type[RecedingParams] = RecedingParams
    goal_kinds = frozenset({"position"})  # see the module docstring
    # the sphere models (params) are the UR5e's links; another arm's are not written, so the factory refuses
    # another `robot.model` and a comparison skips such a pair
    robot_models = frozenset({"ur5e"})
    name = "mpc"  # in log lines
    # a segment that would leave no free way to stop at its end, or a plan that runs into a collision a few
    # steps ahead: brake to rest and solve again (`_recover`, at most `max_solves` solves in all) rather than end
    # the goal; croc's (its lagged fallbacks near the warehouse wall); nmpc's tests keep the end
    _recovers_blocked_segments = False

    def __init__(self, params: RecedingParams | None, context: PluginContext):
        self.params = params if params is not None else self.Params()
        self.context = context
        self.kin: URArm = context.kinematics
        col = context.settings.collision
        self._resolution = {"max_step_rad": col.check_resolution_rad, "max_step_m": col.check_resolution_m}
        self._robot_sph = robot_spheres(self.params.tool_spheres, self.params.wrist_spheres)
        self._request: MotionRequest | None = None
        self._scene: PlanningScene | None = None
        self._start_goal()

    @property
    def jerk_limited(self) -> bool:
        """Declared (`twin.planning.jerk_limited`): the solve bounds the change of the step's change by the
        request's jerk limit x dt^3 unless `limit_jerk` is off."""
        return bool(self.params.limit_jerk)

    def _weights(self) -> Weights:
        """The seed's cost weights, from the parameters."""
        P = self.params
        return Weights(
            P.position_weight, P.terminal_weight_factor, P.step_weight, P.table_slack_weight, P.facing_down_weight
        )

    def _solve(self, q: np.ndarray, boxes: list[Box], obj: np.ndarray, sph: np.ndarray) -> Solved:
        """One solve from the measured state `q`, warm-started from `self._ws` (the last accepted solve's
        `warm_start`, `self._ws_offset` steps ago) when there is one."""
        raise NotImplementedError

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
        obj = object_spheres(
            size, T, r_min=P.object_sphere_min_radius_m, r_max=P.object_sphere_max_radius_m, max_n=P.max_object_spheres
        )
        return drop_covered(obj, self._robot_sph)

    def _boxes(self) -> list[Box]:
        """The scene's run-time (perceived) boxes, read fresh for every solve: (name, lo, hi)."""
        if self._scene is None:
            return []
        return [(n, b.lo, b.hi) for n, b in sorted(self._scene.box_bounds().items())]

    # ---- receding horizon -------------------------------------------------------------------------
    def _start_goal(self) -> None:
        """The state of one goal, as before its first solve (what the solver built is kept)."""
        self._solves = 0
        self._fallbacks = 0
        self._braking_steps = 0
        self._recoveries = 0  # failed solves with nothing to follow, braked to rest and solved again (`_recover`)
        self._solve_log: list[dict[str, Any]] = []
        self._plan: np.ndarray | None = None  # (N+1, 6) knots of the last feasible plan
        self._plan_idx = 0  # index of the knot the robot should be at now
        self._ws: Any = None  # the last accepted solve's warm start (`Solved.warm_start`)
        self._ws_offset = 0  # steps executed since
        self._commanded = None  # the knot the arm was last commanded to (`_commit`)
        self._dq_prev = np.zeros(6)  # the last executed step (knot to knot): the start is at rest
        self._dq_prev2 = np.zeros(6)  # the step before it
        self._started = False  # whether step() has seen the measured start
        self._guess_kind = ""  # what the last cold solve started from (twin.planning.guess)
        self._done: MotionResult | None = None
        self._pending: MotionResult | None = None
        self._safe_stop: np.ndarray | None = None  # a checked-free stop (knots) from the last segment's end
        self._goal_candidates = np.zeros((0, 6))  # goal configurations, for a joint-space initial guess
        self._track = np.zeros(3)  # the point that goes to the goal, TCP frame
        self._target = np.zeros(3)  # the goal position, base frame
        self._tolerance = self.params.goal_tolerance_m  # or the goal's tighter position tolerance

    def reset(self, request: MotionRequest, scene: PlanningScene) -> None:
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
                self._pending = self._final(
                    Status.INVALID_GOAL, f"joint goal {np.round(goal.q, 3).tolist()} is outside the joint limits"
                )
        elif isinstance(goal, PoseGoal):
            if goal.frame not in ("tcp", "flange"):
                self._pending = self._final(
                    Status.INVALID_GOAL, f"unknown goal frame {goal.frame!r}; allowed: tcp, flange"
                )
                self._target = np.asarray(goal.pose.position, dtype=float)
                return
            self._track = np.zeros(3) if goal.frame == "tcp" else np.array([0.0, 0.0, -self.kin.tcp_offset_m])
            self._target = np.asarray(goal.pose.position, dtype=float)
            self._goal_candidates = self._goal_ik(goal)
            if self._goal_candidates.shape[0] == 0:
                self._pending = self._final(
                    Status.INVALID_GOAL, f"goal position {np.round(self._target, 3).tolist()} is out of reach (no IK)"
                )
        else:  # pragma: no cover - MotionRequest already rejects other goal types
            raise PlanningError(f"unsupported goal {goal!r}")
        if self._pending is None and self._target[2] < self.params.table_z_m:
            self._pending = self._final(
                Status.INVALID_GOAL,
                f"goal z {self._target[2]:.3f} m is below the table top ({self.params.table_z_m} m)",
            )

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
            "nmpc_recoveries": self._recoveries,
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
        if self._request is None or self._scene is None:
            raise PlanningError(f"{type(self).__name__}.step() called before reset()")
        if self._done is not None:
            return self._done
        q = as_q(q, "q")
        P = self.params
        if self._pending is not None:
            self._done = self._pending
            return self._done
        if not self._started:
            self._started = True
            if self._scene.in_collision(q):
                pair = colliding_pair(self._scene, q)
                self._done = self._final(Status.INVALID_START, f"the start is in collision ({pair})", q)
                return self._done
        err = float(np.linalg.norm(self._tracked(q) - self._target))
        boxes = self._boxes()
        obj = self._object_spheres()
        sph = with_object(self._robot_sph, obj)
        if err <= self._tolerance:
            # within the tolerance the NMPC stops solving; a moving arm first comes to rest within its limits
            # (`_stop_at_goal`), and the status follows once it stands
            if self._moving():
                knots = self._stop_at_goal(q, sph, boxes)
                if knots is not None:
                    return self._execute(knots, {"solve": self._solves, "braking": True, "fallback": False}, 0.0, err)
                log.warning(
                    "%s: at the goal but no way to come to rest within the limits; stopping from %.3f rad/step",
                    self.name,
                    float(np.abs(self._dq_prev).max()),
                )
            self._done = self._final(
                Status.SUCCESS, f"TCP within {err:.4f} m of the goal after {self._solves} solves", q
            )
            return self._done
        if self._solves >= P.max_solves:
            why = f"goal not reached after {self._solves} solves: TCP {err:.3f} m away (tolerance {self._tolerance} m)"
            return self._end(Status.NO_SOLUTION, why, q)

        for name, lo, hi in boxes:
            if np.any(np.all((self._target >= lo) & (self._target <= hi))):
                return self._end(Status.INVALID_GOAL, f"the goal lies inside obstacle box {name!r}", q)
        clear = clearance(self.kin, q[None], sph, boxes, margin=0.0)
        if clear.size and clear.min() < 0.0 and self._refuses_sphere_overlap():
            when = "at the start" if self._solves == 0 else f"at the state measured for solve {self._solves + 1}"
            why = f"a proxy sphere is {-clear.min():.3f} m inside an obstacle box {when}"
            return self._end(Status.INVALID_START, why, q)

        shifted_by, off = self._ws_offset, self._off_commanded(q)
        sol = self._solve(q, boxes, obj, sph)
        self._solves += 1
        entry = {"solve": self._solves, "warm": sol.warm, "time_s": sol.time_s, **sol.log}
        if sol.warm:  # how far the warm start was shifted, and how far the measured state is off the commanded knot
            entry.update(shifted_by=shifted_by, off_commanded_rad=off)
        self._solve_log.append(entry)

        k = P.execute_steps
        problem = sol.problem
        if problem is None and sol.plan is not None:
            problem = self._violation(sol.plan, sph, boxes)
        if problem is None and sol.plan is not None:
            self._plan, self._plan_idx = sol.plan, 0
            self._ws, self._ws_offset = sol.warm_start, 0
            knots = sol.plan[: k + 1].copy()
            fallback = False
        else:
            problem = problem or "no plan"
            entry["rejected"] = problem
            log.info("%s: solve %d rejected (%s)", self.name, self._solves, problem)
            if self._plan is None and not sol.warm and sol.guess is not None:
                # the first solve of a goal failed: its initial guess is itself a plan over the box, at
                # reduced speed; it is followed (as the "last feasible plan") only if it passes the same check
                path = np.vstack([q[None], sol.guess])
                if self._violation(path, sph, boxes) is None:
                    self._plan, self._plan_idx = path, 0
                    entry["following"] = "initial guess"
            self._ws = None  # the next solve starts cold, from a fresh guess at the state reached
            knots, fallback = self._fallback_knots(q, sph, boxes, k), True
            if knots is None:
                why = f"solve {self._solves} failed ({problem}) and no feasible plan is left to follow"
                if self._moving() and self._solves < P.max_solves:
                    recovered = self._recover(q, why, err, sph, boxes)
                    if recovered is not None:
                        return recovered
                return self._end(Status.NO_SOLUTION, why, q)
            self._fallbacks += 1
        knots[0] = q
        entry["fallback"] = fallback
        return self._execute(knots, dict(entry, cost=sol.cost), sol.time_s, err)

    def _shifted(self, knots: np.ndarray, k: int) -> np.ndarray:
        """The plan `knots` (N+1, 6) k steps on (N+1, 6): its knots from the k-th, then k past its horizon that go
        on slowing down within the step, acceleration and jerk bounds (`braking.slowing_steps`). A plan may still
        move at its horizon (a warehouse transfer's did, at 0.06 rad per step): its last knot repeated, a zero
        step, broke the last stages' acceleration and jerk rows, and a warm solve from there took 12-18 IPOPT
        iterations where the bench's took 2."""
        N = knots.shape[0] - 1
        k = min(k, N)
        if k == 0 or N < 2:
            return np.vstack([knots[k:], np.repeat(knots[-1:], k, axis=0)])
        step, dstep, jstep = self._step_bounds()
        d2, d1 = np.diff(knots[-3:], axis=0)
        tail = knots[-1] + np.cumsum(slowing_steps(d2, d1, k, step, dstep, jstep), axis=0)
        return np.vstack([knots[k:], tail])

    def _off_commanded(self, q: np.ndarray) -> float:
        """How far (max per joint, rad) the measured state `q` is from the knot the arm was commanded to (0 before
        the first segment): a physics controller's tracking lag; 0 on the kinematic model."""
        return 0.0 if self._commanded is None else float(np.abs(q - self._commanded).max())

    def _cold_guess(self, q: np.ndarray, boxes: list[Box], sph: np.ndarray) -> np.ndarray:
        """The initial guess of a cold solve from `q` (`twin.planning.guess`); says which in `_guess_kind`."""
        step, dstep, jstep = self._step_bounds()
        guess, self._guess_kind = initial_guess(
            self.kin, self.params, q, self._target, self._track, self._goal_candidates, boxes, sph, step, dstep, jstep
        )
        return guess

    # ---- executing, checked -------------------------------------------------------------------------
    def _execute(
        self, knots: np.ndarray, info: dict[str, Any], solve_time_s: float, err: float
    ) -> Segment | MotionResult:
        """Command `knots` (m+1, 6), knots[0] = the measured state, if they are free in the FCL scene and the
        last plan is free for as far beyond them as the arm needs to stop; else brake (`_end`)."""
        traj = self._segment(knots)
        hit = self._collision(traj)
        braking = bool(info.get("braking"))
        if hit is None and not braking:
            ahead = self._collision_ahead(knots)
            if ahead is not None:
                pair, n = ahead
                why = f"the plan runs into a collision ({pair}) within {n} step{'' if n == 1 else 's'}"
                if self._recovers_blocked_segments and self._moving() and self._solves < self.params.max_solves:
                    # as for a blocked segment: to rest by a free stop, and a cold solve from there (stress seed
                    # 1160: a warm plan bent the upper arm into the held cube, held across two edges)
                    recovered = self._recover(knots[0], why, err, self.spheres(), self._boxes())
                    if recovered is not None:
                        return recovered
                return self._end(Status.COLLISION, why, knots[0], hit=True)
        elif hit is not None:
            kind = "braking segment" if braking else ("fallback segment" if info.get("fallback") else "segment")
            return self._end(Status.COLLISION, f"the next {kind} would collide ({hit})", knots[0], hit=True)
        stop: np.ndarray | None = None
        if not braking:
            stop, blocked = self._stop_after(knots)
            if stop is None:
                kind = "fallback segment" if info.get("fallback") else "segment"
                why = f"the next {kind} would leave no free way to stop at its end ({blocked})"
                if self._recovers_blocked_segments and self._moving() and self._solves < self.params.max_solves:
                    # a brake from here is free (checked when the last segment was commanded): to rest, solve again
                    # (a fallback's steps from a lagged state, seed 110: "cube with obstacle" from its end)
                    recovered = self._recover(knots[0], why, err, self.spheres(), self._boxes())
                    if recovered is not None:
                        return recovered
                return self._end(Status.COLLISION, why, knots[0], hit=True)
        self._commit(knots)
        self._safe_stop = stop
        if braking:
            self._braking_steps += knots.shape[0] - 1
        return Segment(traj, solve_time_s, dict(info, position_error_m=err), fallback=bool(info.get("fallback", False)))

    def _recover(self, q: np.ndarray, why: str, err: float, sph: np.ndarray, boxes: list[Box]) -> Segment | None:
        """A moving arm whose solve failed with no plan left to follow brakes to rest (a free stop: the shortest, or
        the one kept from the last segment's end) and the loop solves again from there, cold; None without a free
        stop. From a measured state off the commanded one (a controller lagging 50 ms: ~0.07 rad behind at
        speed), with the step it was commanded, the rows near a box can leave no plan within the step and
        acceleration bounds, and the last plan's next steps do not pass from there either; from rest they can.
        Of the free stops, one that passes the constraint check is taken first; a formulation whose rows hold a
        proxy sphere that starts inside a box no deeper (`_refuses_sphere_overlap` False: croc) then takes any
        stop FCL passes. Near the warehouse wall no stop passed the constraint check (the shortest stop heads on
        into the wall: a proxy sphere 1 cm inside its box, the gripper clear of it). Counted in
        `nmpc_recoveries`; `max_solves` bounds how often."""
        stops = [k for k in (self._brake_knots(q), *self._kept_stop(q)) if k is not None]
        checked: list[np.ndarray | None] = [k for k in stops if self._violation(k, sph, boxes) is None]
        starts: list[np.ndarray] = [] if self._refuses_sphere_overlap() else stops
        knots, _ = self._free_stop(q, [*checked, *starts] or [None])
        if knots is None:
            return None
        log.info("%s: %s; braking to solve again from rest", self.name, why)
        traj = self._segment(knots)
        self._commit(knots)
        self._safe_stop = None
        self._plan, self._plan_idx = None, 0
        self._braking_steps += knots.shape[0] - 1
        self._recoveries += 1
        info = {"solve": self._solves, "braking": True, "fallback": False, "recovering": why}
        return Segment(traj, 0.0, dict(info, position_error_m=err))

    def _end(self, status: Status, reason: str, q: np.ndarray, *, hit: bool = False) -> Segment | MotionResult:
        """End the goal with `status`: a moving arm first brakes to rest (a braking segment: the shortest stop, or
        else the stop kept free from the last segment's end; the status follows at the next step), else the
        status now. `hit`: the reason is a collision ahead (the braking segment is what avoids it)."""
        if self._moving():
            knots, pair = self._free_stop(q, [self._brake_knots(q), *self._kept_stop(q)])
            if knots is not None:
                traj = self._segment(knots)
                self._commit(knots)
                self._safe_stop = None
                self._braking_steps += knots.shape[0] - 1
                what = "braked to a stop" if hit else "braked to a stop first"
                self._pending = self._final(status, f"{reason}; {what}", knots[-1])
                info = {"solve": self._solves, "braking": True, "fallback": False, "stopping": status.value}
                err = float(np.linalg.norm(self._tracked(q) - self._target))
                return Segment(traj, 0.0, dict(info, position_error_m=err))
            reason += f"; no free way to brake ({pair}): stopped at once"
            log.warning("%s: %s", self.name, reason)
        self._done = self._final(status, reason, q)
        return self._done

    # ---- what a formulation may say -----------------------------------------------------------------
    def _refuses_sphere_overlap(self) -> bool:
        """Whether a measured state with a proxy sphere inside a box is refused (invalid_start): the seed's spheres
        are generous, but its NLP cannot start inside a box. A formulation whose rows let a sphere that starts
        inside stay as deep (not deeper) may say no; the FCL check of the start decides then."""
        return True
