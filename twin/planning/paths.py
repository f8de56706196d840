"""What every path planner does around its search: check the start, turn the goal into goal configurations,
keep a clearance, and time and check the path it found.

Why in the core: the OMPL planners (`twin_ompl`) and the compiled planner (`twin_compiled`) search differently
but must agree on everything else, or a comparison compares more than the search. Exported through
`twin.plugin`.

* `start_failure`: a start outside the limits or in collision is INVALID_START, with what it hits.
* `goal_set`: a joint goal inside the limits and free; a pose goal as every free IK solution (all 2 pi
  wraps) inside the sampling bounds, nearest to the start first; else INVALID_GOAL saying why.
* `sampling_bounds`: 'compact' = [-pi, pi] per joint widened to start +- pi and to a joint goal, clipped to
  the limits (every IK branch keeps a representative within pi of the start in each joint, and the sampled
  volume is ~1/20 of the full +-2 pi box); 'full' = the joint limits.
* `padded_scene`: the scene with its environment inflated by a clearance, cached.
* `timed_and_checked`: a retimer times the path; the trajectory is checked on the scene at a fine
  resolution; a straight segment found colliding is reported (for the planner to plan again), and a
  timing spline that cuts a corner of a free path is timed again through denser waypoints. The check asks
  the scene's planning model first: where it proves the trajectory's polyline free in one continuous pass,
  FCL would find none of the check's configurations colliding, so it is not asked (the same verdict, ~1/3 of
  the time on the OMPL bench's blocked queries); elsewhere FCL checks every configuration as before.
  `warm_up_checks` loads that pass's compiled kernel when a planner is built, not inside a request's limit.
"""

from __future__ import annotations

import logging
import math
import time
import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from twin.errors import TwinError
from twin.planning.checked import colliding_pair, densify_path
from twin.types import JointGoal, Limits, MotionRequest, PoseGoal, Status

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.planning.checked import Retimer
    from twin.robot.kinematics import URArm
    from twin.robot.robot import Robot
    from twin.types import Trajectory

__all__ = [
    "PathPlannerParams",
    "QueryEnds",
    "add_time",
    "goal_set",
    "padded_scene",
    "path_length",
    "query_ends",
    "sampling_bounds",
    "start_failure",
    "timed_and_checked",
    "trajectory_check_points",
    "warm_up_checks",
    "warm_up_retimer",
]

log = logging.getLogger("twin")


class PathPlannerParams(BaseModel):
    """Options every path planner built on these steps takes (units in the names; None = derived): the OMPL
    planners' and `compiled.rrtconnect`'s parameter models extend it."""

    model_config = ConfigDict(extra="forbid")

    time_limit_s: float | None = Field(
        None, gt=0, description="cap on the planning time; the request's time_limit_s applies when smaller or when None"
    )
    joint_range: Literal["compact", "full"] = Field(
        "compact",
        description=(
            "sampling bounds: 'compact' = [-pi, pi] per joint widened to start +- pi and to the joint goal "
            "(every IK branch keeps a representative); 'full' = the joint limits (+-2pi, elbow +-pi)"
        ),
    )
    clearance_m: float = Field(
        0.005,
        ge=0,
        le=0.05,
        description=(
            "planning and the final check keep this distance to the environment (obstacles inflated); "
            "0 = plan on the scene as given. A query whose start or goal lies closer is planned without it"
        ),
    )
    verify_resolution_rad: float = Field(
        0.002, ge=0, le=0.1, description="joint step of the final check of the timed trajectory; 0 = no final check"
    )
    verify_resolution_m: float = Field(
        0.004,
        gt=0,
        le=0.05,
        description="TCP travel resolution of the final check (checked every half of it, as twin.planning does)",
    )
    max_goal_states: int = Field(
        64, ge=1, le=512, description="most IK solutions of a pose goal put in the goal set (nearest first)"
    )
    retimer: str = Field(
        "toppra", description="retimer plugin that turns the path into a trajectory (a config block's retimer: wins)"
    )
    retimer_params: dict[str, Any] = Field(default_factory=dict, description="parameters of that retimer")


