"""Joint-space point-to-point planners: `ruckig.movej` and the seed-002 baseline `seed.quintic_movej`.

Both take joint goals and pose goals (pose goals go through the defensive IK with the start as continuity
seed and the configured home posture as reference), sample their trajectory exactly every <= 1 ms, hit
both endpoints exactly, and check the result against the planning scene before calling it a success.

`MotionPlannerBase` holds what every planner of this plugin shares (start/goal validation, goal IK,
collision check of the final trajectory); the MoveL planners in `twin_motion.movel` use it too.
"""

from __future__ import annotations

import logging
import math
import time
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from twin.plugin import (
    JointGoal,
    MotionRequest,
    MotionResult,
    PoseGoal,
    Status,
    Trajectory,
    URArm,
    colliding_pair,
    densify,
    first_collision,
    wrap_to_pi,
)
from twin_motion.ik import DefensiveIK, DefensiveIKParams, IKResult
from twin_motion.retimers import RetimingFailed, ruckig_point_to_point, ruckig_samples

if TYPE_CHECKING:
    from twin.plugin import PlanningScene, PluginContext

__all__ = [
    "MotionPlannerBase",
    "QuinticMoveJ",
    "RuckigMoveJ",
    "quintic_duration",
    "sample_times",
    "stationary",
    "unwrap_goal",
]

log = logging.getLogger("twin")

_FRAMES = ("tcp", "flange")


def sample_times(duration: float, dt: float) -> np.ndarray:
    """0 .. duration inclusive, evenly spaced, no gap longer than `dt`."""
    n = max(1, math.ceil(duration / dt - 1e-9))
    return np.linspace(0.0, duration, n + 1)


def stationary(q: np.ndarray) -> Trajectory:
    """A one-sample trajectory that stays at `q` (start == goal)."""
    q = np.asarray(q, dtype=float).reshape(1, 6)
    return Trajectory(np.zeros(1), q.copy(), np.zeros((1, 6)), np.zeros((1, 6)))


