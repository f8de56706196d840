"""The planning API: one call plans one request with any registered planner, and checks the result.

Planners never touch PyBullet: they get a `MotionRequest`, the kinematics (in their context) and an FCL
`PlanningScene`. Whatever the registry hands out goes through `make_planner`, which wraps it in a
`CheckedPlanner`: one-shot trajectories and every receding-horizon segment are re-checked against the
scene at a resolution of at most `collision.check_resolution_m` of TCP travel and `check_resolution_rad`
per joint, and against the request's joint velocity and acceleration limits (jerk too for a planner that
declares itself `jerk_limited`), before anything can execute them; every planner's end state is judged
against the goal's own tolerances (`goal_miss`). A colliding trajectory or segment becomes a COLLISION
result, one beyond the limits a LIMIT_VIOLATION, never a success and never a motion. `CheckedPlanner.drive`
is the one loop that plans and hands checked pieces to a plant: the kinematic model (`plan`) or the
simulated arm (`twin.executor`).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from twin.config import PlannerBlock
from twin.errors import ConfigError, InvalidRequestError, PlanningError, PluginCrashed, TwinError
from twin.limit_check import LIMIT_TOLERANCE, LimitExcess, limit_excess, stitched
from twin.registry import Kind, PluginContext, Registry, default_registry
from twin.robot import Robot
from twin.robot.ur_models import ur_model
from twin.timing import stage
from twin.types import BoxBounds, JointGoal, Limits, MotionRequest, MotionResult, PoseGoal, Status, Trajectory

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.config import Settings
    from twin.robot.kinematics import URArm

__all__ = [
    "FINAL_CHECK",
    "GOAL_KINDS",
    "CheckedPlanner",
    "KinematicPlant",
    "OneShotPlanner",
    "PathPlanner",
    "Plant",
    "RecedingHorizonPlanner",
    "Retimer",
    "SceneView",
    "Segment",
    "accepts_retimer",
    "as_checked",
    "cannot_reach",
    "colliding_pair",
    "declared_goal_kinds",
    "declared_robot_models",
    "densify",
    "densify_path",
    "describe_goal_kinds",
    "first_collision",
    "goal_miss",
    "jerk_limited",
    "limit_ratios",
    "limits_from_settings",
    "make_context",
    "make_planner",
    "plan",
    "plan_with",
    "robot_refusal",
]

log = logging.getLogger("twin")

# `MotionResult.info["rejected_by"]` of a result the planner called a success and the independent check
# (collision re-check of every returned trajectory or segment, joint limits, goal reached) turned down
FINAL_CHECK = "final_check"
# `MotionResult.info["limit_ratios"]`: {'velocity' | 'acceleration' | 'jerk': the largest |value| / limit of
# any joint} over everything the judge saw of the motion (jerk is measured for every planner, judged only
# for one that declares `jerk_limited`)
LIMIT_RATIOS = "limit_ratios"


def limit_ratios(result: MotionResult) -> dict[str, float]:
    """The judge's limit ratios of a result (`info["limit_ratios"]`); empty when it judged no motion."""
    r = result.info.get(LIMIT_RATIOS) if isinstance(result.info, dict) else None
    return {str(k): float(v) for k, v in r.items()} if isinstance(r, dict) else {}


def _over_limits(excess: dict[str, LimitExcess], *, jerk: bool) -> str | None:
    """'joint 2 reaches 5.17 rad/s (declared qd), limit 3.14 (1.65x); ...' for every judged limit beyond
    LIMIT_TOLERANCE, or None."""
    over = [e for k, e in excess.items() if e.ratio > 1.0 + LIMIT_TOLERANCE and (jerk or k != "jerk")]
    return "; ".join(f"{e.kind} {e.reason()}" for e in over) or None


# the judge's refusals per (planner, what) in this process: the first is a warning that says what broke, the
# repeats are debug lines with their count (a sweep said "planner returned a trajectory beyond the joint limits"
# 15 times in a row, and never which joint)
_REFUSALS: dict[tuple[str, str], int] = {}