@dataclass(frozen=True)
class QueryEnds:
    """A query's checked ends: the start (6,), the sampling bounds (6, 2) and the goal configurations (k, 6)."""

    start: np.ndarray
    bounds: np.ndarray
    goals: np.ndarray


def query_ends(
    kin: URArm, scene: PlanningScene, request: MotionRequest, params: PathPlannerParams
) -> QueryEnds | tuple[Status, str]:
    """The start checked (`start_failure`), the sampling bounds of `params.joint_range`, and the goal set
    (`goal_set`); or the refusal (INVALID_START, INVALID_GOAL) and why."""
    start = np.array(request.start, dtype=float)
    refused = start_failure(kin, scene, start)
    if refused is not None:
        return refused
    joint_goal = np.array(request.goal.q, dtype=float) if isinstance(request.goal, JointGoal) else None
    bounds = sampling_bounds(kin, start, joint_goal, params.joint_range)
    goals, failure = goal_set(
        kin, scene, request, bounds, max_goals=params.max_goal_states, joint_range=params.joint_range
    )
    if failure is not None:
        return failure
    assert goals is not None
    return QueryEnds(start, bounds, goals)


# waypoint spacings (rad) tried in turn when the timed trajectory cuts a corner of a free path; None: as planned
_RETIME_SPACINGS: tuple[float | None, ...] = (None, 0.02, 0.005)


def add_time(timings: dict[str, float], key: str, since: float) -> None:
    """Add the seconds since `since` (a perf_counter reading) to `timings[key]`."""
    timings[key] = timings.get(key, 0.0) + time.perf_counter() - since


def path_length(path: np.ndarray) -> float:
    """Joint-space length of a waypoint path (m, 6): sum of the L2 norms of its segments, rad."""
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) if path.shape[0] > 1 else 0.0


def sampling_bounds(kin: URArm, start: np.ndarray, joint_goal: np.ndarray | None, joint_range: str) -> np.ndarray:
    """(6, 2) sampling bounds in rad for `joint_range` 'compact' or 'full' (see the module docstring)."""
    lim = np.asarray(kin.joint_limits, dtype=float)
    if joint_range == "full":
        return lim.copy()
    lo = np.minimum(-math.pi, start - math.pi)
    hi = np.maximum(math.pi, start + math.pi)
    if joint_goal is not None:
        lo, hi = np.minimum(lo, joint_goal), np.maximum(hi, joint_goal)
    return np.stack([np.maximum(lo, lim[:, 0]), np.minimum(hi, lim[:, 1])], axis=1)


def start_failure(kin: URArm, scene: PlanningScene, start: np.ndarray) -> tuple[Status, str] | None:
    """INVALID_START and why, for a start outside the joint limits or in collision; None for a good start."""
    if not kin.within_limits(start):
        lo, hi = kin.joint_limits[:, 0], kin.joint_limits[:, 1]
        j = int(np.argmax(np.maximum(lo - start, start - hi)))
        return Status.INVALID_START, f"start joint {j + 1} = {start[j]:.3f} rad is outside [{lo[j]:.3f}, {hi[j]:.3f}]"
    if scene.in_collision(start):
        return Status.INVALID_START, f"the start configuration is in collision ({colliding_pair(scene, start)})"
    return None