class MotionPlannerBase:
    """Shared plumbing of the MoveJ/MoveL planners: validation, goal IK, collision check, timing.

    Subclasses define `Params` (a pydantic model with at least `ik` and `sample_dt_s`) and `_plan`.
    """

    class Params(BaseModel):
        model_config = ConfigDict(extra="forbid")

        ik: DefensiveIKParams = Field(default_factory=DefensiveIKParams)
        sample_dt_s: float = Field(0.001, gt=0, le=0.05, description="sampling period of the trajectory")

    # each subclass narrows this to its own `Params` (the registry validates with that model)
    params: MotionPlannerBase.Params

    def __init__(self, params: MotionPlannerBase.Params | None, context: PluginContext):
        self.params = params if params is not None else self.Params()
        self.context = context  # the robot it plans for: no default arm (a UR10e config plans a UR10e)
        self.kin: URArm = context.kinematics
        settings = context.settings
        self.home = np.array(settings.robot.home, dtype=float)
        self.check_rad = float(settings.collision.check_resolution_rad)
        self.check_m = float(settings.collision.check_resolution_m)
        self.ik = DefensiveIK(self.kin, self.params.ik)

    # ---- the protocol -----------------------------------------------------------------------------
    def plan(self, request: MotionRequest, scene: PlanningScene) -> MotionResult:
        """Plan `request` in `scene`; "no solution" is a status with a reason, never an exception."""
        t0 = time.perf_counter()
        try:
            result = self._plan(request, scene)
        except RetimingFailed as e:
            result = MotionResult(Status.LIMIT_VIOLATION, str(e))
        return _with_time(result, time.perf_counter() - t0)

    def _plan(self, request: MotionRequest, scene: PlanningScene) -> MotionResult:
        raise NotImplementedError

    # ---- shared steps -----------------------------------------------------------------------------
    def check_start(self, request: MotionRequest, scene: PlanningScene) -> MotionResult | None:
        """INVALID_START if the start is outside the joint limits or in collision, else None."""
        q = request.start
        if not self.kin.within_limits(q):
            lo, hi = self.kin.joint_limits[:, 0], self.kin.joint_limits[:, 1]
            j = int(np.argmax(np.maximum(lo - q, q - hi)))
            return MotionResult(
                Status.INVALID_START, f"start joint {j + 1} = {q[j]:.3f} rad is outside [{lo[j]:.3f}, {hi[j]:.3f}]"
            )
        if scene.in_collision(q):
            return MotionResult(
                Status.INVALID_START, f"the start configuration is in collision ({colliding_pair(scene, q)})"
            )
        return None

    def goal_configuration(
        self, request: MotionRequest, scene: PlanningScene
    ) -> tuple[np.ndarray | None, MotionResult | None, IKResult | None]:
        """The goal as joint angles (6,): a joint goal as given, a pose goal through the defensive IK.

        Returns (q_goal, None, ik_result) or (None, failure result, ik_result).
        """
        goal = request.goal
        if isinstance(goal, JointGoal):
            q = np.array(goal.q, dtype=float)
            if not self.kin.within_limits(q):
                return None, MotionResult(Status.INVALID_GOAL, "the joint goal is outside the joint limits"), None
            if scene.in_collision(q):
                return (
                    None,
                    MotionResult(Status.INVALID_GOAL, f"the joint goal is in collision ({colliding_pair(scene, q)})"),
                    None,
                )
            return q, None, None
        assert isinstance(goal, PoseGoal)
        if goal.frame not in _FRAMES:
            return (
                None,
                MotionResult(Status.INVALID_GOAL, f"unknown goal frame {goal.frame!r}; allowed: tcp, flange"),
                None,
            )
        res = self.ik.solve(
            goal.pose.matrix(),
            request.start,
            self.home,
            frame=goal.frame,
            is_valid=lambda q: not scene.in_collision(q),
        )
        if not res.ok:
            return None, MotionResult(Status.INVALID_GOAL, f"no acceptable IK for the goal pose: {res.reason}"), res
        return np.array(res.q), None, res

    def point_to_point_goal(
        self, request: MotionRequest, scene: PlanningScene, *, unwrap_joint_goals: bool = False
    ) -> tuple[np.ndarray, dict[str, Any]] | MotionResult:
        """The goal configuration of a MoveJ (start checked, pose goals through the defensive IK, joint goals
        unwrapped when `unwrap_joint_goals` asks), or the typed failure."""
        bad = self.check_start(request, scene)
        if bad:
            return bad
        q_goal, bad, ik = self.goal_configuration(request, scene)
        if bad:
            return bad
        assert q_goal is not None
        if unwrap_joint_goals and isinstance(request.goal, JointGoal):
            q_goal = unwrap_goal(request.start, q_goal, self.kin)
        return q_goal, ({"ik": ik.reason} if ik else {})

    def finish(
        self,
        request: MotionRequest,
        scene: PlanningScene,
        traj: Trajectory,
        *,
        path: np.ndarray | None = None,
        info: dict[str, Any] | None = None,
    ) -> MotionResult:
        """SUCCESS with `traj`, unless it collides somewhere (checked at the configured resolution)."""
        hit = first_collision(traj, scene, self.kin, max_step_rad=self.check_rad, max_step_m=self.check_m)
        if hit is not None:
            q_hit = densify(traj, self.kin, max_step_rad=self.check_rad, max_step_m=self.check_m)[hit]
            return MotionResult(
                Status.COLLISION,
                f"the trajectory collides ({colliding_pair(scene, q_hit)}, densified sample {hit}, "
                f"checked every {self.check_rad:g} rad / {self.check_m:g} m)",
                path=path if path is not None else traj.q,  # the refused motion, for seeing why (twin replay)
                info=dict(info or {}),
            )
        return MotionResult(Status.SUCCESS, "ok", traj, path=path, info=dict(info or {}, duration_s=traj.duration))


def _with_time(result: MotionResult, elapsed: float) -> MotionResult:
    from dataclasses import replace

    return result if result.planning_time_s else replace(result, planning_time_s=elapsed)


def unwrap_goal(q_start: np.ndarray, q_goal: np.ndarray, kin: URArm) -> np.ndarray:
    """The goal with each continuous-range joint (range > 2*pi) moved to the shortest angular difference
    from the start, where that value is inside the joint limits (seed 002's joint unwrapping)."""
    out = np.array(q_goal, dtype=float)
    lo, hi = kin.joint_limits[:, 0], kin.joint_limits[:, 1]
    for j in range(6):
        if hi[j] - lo[j] <= 2.0 * math.pi + 1e-9:
            continue
        cand = q_start[j] + float(wrap_to_pi(q_goal[j] - q_start[j]))
        if lo[j] <= cand <= hi[j]:
            out[j] = cand
    return out