def _refused(planner: str, what: str, detail: str) -> None:
    """Log that the judge refused a motion of `planner`: 'ompl.rrt returned a trajectory beyond the joint limits;
    reported as LIMIT_VIOLATION: velocity joint 2 reaches 5.17 rad/s (declared qd) at t=0.420 s, limit 3.14
    (1.65x)', once per planner and `what`; later ones at debug level (-vv), counted."""
    n = _REFUSALS[planner, what] = _REFUSALS.get((planner, what), 0) + 1
    if n == 1:
        log.warning("%s %s: %s (said once per planner; -vv shows every one)", planner, what, detail)
    else:
        log.debug("%s %s (%d times so far): %s", planner, what, n, detail)


def _worst(ratios: dict[str, float], excess: dict[str, LimitExcess]) -> dict[str, float]:
    """`ratios` raised to the ratios of `excess` where those are larger."""
    out = dict(ratios)
    for k, e in excess.items():
        out[k] = max(out.get(k, 0.0), e.ratio)
    return out


@runtime_checkable
class SceneView(Protocol):
    """What a planner may ask of the planning scene it is given (`twin.collision.PlanningScene` is the one
    implementation): read-only collision and distance queries for joint configurations (6,) / (n, 6)."""

    padding_m: float

    def in_collision(self, q: np.ndarray) -> bool: ...

    def in_collision_batch(self, qs: np.ndarray) -> np.ndarray: ...

    def first_collision(self, qs: np.ndarray) -> int | None: ...

    def min_distance(self, q: np.ndarray, *, include_self: bool = True) -> Any: ...

    def min_distance_batch(self, qs: np.ndarray, *, include_self: bool = True) -> np.ndarray: ...

    def names(self) -> list[str]: ...

    def box_bounds(self) -> dict[str, BoxBounds]: ...

    def attached_box(self) -> tuple[str, np.ndarray, np.ndarray] | None: ...

    @property
    def gripper_opening(self) -> float: ...


@runtime_checkable
class OneShotPlanner(Protocol):
    """Plans a whole trajectory at once."""

    def plan(self, request: MotionRequest, scene: PlanningScene) -> MotionResult: ...


@dataclass(frozen=True)
class Segment:
    """A piece of motion a receding-horizon planner commands before it is asked again.

    `fallback`: the planner did not solve for this piece (its solve failed) and follows an earlier plan
    or its initial guess instead; the checked loop counts such steps (`fallback_steps`)."""

    trajectory: Trajectory
    solve_time_s: float
    info: dict[str, Any]
    fallback: bool = False


@runtime_checkable
class RecedingHorizonPlanner(Protocol):
    """Plans a short segment from the latest measured state, again and again, until done."""

    def reset(self, request: MotionRequest, scene: PlanningScene) -> None: ...

    def step(self, q: np.ndarray) -> Segment | MotionResult:
        """The next segment from measured joint state `q` (6,), or a final MotionResult when done."""
        ...


@runtime_checkable
class Retimer(Protocol):
    """Turns a geometric joint path (m, 6) into a trajectory under joint limits."""

    def retime(self, path: np.ndarray, limits: Limits) -> Trajectory: ...


class PathPlanner:
    """Base class of one-shot planners that return a geometric path and let a retimer plugin time it
    (a config block's `retimer:`). Subclassing declares `accepts_retimer`; `self.retimer` is the retimer
    the config chose, or None (the planner then uses its own default)."""

    accepts_retimer: ClassVar[bool] = True
    retimer: Retimer | None = None

    def set_retimer(self, retimer: Retimer) -> None:
        self.retimer = retimer

    @property
    def jerk_limited(self) -> bool:
        """As jerk-limited as the retimer that times the path (its `jerk_limited`, default True); a subclass
        with a default retimer of its own answers for that one."""
        return jerk_limited(self.retimer) if self.retimer is not None else True


def jerk_limited(planner: Any) -> bool:
    """Does this planner (instance) keep the request's jerk limit? Declared by its attribute `jerk_limited`
    (default True: a planner is held to every limit of the request unless it says otherwise). TOPP-RA
    parameterises with velocity and acceleration limits only, so a path timed by it declares False; a
    `PathPlanner` answers for its retimer."""
    return bool(getattr(planner, "jerk_limited", True))


def accepts_retimer(planner_class: type) -> bool:
    """Does this planner class take a retimer? Declared by the class attribute `accepts_retimer` (default
    False; `PathPlanner` sets it)."""
    return bool(getattr(planner_class, "accepts_retimer", False))