def goal_set(
    kin: URArm, scene: PlanningScene, request: MotionRequest, bounds: np.ndarray, *, max_goals: int, joint_range: str
) -> tuple[np.ndarray | None, tuple[Status, str] | None]:
    """((k, 6) collision-free goal configurations inside `bounds`, nearest to the start first, at most
    `max_goals`; None) or (None, (INVALID_GOAL, why)). `joint_range` names the bounds in a refusal."""
    start, goal = request.start, request.goal
    if isinstance(goal, JointGoal):
        q = np.array(goal.q, dtype=float)
        if not kin.within_limits(q):
            return None, (Status.INVALID_GOAL, "the joint goal is outside the joint limits")
        if scene.in_collision(q):
            return None, (Status.INVALID_GOAL, f"the joint goal is in collision ({colliding_pair(scene, q)})")
        return q[None], None
    assert isinstance(goal, PoseGoal)
    if goal.frame not in ("tcp", "flange"):
        return None, (Status.INVALID_GOAL, f"unknown goal frame {goal.frame!r}; allowed: tcp, flange")
    sols = kin.ik(goal.pose.matrix(), goal.frame)
    if sols.shape[0] == 0:
        return None, (Status.INVALID_GOAL, "the goal pose has no IK solution (out of reach)")
    inside = np.all((sols >= bounds[:, 0] - 1e-9) & (sols <= bounds[:, 1] + 1e-9), axis=1)
    sols = sols[inside]
    if sols.shape[0] == 0:  # cannot happen for 'compact' (every branch has a wrap in [-pi, pi])
        return None, (
            Status.INVALID_GOAL,
            f"no IK solution of the goal pose lies inside the sampling bounds ({joint_range})",
        )
    sols = sols[np.argsort(np.abs(sols - start).max(axis=1), kind="stable")]
    hits = scene.in_collision_batch(sols)
    free = sols[~hits]
    if free.shape[0] == 0:
        return None, (
            Status.INVALID_GOAL,
            f"all {sols.shape[0]} IK solutions of the goal pose collide (e.g. {colliding_pair(scene, sols[0])})",
        )
    return free[:max_goals], None


def trajectory_check_points(traj: Trajectory, kin: URArm, step_rad: float, step_m: float) -> np.ndarray:
    """(k, 6) configurations along `traj` no more than `step_rad` apart in any joint and `step_m / 2` apart
    in TCP position (the factor 2 is `twin.planning.densify`'s margin for chords), end points included.

    The trajectory's own samples are dense (1 kHz), so configurations between them are interpolated
    linearly over a cumulative "resolution units" parameter instead of re-evaluating the spline.
    """
    q = traj.q
    if q.shape[0] == 1:
        return q.copy()
    dq = np.abs(np.diff(q, axis=0)).max(axis=1) / step_rad
    p = kin.fk_batch(q)[:, :3, 3]
    dp = 2.0 * np.linalg.norm(np.diff(p, axis=0), axis=1) / step_m
    u = np.concatenate(([0.0], np.cumsum(np.maximum(dq, dp) + 1e-12)))
    n = max(1, math.ceil(u[-1] - 1e-9))
    targets = np.linspace(0.0, u[-1], n + 1)
    return np.stack([np.interp(targets, u, q[:, j]) for j in range(6)], axis=1)


def timed_and_checked(
    path: np.ndarray,
    retimer: Retimer,
    request: MotionRequest,
    scene: PlanningScene,
    kin: URArm,
    verify_rad: float,
    verify_m: float,
    timings: dict[str, float],
) -> tuple[Trajectory | None, str, int | None]:
    """Time `path` (m, 6) with `retimer` under the request's limits and check it on `scene` every
    `verify_rad` / `verify_m` (`verify_rad` <= 0: no check).

    (trajectory, "ok", None) when the timed path passes the check; else (None, why, segment) with `segment`
    the index of a straight path segment that itself collides (None: the path is free but its timing spline
    cuts a corner even through a denser path, or retiming failed). Adds "retime" and "verify" seconds to
    `timings`."""
    last = ""
    for spacing in _RETIME_SPACINGS:
        P = path if spacing is None else densify_path(path, spacing)
        t = time.perf_counter()
        try:
            traj = retimer.retime(P, request.limits)
        except TwinError as e:
            add_time(timings, "retime", t)
            return None, f"retiming failed: {e}", None
        add_time(timings, "retime", t)
        if verify_rad <= 0:
            return traj, "ok", None
        t = time.perf_counter()
        if _proven_free(scene, traj):
            add_time(timings, "verify", t)
            return traj, "ok", None
        qs = trajectory_check_points(traj, kin, verify_rad, verify_m)
        hit = scene.first_collision(qs)
        if hit is None:
            add_time(timings, "verify", t)
            return traj, "ok", None
        # the path itself (missed between the states checked while planning) or the spline's corner?
        check = scene.check_path(path, resolution_rad=verify_rad)
        add_time(timings, "verify", t)
        if not check.free:
            assert check.segment is not None
            return None, f"path segment {check.segment} collides at {verify_rad:g} rad", check.segment
        last = f"the timed trajectory collides ({colliding_pair(scene, qs[hit])}) while its path is free"
    return None, last, None


