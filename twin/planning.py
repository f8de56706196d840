"""The planning API: one call plans one request with any registered planner, and checks the result.

Planners never touch PyBullet: they get a `MotionRequest`, the kinematics (in their context) and an FCL
`PlanningScene`. Whatever a planner returns, `plan()` re-checks the trajectory against the scene at a
resolution of at most `collision.check_resolution_m` of TCP travel and `check_resolution_rad` per joint,
and checks its endpoints; a colliding trajectory is turned into a COLLISION result, never a success.
"""

from __future__ import annotations

import logging

import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from twin.errors import InvalidRequestError, PlanningError
from twin.registry import PluginContext, Registry, default_registry
from twin.types import JointGoal, Limits, MotionRequest, MotionResult, PoseGoal, Status, Trajectory

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.config import PlannerBlock, Settings
    from twin.kinematics import UR5e

__all__ = [
    "OneShotPlanner",
    "RecedingHorizonPlanner",
    "Retimer",
    "Segment",
    "limits_from_settings",
    "make_context",
    "make_planner",
    "plan",
    "plan_with",
    "densify",
    "first_collision",
]

log = logging.getLogger("twin")


@runtime_checkable
class OneShotPlanner(Protocol):
    """Plans a whole trajectory at once."""

    def plan(self, request: MotionRequest, scene: "PlanningScene") -> MotionResult: ...


@dataclass(frozen=True)
class Segment:
    """A piece of motion a receding-horizon planner commands before it is asked again."""

    trajectory: Trajectory
    solve_time_s: float
    info: dict[str, Any]


@runtime_checkable
class RecedingHorizonPlanner(Protocol):
    """Plans a short segment from the latest measured state, again and again, until done."""

    def reset(self, request: MotionRequest, scene: "PlanningScene") -> None: ...

    def step(self, q: np.ndarray) -> Segment | MotionResult:
        """The next segment from measured joint state `q` (6,), or a final MotionResult when done."""
        ...


@runtime_checkable
class Retimer(Protocol):
    """Turns a geometric joint path (m, 6) into a trajectory under joint limits."""

    def retime(self, path: np.ndarray, limits: Limits) -> Trajectory: ...


def limits_from_settings(settings: "Settings", *, tcp_speed: float | None = None) -> Limits:
    r = settings.robot
    return Limits.uniform(r.max_joint_vel, r.max_joint_acc, r.max_joint_jerk, tcp_speed)


def make_context(settings: "Settings", registry: Registry | None = None, kinematics: "UR5e | None" = None) -> PluginContext:
    from twin.kinematics import UR5e

    return PluginContext(settings=settings, kinematics=kinematics or UR5e(), registry=registry or default_registry())


def make_planner(block: "PlannerBlock | str", context: PluginContext) -> Any:
    """Instantiate a planner from a config block `{name, params}` or a bare name."""
    from twin.config import PlannerBlock

    if isinstance(block, str):
        block = PlannerBlock(name=block)
    planner = context.registry.planner(block.name, block.params, context)
    if block.retimer is not None:
        if not hasattr(planner, "set_retimer"):
            from twin.errors import ConfigError

            raise ConfigError(f"planner {block.name!r} produces trajectories itself and takes no retimer")
        planner.set_retimer(context.registry.retimer(block.retimer, block.retimer_params, context))
    return planner


# ---- trajectory checks ----------------------------------------------------------------------------
def densify(traj: Trajectory, kin: "UR5e", *, max_step_rad: float, max_step_m: float) -> np.ndarray:
    """(k, 6) configurations along `traj`, no joint moving more than `max_step_rad` and the TCP no more
    than `max_step_m` between neighbours.

    Motion is measured in "units" per sample interval, max(|dq|/max_step_rad, 2 |dp|/max_step_m) (a
    factor 2 on TCP travel because chords under-estimate arcs); check points are spaced one unit apart
    along the accumulated units, so a dense 1 kHz trajectory is thinned and a coarse one subdivided.
    """
    if traj.q.shape[0] == 1:
        return traj.q.copy()
    ts, q = traj.t, traj.q
    for _ in range(6):  # a coarse trajectory's chords hide its arcs: re-measure on the new points
        dq = np.abs(np.diff(q, axis=0)).max(axis=1)
        p = kin.fk_batch(q)[:, :3, 3]
        dp = np.linalg.norm(np.diff(p, axis=0), axis=1)
        if ts is not traj.t and dq.max() <= max_step_rad and dp.max() <= max_step_m:
            return q
        units = np.concatenate(([0.0], np.cumsum(np.maximum(dq / max_step_rad, 2.0 * dp / max_step_m))))
        n = max(1, int(np.ceil(units[-1] - 1e-9)))
        ts = np.interp(np.linspace(0.0, units[-1], n + 1), units, ts)
        ts[0], ts[-1] = traj.t[0], traj.t[-1]
        q, _, _ = traj.sample(ts)
    return q


def first_collision(traj: Trajectory, scene: "PlanningScene", kin: "UR5e", *, max_step_rad: float = 0.01, max_step_m: float = 0.01) -> int | None:
    """Index (into the densified samples) of the first colliding configuration, or None if free."""
    qs = densify(traj, kin, max_step_rad=max_step_rad, max_step_m=max_step_m)
    hits = scene.in_collision_batch(qs)
    idx = np.flatnonzero(hits)
    return int(idx[0]) if idx.size else None


def _goal_error(request: MotionRequest, q_end: np.ndarray, kin: "UR5e") -> float:
    if isinstance(request.goal, JointGoal):
        return float(np.abs(q_end - request.goal.q).max())
    T = kin.fk(q_end, request.goal.frame)
    G = request.goal.pose.matrix()
    rot = np.linalg.norm(T[:3, :3] - G[:3, :3])
    return float(max(np.linalg.norm(T[:3, 3] - G[:3, 3]), rot))