# What a goal asks for (`JointGoal.kind`, `PoseGoal.kind`): the joint angles; a pose (position and
# orientation); a position with the orientation free. A planner class declares the kinds it can reach
# in its class attribute `goal_kinds` (default: all three).
GOAL_KINDS: frozenset[str] = frozenset({"joint", "pose", "position"})
_GOAL_KIND_WORDS = {"joint": "joint goals", "pose": "pose goals with an orientation", "position": "position goals"}


def describe_goal_kinds(kinds: frozenset[str] | set[str]) -> str:
    """'joint goals, pose goals with an orientation' (sorted, for messages)."""
    return ", ".join(_GOAL_KIND_WORDS[k] for k in sorted(kinds))


def declared_goal_kinds(planner_class: type) -> frozenset[str]:
    """The goal kinds a planner class declares it can reach (`goal_kinds`; all of them when it says nothing)."""
    return frozenset(getattr(planner_class, "goal_kinds", GOAL_KINDS))


def cannot_reach(name: str, kind: str, kinds: frozenset[str]) -> str:
    """The one message for a goal kind a planner does not serve."""
    return f"{name} cannot reach {describe_goal_kinds({kind})}; it serves {describe_goal_kinds(kinds)}"


def declared_robot_models(planner_class: type) -> frozenset[str] | None:
    """The arms (`robot.model` names) a planner class declares it plans for (`robot_models`); None: every arm."""
    models = getattr(planner_class, "robot_models", None)
    return None if models is None else frozenset(models)


def robot_refusal(name: str, planner_class: type, model: str) -> str | None:
    """Why planner `name` does not plan for the arm `model` (the one message), or None when it does."""
    models = declared_robot_models(planner_class)
    if models is None or model in models:
        return None
    return f"{name} does not plan for robot.model {model}; it plans for {', '.join(sorted(models))}"


def limits_from_settings(settings: Settings, *, tcp_speed: float | None = None) -> Limits:
    """The config's joint limits, each joint's speed no faster than the arm's datasheet allows
    (`twin.robot.ur_models`: the UR10e's base and shoulder turn at most 120 deg/s)."""
    r = settings.robot
    vel = np.minimum(float(r.max_joint_vel), ur_model(r.model).speed_limits())
    return Limits(vel, np.full(6, float(r.max_joint_acc)), np.full(6, float(r.max_joint_jerk)), tcp_speed)


def make_context(settings: Settings, registry: Registry | None = None, robot: Robot | None = None) -> PluginContext:
    """The plugin context of a config: its settings, its robot (`robot`, or built from `settings.robot`:
    build it once and pass it on, as `twin run` does) and the registry (default: every installed plugin)."""
    return PluginContext(
        settings=settings,
        robot=robot or Robot.from_settings(settings),
        registry=registry or default_registry(),
    )


def make_planner(block: PlannerBlock | str, context: PluginContext) -> CheckedPlanner:
    """Instantiate a planner from a config block `{name, params, retimer}` or a bare name, wrapped in the
    one check every planner gets (`CheckedPlanner`)."""
    if isinstance(block, str):
        block = PlannerBlock(name=block)
    entry = context.registry.entry(block.name, (Kind.PLANNER, Kind.RECEDING_HORIZON))
    refusal = robot_refusal(block.name, entry.load(), context.kinematics.model)
    if refusal is not None:
        raise ConfigError(refusal)
    with _plugin_code(block.name, "its constructor"):
        planner = context.registry.planner(block.name, block.params, context)
    if block.retimer is not None:
        if not accepts_retimer(type(planner)):
            raise ConfigError(f"planner {block.name!r} produces trajectories itself and takes no retimer")
        planner.set_retimer(context.registry.retimer(block.retimer, block.retimer_params, context))
    return CheckedPlanner(
        planner, name=block.name, receding_horizon=entry.kind is Kind.RECEDING_HORIZON, context=context
    )


@contextlib.contextmanager
def _plugin_code(name: str, doing: str) -> Iterator[None]:
    """Around a call into a plugin: an exception of the plugin's own (not a TwinError, which says what is
    wrong with the input) becomes PluginCrashed naming the plugin, the call and the exception."""
    try:
        yield
    except TwinError:
        raise
    except Exception as e:  # any bug of a plugin is reported as the plugin's
        raise PluginCrashed(name, doing, e) from e