_WARM: list[bool] = []  # the polyline proof's kernel is loaded in this process


def warm_up_checks(robot: Robot) -> None:
    """Load (the first time on a machine: compile, seconds) the compiled kernel `timed_and_checked`'s proof
    uses, once per process, on the robot alone (every call's argument types are the same): a planner calls
    this when it is built, so that no request pays it inside its time limit."""
    if _WARM:
        return
    from twin.collision import PlanningScene  # lazy: fcl

    q = np.zeros(6)
    PlanningScene(robot).sphere_model().first_unproven_segment(np.stack([q, q + 0.1]))
    _WARM.append(True)


_WARM_RETIMERS: set[type] = set()  # retimer classes that timed a path in this process


def warm_up_retimer(retimer: Retimer) -> None:
    """Time one tiny path with `retimer`, once per retimer class and process: its first-use imports (TOPP-RA
    ~1 s) are then paid when a planner is built, not inside a request's time limit, and a sweep that builds a
    planner per run pays them once."""
    if type(retimer) in _WARM_RETIMERS:
        return
    try:
        retimer.retime(np.array([np.zeros(6), np.full(6, 0.1)]), Limits.uniform(1.0, 1.0, 10.0))
    except Exception as e:  # noqa: BLE001 - the real call reports problems with the request at hand
        log.debug("retimer warm-up failed: %r", e)
    _WARM_RETIMERS.add(type(retimer))


def _proven_free(scene: PlanningScene, traj: Trajectory) -> bool:
    """True when the scene's planning model proves the polyline through the trajectory's samples free in one
    continuous pass (`SphereModel.first_unproven_segment`). The fine check's configurations all lie on that
    polyline and the model never calls free what FCL calls colliding, so FCL would find none of them
    colliding: the check's verdict, without asking it. False (FCL decides) where it cannot prove it, for a
    scene with its sphere filter off (FCL checks everything there) and for an object that is not a planning
    scene (a test double)."""
    from twin.collision import PlanningScene  # lazy: fcl

    if not isinstance(scene, PlanningScene) or not scene.sphere_filter or traj.q.shape[0] < 2:
        return False
    return scene.sphere_model().first_unproven_segment(traj.q) is None


# ---- clearance: the same scene with the environment inflated ------------------------------------------------
_PADDED: weakref.WeakKeyDictionary[PlanningScene, tuple[Any, PlanningScene]] = weakref.WeakKeyDictionary()


def _signature(scene: PlanningScene) -> tuple[Any, ...]:
    boxes = tuple((n, sz.tobytes(), T.tobytes()) for n, (sz, T) in sorted(scene.boxes().items()))
    held = scene.attached_box()
    held_sig = None if held is None else (held[0], held[1].tobytes(), held[2].tobytes())
    return (
        tuple(scene.names()),
        boxes,
        held_sig,
        float(scene.gripper_opening),
        float(scene.padding_m),
        scene.sphere_filter,
    )


def padded_scene(scene: PlanningScene, clearance_m: float) -> PlanningScene | None:
    """A copy of `scene` whose environment (fixtures, boxes) is inflated by `clearance_m` more
    (`PlanningScene.padded`), or None for an object that is not a planning scene (a test double).

    Why: discrete checks (any resolution) can pass a path that grazes an obstacle by a fraction of a
    millimetre between two checked states; a finer check then finds it, and execution in the world would
    touch it. Planning and the final check on the inflated scene keep that margin instead. The copy is
    cached per scene and made again when the scene's boxes, held object, finger opening, padding or sphere
    filter change.
    """
    from twin.collision import PlanningScene  # lazy: fcl

    if not isinstance(scene, PlanningScene):
        return None
    sig = _signature(scene) + (float(clearance_m),)
    cached = _PADDED.get(scene)
    if cached is not None and cached[0] == sig:
        return cached[1]
    copy = scene.padded(clearance_m)
    _PADDED[scene] = (sig, copy)
    return copy