def _goal_position_error(request: MotionRequest, q_end: np.ndarray, kin: "UR5e") -> float:
    """Distance (m) of the goal frame's origin at q_end from the goal position (a joint goal: its TCP)."""
    if isinstance(request.goal, JointGoal):
        target, frame = kin.fk(request.goal.q, "tcp")[:3, 3], "tcp"
    else:
        target, frame = np.asarray(request.goal.pose.position, dtype=float), request.goal.frame
    return float(np.linalg.norm(kin.fk(q_end, frame)[:3, 3] - target))


def _rollout(planner: RecedingHorizonPlanner, request: MotionRequest, scene: "PlanningScene", max_segments: int = 1000) -> MotionResult:
    """Run a receding-horizon planner on the kinematic model (each segment executed exactly)."""
    planner.reset(request, scene)
    q = request.start
    pieces: list[Trajectory] = []
    solve_times: list[float] = []
    for _ in range(max_segments):
        out = planner.step(q)
        if isinstance(out, MotionResult):
            traj = _concat(pieces) if pieces else None
            info = dict(out.info, solve_times_s=solve_times, solves=len(solve_times))
            if out.status is Status.SUCCESS:
                if traj is None:
                    traj = Trajectory(np.zeros(1), q[None], np.zeros((1, 6)), np.zeros((1, 6)))
                return replace(out, trajectory=traj, info=info)
            return replace(out, trajectory=None, info=info)
        pieces.append(out.trajectory)
        solve_times.append(out.solve_time_s)
        q = out.trajectory.q[-1]
    return MotionResult(Status.NO_SOLUTION, f"no end after {max_segments} segments")


def _concat(pieces: list[Trajectory]) -> Trajectory:
    t, q, qd, qdd = [pieces[0].t], [pieces[0].q], [pieces[0].qd], [pieces[0].qdd]
    offset = pieces[0].t[-1]
    for p in pieces[1:]:
        t.append(p.t[1:] - p.t[0] + offset)
        q.append(p.q[1:])
        qd.append(p.qd[1:])
        qdd.append(p.qdd[1:])
        offset = t[-1][-1] if t[-1].size else offset
    return Trajectory(np.concatenate(t), np.concatenate(q), np.concatenate(qd), np.concatenate(qdd))


def plan_with(planner: Any, request: MotionRequest, scene: "PlanningScene", context: PluginContext) -> MotionResult:
    """Plan `request` with an instantiated planner, time it, and check what it returns."""
    t0 = time.perf_counter()
    if isinstance(planner, OneShotPlanner):
        result = planner.plan(request, scene)
    elif isinstance(planner, RecedingHorizonPlanner):
        result = _rollout(planner, request, scene)
    else:
        raise PlanningError(f"{type(planner).__name__} has neither plan() nor reset()/step()")
    elapsed = time.perf_counter() - t0
    if not isinstance(result, MotionResult):
        raise PlanningError(f"{type(planner).__name__}.plan returned {type(result).__name__}, not MotionResult")
    if not result.planning_time_s:
        result = replace(result, planning_time_s=elapsed)
    if not result.success:
        return result
    return _checked(result, request, scene, context)


def _checked(result: MotionResult, request: MotionRequest, scene: "PlanningScene", context: PluginContext) -> MotionResult:
    traj = result.trajectory
    assert traj is not None
    kin = context.kinematics
    col = context.settings.collision
    start_err = float(np.abs(traj.q[0] - request.start).max())
    if start_err > 1e-6:
        raise PlanningError(f"trajectory starts {start_err:.2e} rad away from the request's start")
    tol_m = result.info.get("goal_tolerance_m")
    if tol_m is not None:
        # a planner that stops near the goal by design (receding horizon: NMPC) declares its TCP tolerance
        goal_err = _goal_position_error(request, traj.q[-1], kin)
        if goal_err > float(tol_m) + 1e-9:
            return replace(result, status=Status.NO_SOLUTION, trajectory=None, reason=f"trajectory ends {goal_err:.4f} m from the goal (tolerance {tol_m} m)")
    else:
        goal_err = _goal_error(request, traj.q[-1], kin)
        if goal_err > 1e-6:
            return replace(result, status=Status.NO_SOLUTION, trajectory=None, reason=f"trajectory ends {goal_err:.2e} away from the goal")
    hit = first_collision(traj, scene, kin, max_step_rad=col.check_resolution_rad, max_step_m=col.check_resolution_m)
    if hit is not None:
        log.warning("planner returned a colliding trajectory; reported as COLLISION")
        return replace(result, status=Status.COLLISION, trajectory=None, reason=f"trajectory collides (checked sample {hit})")
    return result


def plan(
    settings: "Settings",
    planner: "PlannerBlock | str",
    request: MotionRequest,
    *,
    scene: "PlanningScene | None" = None,
    registry: Registry | None = None,
) -> MotionResult:
    """Plan one request with the planner named in `planner` (a config block or a name).

    Bad input (unknown name, bad parameter) raises a TwinError; "no solution" is a status in the result.
    """
    from twin.collision import PlanningScene

    context = make_context(settings, registry)
    p = make_planner(planner, context)
    if scene is None:
        scene = PlanningScene.from_settings(settings)
    if isinstance(request.goal, PoseGoal) and request.goal.frame not in ("tcp", "flange"):
        raise InvalidRequestError(f"unknown goal frame {request.goal.frame!r}; allowed: tcp, flange")
    return plan_with(p, request, scene, context)