# ---- trajectory checks ----------------------------------------------------------------------------
def densify(traj: Trajectory, kin: URArm, *, max_step_rad: float, max_step_m: float) -> np.ndarray:
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


def densify_path(path: np.ndarray, max_step_rad: float) -> np.ndarray:
    """The polyline through the joint path `path` (m, 6) with points added on its straight segments, so no
    two neighbours are more than `max_step_rad` apart (Euclidean norm over the six joints, rad). Every
    original waypoint is kept; a segment of length L gets ceil(L / max_step_rad) - 1 points, evenly spaced."""
    path = np.asarray(path, dtype=float)
    out = [path[:1]]
    for a, b in itertools.pairwise(path):
        k = max(1, math.ceil(float(np.linalg.norm(b - a)) / max_step_rad - 1e-9))
        out.append(a + np.outer(np.arange(1, k + 1) / k, b - a))
    return np.concatenate(out)


def first_collision(
    traj: Trajectory, scene: PlanningScene, kin: URArm, *, max_step_rad: float = 0.01, max_step_m: float = 0.01
) -> int | None:
    """Index (into the densified samples) of the first colliding configuration, or None if free."""
    qs = densify(traj, kin, max_step_rad=max_step_rad, max_step_m=max_step_m)
    hits = scene.in_collision_batch(qs)
    idx = np.flatnonzero(hits)
    return int(idx[0]) if idx.size else None


def _rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1.0) / 2.0, -1.0, 1.0)))


def goal_miss(goal: JointGoal | PoseGoal, q_end: np.ndarray, kin: URArm) -> str | None:
    """Why `q_end` (6,) does not reach `goal` within the goal's own tolerances, or None when it does.

    The one definition of "reached" for every planner: a joint goal, every joint within `tolerance_rad`;
    a pose goal, the frame's origin within `position_tolerance_m` and (unless free) its rotation within
    `orientation_tolerance_rad`."""
    if isinstance(goal, JointGoal):
        err = float(np.abs(q_end - goal.q).max())
        return (
            None
            if err <= goal.tolerance_rad
            else f"ends {err:.2e} rad from the joint goal (tolerance {goal.tolerance_rad:g} rad)"
        )
    T = kin.fk(q_end, goal.frame)
    G = goal.pose.matrix()
    d = float(np.linalg.norm(T[:3, 3] - G[:3, 3]))
    if d > goal.position_tolerance_m:
        return f"ends {d:.4f} m from the goal position (tolerance {goal.position_tolerance_m:g} m)"
    if goal.orientation_tolerance_rad is not None:
        a = _rotation_angle(T[:3, :3], G[:3, :3])
        if a > goal.orientation_tolerance_rad:
            return f"ends {a:.4f} rad from the goal orientation (tolerance {goal.orientation_tolerance_rad:g} rad)"
    return None


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


def _still(q: np.ndarray) -> Trajectory:
    return Trajectory(np.zeros(1), np.asarray(q, dtype=float)[None], np.zeros((1, 6)), np.zeros((1, 6)))


def colliding_pair(scene: PlanningScene, q: np.ndarray) -> str:
    """'forearm_link with table' for the closest (penetrating) pair at q, for failure reasons ("an unknown
    pair" from a scene that cannot measure distances, e.g. a planner's own collision-only scene)."""
    measure = getattr(scene, "min_distance", None)
    if measure is None:
        return "an unknown pair"
    try:
        d = measure(q)
    except TwinError:
        return "an unknown pair"
    return f"{d.robot_part} with {d.other}" if d.robot_part else "an unknown pair"


# ---- the one checked path -------------------------------------------------------------------------
class Plant(Protocol):
    """Where checked motion goes: the kinematic model (planning only) or the simulated arm (`twin.executor`)."""

    def measured_q(self) -> np.ndarray:
        """(6,) joint angles now, rad (encoders)."""
        ...

    def run(self, traj: Trajectory) -> str | None:
        """Execute a checked trajectory; a reason when execution had to stop (e.g. an unexpected contact)."""
        ...