# ---- ruckig.movej ---------------------------------------------------------------------------------------
class RuckigMoveJ(MotionPlannerBase):
    """Time-optimal, jerk-limited point-to-point motion (Ruckig) under the request's vel/acc/jerk limits."""

    class Params(MotionPlannerBase.Params):
        synchronization: Literal["phase", "time"] = Field(
            "phase", description="phase: all joints on one straight joint-space line; time: only finish together"
        )
        unwrap_joint_goals: bool = Field(
            False,
            description="move joint goals by 2*pi to the shortest difference (the end is then the goal modulo 2*pi)",
        )

    params: Params

    def _plan(self, request: MotionRequest, scene: PlanningScene) -> MotionResult:
        ends = self.point_to_point_goal(request, scene, unwrap_joint_goals=self.params.unwrap_joint_goals)
        if isinstance(ends, MotionResult):
            return ends
        q_goal, info = ends
        if np.abs(q_goal - request.start).max() <= 1e-12:
            return self.finish(request, scene, stationary(request.start), info=info)
        rt = ruckig_point_to_point(request.start, q_goal, request.limits, synchronization=self.params.synchronization)
        ts = sample_times(rt.duration, self.params.sample_dt_s)
        q, qd, qdd = ruckig_samples(rt, ts)
        q[0], q[-1] = request.start, q_goal
        qd[0] = qd[-1] = qdd[0] = qdd[-1] = 0.0
        traj = Trajectory(ts, q, qd, qdd)
        return self.finish(request, scene, traj, path=np.array([request.start, q_goal]), info=info)


# ---- seed.quintic_movej ---------------------------------------------------------------------------------
_QUINTIC_PEAK_VEL = 1.875  # max s'(tau)
_QUINTIC_PEAK_ACC = 10.0 / math.sqrt(3.0)  # max |s''(tau)|, at tau = (3 -+ sqrt 3) / 6
_QUINTIC_PEAK_JERK = 60.0  # max |s'''(tau)|, at tau = 0 and 1


def quintic_duration(
    dq: np.ndarray, vel: np.ndarray, acc: np.ndarray | None = None, jerk: np.ndarray | None = None
) -> float:
    """Shortest T for q(t) = q0 + dq * s(t / T), s = 10t^3 - 15t^4 + 6t^5, within the limits given.

    Velocity alone is the seed's rule (1.875 |dq| / T <= v); with `acc` and `jerk` the peak acceleration
    5.774 |dq| / T^2 and jerk 60 |dq| / T^3 are kept too.
    """
    d = np.abs(np.asarray(dq, dtype=float))
    T = d * _QUINTIC_PEAK_VEL / vel
    if acc is not None:
        T = np.maximum(T, np.sqrt(d * _QUINTIC_PEAK_ACC / acc))
    if jerk is not None:
        T = np.maximum(T, np.cbrt(d * _QUINTIC_PEAK_JERK / jerk))
    return float(T.max())


class QuinticMoveJ(MotionPlannerBase):
    """Seed 002's MoveJ: quintic time scaling s(t) = 10t^3 - 15t^4 + 6t^5 along the joint-space line.

    The seed picks T so that the peak velocity 1.875 * dq / T stays under the joint limit. By default
    the peak acceleration and jerk are kept under the request's limits as well, so that the baseline is
    compared with Ruckig under the same limits; `respect_acc_jerk: false` reproduces the seed literally.
    """

    class Params(MotionPlannerBase.Params):
        respect_acc_jerk: bool = Field(True, description="also keep peak acceleration and jerk under the limits")
        min_duration_s: float = Field(0.0, ge=0, description="lower bound on the duration")
        unwrap_joint_goals: bool = Field(
            False,
            description="seed's joint unwrapping for joint goals (the end is then the goal modulo 2*pi)",
        )

    params: Params

    def _plan(self, request: MotionRequest, scene: PlanningScene) -> MotionResult:
        ends = self.point_to_point_goal(request, scene, unwrap_joint_goals=self.params.unwrap_joint_goals)
        if isinstance(ends, MotionResult):
            return ends
        q_goal, info = ends
        q0 = request.start
        dq = q_goal - q0
        if np.abs(dq).max() <= 1e-12:
            return self.finish(request, scene, stationary(q0), info=info)
        lim = request.limits
        if self.params.respect_acc_jerk:
            T = quintic_duration(dq, lim.max_joint_vel, lim.max_joint_acc, lim.max_joint_jerk)
        else:
            T = quintic_duration(dq, lim.max_joint_vel)
        T = max(T, self.params.min_duration_s)
        t = sample_times(T, self.params.sample_dt_s)
        tau = t / T
        s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
        sd = 30.0 * tau**2 * (1.0 - tau) ** 2 / T
        sdd = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau) / T**2
        q = q0 + np.outer(s, dq)
        qd = np.outer(sd, dq)
        qdd = np.outer(sdd, dq)
        q[0], q[-1] = q0, q_goal
        qd[0] = qd[-1] = qdd[0] = qdd[-1] = 0.0
        traj = Trajectory(t, q, qd, qdd)
        return self.finish(request, scene, traj, path=np.array([q0, q_goal]), info=info)