class KinematicPlant:
    """The arm as the planner's model has it: every trajectory is followed exactly."""

    def __init__(self, q: np.ndarray):
        self.q = np.asarray(q, dtype=float).copy()

    def measured_q(self) -> np.ndarray:
        return self.q

    def run(self, traj: Trajectory) -> str | None:
        self.q = traj.q[-1].copy()
        return None


class CheckedPlanner:
    """What `make_planner` hands out: any registered planner, built-in or third-party, checked the same way.

    * One-shot results: the trajectory must start at the request's start, reach the goal within the goal's
      tolerances (`goal_miss`) and pass the FCL scene (whole arm, gripper, held object, fixtures, perceived
      boxes, self-collision) every `collision.check_resolution_rad` / `check_resolution_m`.
    * Receding-horizon segments: each must start at the measured state and pass the same FCL check
      *before* it is returned (`step`) and so before it is executed; a colliding segment ends the motion
      with `Status.COLLISION` naming the pair. Segments a planner marks as `fallback` are counted.
    * `drive(request, scene, plant)` is the single loop for both kinds; `plan` drives the kinematic plant.

    The plugin itself is `inner`; other attributes are read through to it (its params, diagnostics).
    """

    def __init__(self, inner: Any, *, name: str, receding_horizon: bool, context: PluginContext):
        if receding_horizon and not isinstance(inner, RecedingHorizonPlanner):
            raise PlanningError(
                f"{name!r} is registered as receding-horizon but {type(inner).__name__} has no reset()/step()"
            )
        if not receding_horizon and not isinstance(inner, OneShotPlanner):
            raise PlanningError(f"{name!r} is registered as one-shot but {type(inner).__name__} has no plan()")
        self.inner = inner
        self.name = name
        self.receding_horizon = receding_horizon
        self.context = context
        self.goal_kinds = declared_goal_kinds(type(inner))
        unknown = self.goal_kinds - GOAL_KINDS
        if unknown:
            raise PlanningError(
                f"{name!r} declares unknown goal kinds {sorted(unknown)}; allowed: {sorted(GOAL_KINDS)}"
            )
        self._request: MotionRequest | None = None
        self._scene: PlanningScene | None = None
        self._fallback_steps = 0
        self._segments = 0
        self._reset_time_s = 0.0  # wall time of the last reset(), s
        self._check_time_s = 0.0  # wall time of our FCL check of the segments since reset(), s
        self._last: Trajectory | None = None  # the last segment accepted since reset()
        self._ratios: dict[str, float] = {}  # the worst limit ratios of the segments since reset()

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__") or attr == "inner":
            raise AttributeError(attr)
        return getattr(self.inner, attr)

    def __repr__(self) -> str:
        return f"CheckedPlanner({self.name!r}, {type(self.inner).__name__})"

    def serves(self, kind: str) -> bool:
        """Whether the planner declares it can reach goals of this kind ('joint', 'pose', 'position')."""
        return kind in self.goal_kinds

    # ---- receding horizon, checked --------------------------------------------------------------
    def reset(self, request: MotionRequest, scene: PlanningScene) -> None:
        if not self.receding_horizon:
            raise PlanningError(f"{self.name} is a one-shot planner: call plan(), not reset()/step()")
        if request.goal.kind not in self.goal_kinds:
            raise InvalidRequestError(cannot_reach(self.name, request.goal.kind, self.goal_kinds))
        self._request, self._scene = request, scene
        self._fallback_steps = self._segments = 0
        self._check_time_s = 0.0
        self._last, self._ratios = None, {}
        t0 = time.perf_counter()
        with _plugin_code(self.name, "reset()"):
            self.inner.reset(request, scene)
        self._reset_time_s = time.perf_counter() - t0

    def step(self, q: np.ndarray) -> Segment | MotionResult:
        """The planner's next segment from measured `q`, FCL-checked; or a final MotionResult (judged)."""
        if self._request is None or self._scene is None:
            raise PlanningError(f"{self.name}.step() called before reset()")
        q = np.asarray(q, dtype=float)
        t0 = time.perf_counter()
        with _plugin_code(self.name, "step()"):
            out = self.inner.step(q)
        elapsed = time.perf_counter() - t0
        if isinstance(out, MotionResult):
            if out.success and self._last is not None:  # the arm stops at the end: from the last segment to rest
                excess = limit_excess(self._last, self._request.limits, from_rest=False, to_rest=True)
                self._ratios = _worst(self._ratios, excess)
                over = _over_limits(excess, jerk=jerk_limited(self.inner))
                if over is not None:
                    return MotionResult(
                        Status.LIMIT_VIOLATION,
                        f"stopping at the end of segment {self._segments} exceeds the joint limits: {over}",
                        info=dict(out.info, **self._info_extra(), rejected_by=FINAL_CHECK),
                    )
            if out.success:
                q_end = out.trajectory.q[-1] if out.trajectory is not None else q
                why = goal_miss(self._request.goal, q_end, self.context.kinematics)
                if why is not None:
                    return MotionResult(
                        Status.NO_SOLUTION,
                        f"{self.name} reported success but {why}",
                        info=dict(out.info, **self._info_extra(), rejected_by=FINAL_CHECK),
                    )
            return replace(out, info=dict(out.info, **self._info_extra()))
        if not isinstance(out, Segment):
            raise PlanningError(
                f"{type(self.inner).__name__}.step returned {type(out).__name__}, not Segment or MotionResult"
            )
        traj = out.trajectory
        off = float(np.abs(traj.q[0] - q).max())
        if off > 1e-6:
            raise PlanningError(
                f"{self.name}: segment {self._segments + 1} starts {off:.2e} rad away from the measured state"
            )
        # the step's time is the wall time of everything the planner did for it, whatever it reports itself
        out = replace(out, solve_time_s=elapsed, info=dict(out.info, reported_solve_time_s=out.solve_time_s))
        kind = "fallback segment" if out.fallback else "segment"
        t0 = time.perf_counter()  # the judge's time: limits and FCL
        # the limits, with the motion that led into the segment (velocity and acceleration carry over)
        excess = limit_excess(
            stitched(self._last, traj), self._request.limits, from_rest=self._last is None, to_rest=False
        )
        self._ratios = _worst(self._ratios, excess)
        over = _over_limits(excess, jerk=jerk_limited(self.inner))
        if over is not None:
            self._check_time_s += time.perf_counter() - t0
            self._segments += 1
            _refused(
                self.name, "planned a segment beyond the joint limits; not executed", f"{kind} {self._segments}: {over}"
            )
            return MotionResult(
                Status.LIMIT_VIOLATION,
                f"{kind} {self._segments} would exceed the joint limits ({over}); not executed",
                info=dict(out.info, **self._info_extra(), rejected_by=FINAL_CHECK),
            )
        col = self.context.settings.collision
        hit = first_collision(
            traj,
            self._scene,
            self.context.kinematics,
            max_step_rad=col.check_resolution_rad,
            max_step_m=col.check_resolution_m,
        )
        self._check_time_s += time.perf_counter() - t0
        self._segments += 1
        if hit is not None:
            qs = densify(
                traj, self.context.kinematics, max_step_rad=col.check_resolution_rad, max_step_m=col.check_resolution_m
            )
            pair = colliding_pair(self._scene, qs[hit])
            _refused(self.name, "planned a colliding segment; not executed", f"{kind} {self._segments}: {pair}")
            return MotionResult(
                Status.COLLISION,
                f"{kind} {self._segments} would collide ({pair}); not executed",
                info=dict(out.info, **self._info_extra(), rejected_by=FINAL_CHECK),
            )
        if out.fallback:
            self._fallback_steps += traj.q.shape[0] - 1
        self._last = traj
        return out

    def _info_extra(self) -> dict[str, Any]:
        """What the judge adds to a receding-horizon result's info: fallback steps, check time, limit ratios."""
        return {
            "fallback_steps": self._fallback_steps,
            "final_check_time_s": self._check_time_s,
            LIMIT_RATIOS: dict(self._ratios),
        }

    # ---- one-shot, checked ----------------------------------------------------------------------
    def _plan_one_shot(self, request: MotionRequest, scene: PlanningScene) -> MotionResult:
        t0 = time.perf_counter()
        with _plugin_code(self.name, "plan()"):
            result = self.inner.plan(request, scene)
        elapsed = time.perf_counter() - t0
        if not isinstance(result, MotionResult):
            raise PlanningError(f"{type(self.inner).__name__}.plan returned {type(result).__name__}, not MotionResult")
        # planning time is the same for every planner: the wall time of everything plan() did, its own checks
        # included; our final check is timed apart (info["final_check_time_s"])
        info = dict(result.info)
        if result.planning_time_s:
            info["reported_planning_time_s"] = result.planning_time_s
        result = replace(result, planning_time_s=elapsed, info=info)
        if not result.success:
            return result
        t0 = time.perf_counter()
        checked = _checked(result, request, scene, self.context, jerk=jerk_limited(self.inner), name=self.name)
        return replace(checked, info=dict(checked.info, final_check_time_s=time.perf_counter() - t0))

    # ---- the one loop ---------------------------------------------------------------------------
    def drive(
        self, request: MotionRequest, scene: PlanningScene, plant: Plant, *, max_segments: int = 1000
    ) -> MotionResult:
        """Plan and hand every checked piece to `plant`: a one-shot plan is one piece, a receding-horizon
        planner gives one piece per step from the plant's measured state. Nothing unchecked reaches the
        plant. The result's trajectory is what was commanded; `info` holds `solve_times_s`, `solves`,
        `fallback_steps` and, when the plant stopped execution, `execution_stop`. Its wall time goes to
        the run's breakdown as `planning.<name>`, less the plant's (`execution`, and the physics in it)."""
        with stage(f"planning.{self.name}"):
            return self._drive(request, scene, plant, max_segments=max_segments)

    def _drive(self, request: MotionRequest, scene: PlanningScene, plant: Plant, *, max_segments: int) -> MotionResult:
        if request.goal.kind not in self.goal_kinds:
            return MotionResult(Status.INVALID_GOAL, cannot_reach(self.name, request.goal.kind, self.goal_kinds))
        if not self.receding_horizon:
            result = self._plan_one_shot(request, scene)
            if result.success:
                assert result.trajectory is not None
                stop = _execute(plant, result.trajectory)
                if stop is not None:
                    return replace(
                        result,
                        status=Status.EXECUTION_STOPPED,
                        reason=stop,
                        trajectory=None,
                        info=dict(result.info, execution_stop=stop),
                    )
            return result
        t0 = time.perf_counter()
        self.reset(request, scene)
        pieces: list[Trajectory] = []
        solve_times: list[float] = []
        final: MotionResult | None = None
        for _ in range(max_segments):
            out = self.step(plant.measured_q())
            if isinstance(out, MotionResult):
                final = out
                break
            solve_times.append(out.solve_time_s)
            pieces.append(out.trajectory)
            stop = _execute(plant, out.trajectory)
            if stop is not None:
                final = MotionResult(
                    Status.EXECUTION_STOPPED, stop, info={"execution_stop": stop, **self._info_extra()}
                )
                break
        if final is None:
            final = MotionResult(Status.NO_SOLUTION, f"no end after {max_segments} segments", info=self._info_extra())
        info = dict(
            final.info,
            solve_times_s=solve_times,
            solves=len(solve_times),
            reset_time_s=self._reset_time_s,
            final_check_time_s=self._check_time_s,
        )
        planning_time = self._reset_time_s + float(sum(solve_times)) or time.perf_counter() - t0
        if final.success:
            traj = _concat(pieces) if pieces else _still(plant.measured_q())
            return replace(final, trajectory=traj, info=info, planning_time_s=planning_time)
        return replace(final, trajectory=None, info=info, planning_time_s=planning_time)

    def plan(self, request: MotionRequest, scene: PlanningScene) -> MotionResult:
        """Plan `request` without a robot: one-shot as is, receding horizon on the kinematic model."""
        return self.drive(request, scene, KinematicPlant(request.start))


def _execute(plant: Plant, traj: Trajectory) -> str | None:
    """`plant.run(traj)`, timed as the run's `execution` stage."""
    with stage("execution"):
        return plant.run(traj)


def as_checked(planner: Any, context: PluginContext, *, name: str | None = None) -> CheckedPlanner:
    """`planner` itself when it came from `make_planner`; a bare plugin instance wrapped in the same check."""
    if isinstance(planner, CheckedPlanner):
        return planner
    label = name or type(planner).__name__
    if isinstance(planner, OneShotPlanner):
        return CheckedPlanner(planner, name=label, receding_horizon=False, context=context)
    if isinstance(planner, RecedingHorizonPlanner):
        return CheckedPlanner(planner, name=label, receding_horizon=True, context=context)
    raise PlanningError(f"{type(planner).__name__} has neither plan() nor reset()/step()")


def plan_with(planner: Any, request: MotionRequest, scene: PlanningScene, context: PluginContext) -> MotionResult:
    """Plan `request` with an instantiated planner (from `make_planner`, or a bare plugin instance, which
    gets the same check) on the kinematic model."""
    return as_checked(planner, context).plan(request, scene)


def _checked(
    result: MotionResult,
    request: MotionRequest,
    scene: PlanningScene,
    context: PluginContext,
    *,
    jerk: bool = True,
    name: str = "planner",
) -> MotionResult:
    """The judge of a one-shot success: it starts at the start, ends on the goal, keeps the joint limits
    (jerk when `jerk`: the planner declares itself jerk-limited) and is collision-free; else a failure
    status naming what broke, `info["rejected_by"] = FINAL_CHECK`. The limit ratios go to the info either way."""
    traj = result.trajectory
    assert traj is not None
    kin = context.kinematics
    col = context.settings.collision
    start_err = float(np.abs(traj.q[0] - request.start).max())
    if start_err > 1e-6:
        raise PlanningError(f"trajectory starts {start_err:.2e} rad away from the request's start")
    why = goal_miss(request.goal, traj.q[-1], kin)
    if why is not None:
        return replace(
            result,
            status=Status.NO_SOLUTION,
            trajectory=None,
            reason=f"the trajectory {why}",
            info=dict(result.info, rejected_by=FINAL_CHECK),
        )
    excess = limit_excess(traj, request.limits)
    result = replace(result, info=dict(result.info, **{LIMIT_RATIOS: {k: e.ratio for k, e in excess.items()}}))
    over = _over_limits(excess, jerk=jerk)
    if over is not None:
        _refused(name, "returned a trajectory beyond the joint limits; reported as LIMIT_VIOLATION", over)
        return replace(
            result,
            status=Status.LIMIT_VIOLATION,
            trajectory=None,
            path=result.path if result.path is not None else traj.q,  # the refused motion (for seeing why)
            reason=f"the trajectory exceeds the joint limits: {over}",
            info=dict(result.info, rejected_by=FINAL_CHECK),
        )
    hit = first_collision(traj, scene, kin, max_step_rad=col.check_resolution_rad, max_step_m=col.check_resolution_m)
    if hit is not None:
        qs = densify(traj, kin, max_step_rad=col.check_resolution_rad, max_step_m=col.check_resolution_m)
        pair = f"{colliding_pair(scene, qs[hit])}, checked sample {hit}"
        _refused(name, "returned a colliding trajectory; reported as COLLISION", pair)
        return replace(
            result,
            status=Status.COLLISION,
            trajectory=None,
            path=result.path if result.path is not None else traj.q,  # the refused motion (for seeing why)
            reason=f"the trajectory collides ({pair})",
            info=dict(result.info, rejected_by=FINAL_CHECK),
        )
    return result


def plan(
    settings: Settings,
    planner: PlannerBlock | str,
    request: MotionRequest,
    *,
    scene: PlanningScene | None = None,
    registry: Registry | None = None,
    robot: Robot | None = None,
) -> MotionResult:
    """Plan one request with the planner named in `planner` (a config block or a name), in `scene` (default:
    the config's cell) for `robot` (default: built from `settings.robot`; pass the one `scene` was built for).

    Bad input (unknown name, bad parameter) raises a TwinError; "no solution" is a status in the result.
    """
    from twin.collision import PlanningScene  # lazy: fcl

    context = make_context(settings, registry, robot)
    p = make_planner(planner, context)
    if scene is None:
        scene = PlanningScene.from_settings(settings, robot=context.robot)
    if isinstance(request.goal, PoseGoal) and request.goal.frame not in ("tcp", "flange"):
        raise InvalidRequestError(f"unknown goal frame {request.goal.frame!r}; allowed: tcp, flange")
    return p.plan(request, scene)
