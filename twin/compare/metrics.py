"""What the comparison measures on one run, and the names the reports use.

Metrics are split in two dicts per row: `metrics` are deterministic for the same (planner, case, seed)
(the same sweep twice gives identical values), `timing` holds wall-clock numbers that never are.
Every row carries every key (None where it does not apply: a failed plan has no duration, a motion
query has no task success rate), so rows, CSV and summaries share one schema.

Physics ("contacts seen in physics", goal error) comes from executing the planned trajectory in the
PyBullet world: the arm is commanded `q(t), qd(t)` at every physics step, then held at the end for
`settle_s`. A contact is any robot link touching any other body, except the base link on what it
stands on (it is fixed to the world and cannot move).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.errors import DependencyMissing, PluginCrashed
from twin.executor import execute
from twin.failures import FAILURES, failure_of_plan, failure_of_task
from twin.limit_check import RATIO_METRICS
from twin.planning import densify
from twin.types import JointGoal, MotionRequest, MotionResult, RunSummary, Trajectory

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.config import Settings
    from twin.robot.kinematics import URArm
    from twin.world import World

__all__ = [
    "FAILURES",
    "METRICS",
    "METRIC_KEYS",
    "TIMINGS",
    "TIMING_KEYS",
    "MetricDef",
    "empty_metrics",
    "empty_timing",
    "execute_in_physics",
    "failure_of_exception",
    "failure_of_plan",
    "failure_of_row",
    "failure_of_task",
    "finite_or_none",
    "limit_metrics",
    "path_smoothness",
    "step_times",
    "task_metrics",
    "timing_metrics",
    "trajectory_metrics",
]

_MAX_FINE_SAMPLES = 200_000
SMOOTHNESS_STEP_RAD = 0.05  # arc-length step of the path the smoothness is measured on


@dataclass(frozen=True)
class MetricDef:
    """A metric's key, unit and one-line meaning (used as column headers and in summary.md)."""

    key: str
    unit: str
    description: str
    better: str = "lower"  # "lower" | "higher" | "" (neither)


METRICS: tuple[MetricDef, ...] = (
    MetricDef("duration_s", "s", "trajectory duration"),
    MetricDef("joint_path_length_rad", "rad", "joint-space path length (sum of |dq|, 2-norm)"),
    MetricDef("tcp_path_length_m", "m", "TCP path length"),
    MetricDef(
        "smoothness",
        "1/rad^2",
        f"OMPL's path smoothness (sum of squared discrete curvature) of the joint path resampled every "
        f"{SMOOTHNESS_STEP_RAD:g} rad; 0 for a straight line",
    ),
    MetricDef("max_jerk", "rad/s^3", "max |jerk| of any joint (finite differences of qdd, fine resampling)"),
    MetricDef(
        "max_vel_ratio",
        "",
        "largest joint velocity / its limit, as the judge measured it (declared qd and differences of q); "
        "above 1.001 the motion is refused (limit_violation), also on failed rows",
    ),
    MetricDef("max_acc_ratio", "", "largest joint acceleration / its limit, as max_vel_ratio"),
    MetricDef(
        "max_jerk_ratio",
        "",
        "largest joint jerk / its limit, as max_vel_ratio; judged only for a planner that declares itself "
        "jerk-limited (TOPP-RA-timed motion is not)",
    ),
    MetricDef(
        "min_clearance_m",
        "m",
        "minimum FCL distance to the environment along the trajectory, its start and goal included",
        "higher",
    ),
    MetricDef("contacts", "", "distinct (robot link, body) contacts seen when executed in physics"),
    MetricDef("contact_time_s", "s", "simulated time with any unexpected robot contact"),
    MetricDef("goal_error_m", "m", "TCP position error after execution and settling"),
    MetricDef("goal_error_rad", "rad", "max joint error to the planned final posture after settling"),
    MetricDef("solves", "", "solver calls of a receding-horizon planner", ""),
    MetricDef(
        "fallback_steps", "", "receding-horizon steps that followed an earlier plan or guess because a solve failed"
    ),
    MetricDef("task_success_rate", "", "objects placed / objects (task runs)", "higher"),
    MetricDef("cycle_time_s", "s", "mean simulated time per placed object (task runs)"),
    MetricDef("sim_time_s", "s", "simulated time of the whole task run"),
)

TIMINGS: tuple[MetricDef, ...] = (
    MetricDef(
        "planning_time_s",
        "s",
        "wall time of everything the planner did, its own checks included (receding horizon: reset and every "
        "step); our final check is not included",
    ),
    MetricDef("final_check_time_s", "s", "wall time of twin's independent FCL check of what the planner returned"),
    MetricDef("solve_time_median_s", "s", "median wall time per step (receding horizon)"),
    MetricDef("solve_time_max_s", "s", "longest step (receding horizon)"),
    MetricDef("wall_time_s", "s", "wall time of the whole run in its worker"),
    MetricDef(
        "task_planning_time_s",
        "s",
        "task runs: the compared planner's planning wall time per motion it planned in the run (its mean; "
        "comparable with a query's planning_time_s)",
    ),
)


def failure_of_row(row: dict[str, Any]) -> str | None:
    """The failure reason of a result row: its `failure`; for a row written before rows carried one,
    derived from its status as the worker would (None for a success, a skipped or unfinished row)."""
    if "failure" in row:
        return None if row["failure"] is None else str(row["failure"])
    status = row.get("status")
    if row.get("success") or status in (None, "skipped"):
        return None
    return failure_of_plan(str(status), str(row.get("reason") or ""))


def failure_of_exception(e: BaseException) -> str:
    """dependency_missing for a planner whose backend is not installed, plugin_error for a plugin that raised
    an exception of its own, else error."""
    if isinstance(e, PluginCrashed):
        return "plugin_error"
    return "dependency_missing" if isinstance(e, DependencyMissing) else "error"


METRIC_KEYS: tuple[str, ...] = tuple(m.key for m in METRICS)
TIMING_KEYS: tuple[str, ...] = tuple(m.key for m in TIMINGS)


def finite_or_none(x: Any) -> float | None:
    """A JSON-safe float: None for None, NaN and infinities (JSON has no inf)."""
    if x is None:
        return None
    v = float(x)
    return v if math.isfinite(v) else None


def empty_metrics() -> dict[str, Any]:
    return dict.fromkeys(METRIC_KEYS)


def empty_timing() -> dict[str, Any]:
    return dict.fromkeys(TIMING_KEYS)


def _fine(traj: Trajectory, dt: float) -> Trajectory:
    """The trajectory resampled at `dt` (coarsened if it would exceed _MAX_FINE_SAMPLES)."""
    if traj.t.shape[0] < 2:
        return traj
    dt = max(dt, traj.duration / _MAX_FINE_SAMPLES)
    return traj.resampled(dt)


def path_smoothness(q: np.ndarray, step_rad: float = SMOOTHNESS_STEP_RAD) -> float:
    """OMPL's `PathGeometric::smoothness` (sum over consecutive waypoint triples of the squared discrete
    curvature 2 * turn angle / (a + b)) on the joint path `q` (n, 6) resampled at equal arc length
    `step_rad`: OMPL measures its own waypoints, whose spacing differs between planners; a fixed spacing
    makes the number comparable across planners and retimers."""
    seg = np.linalg.norm(np.diff(q, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] < 2 * step_rad:
        return 0.0
    keep = np.concatenate([[True], seg > 1e-12])  # arc length must increase for the interpolation
    s, q = s[keep], q[keep]
    grid = np.arange(0.0, s[-1] + 1e-12, step_rad)
    p = np.stack([np.interp(grid, s, q[:, j]) for j in range(q.shape[1])], axis=1)
    d = np.linalg.norm(np.diff(p, axis=0), axis=1)
    a, b = d[:-1], d[1:]
    c = np.linalg.norm(p[2:] - p[:-2], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos = (a * a + b * b - c * c) / (2.0 * a * b)
    ok = (cos > -1.0) & (cos < 1.0)  # as OMPL: straight (cos = -1) and degenerate triples add nothing
    k = 2.0 * (math.pi - np.arccos(cos[ok])) / (a[ok] + b[ok])
    return float(np.sum(k * k))


def trajectory_metrics(
    traj: Trajectory, *, kin: URArm, scene: PlanningScene, settings: Settings, jerk_dt_s: float = 1e-3
) -> tuple[dict[str, float | None], str]:
    """Duration, joint and TCP path length, max |jerk| and minimum clearance of a planned trajectory,
    and the closest pair 'robot_part->other' (why the clearance is what it is).

    Path lengths and jerk use a fine resampling (`jerk_dt_s`) so that coarse and dense planners are
    measured alike. Clearance is the FCL distance robot-vs-environment (self pairs excluded: some stay
    close by construction) at the planning API's own check resolution, its minimum over the whole path:
    where the query's start or goal is the closest point (a grasp just above the table), every path to it
    has the same clearance, and so do planners that return the same path (the straight joint motion).
    """
    fine = _fine(traj, jerk_dt_s)
    dq = np.diff(fine.q, axis=0)
    joint_len = float(np.linalg.norm(dq, axis=1).sum()) if dq.size else 0.0
    p = kin.fk_batch(fine.q)[:, :3, 3]
    tcp_len = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) if fine.t.shape[0] > 1 else 0.0
    if fine.t.shape[0] > 1:
        jerk = np.diff(fine.qdd, axis=0) / np.diff(fine.t)[:, None]
        max_jerk = float(np.abs(jerk).max())
    else:
        max_jerk = 0.0
    col = settings.collision
    qs = densify(traj, kin, max_step_rad=col.check_resolution_rad, max_step_m=col.check_resolution_m)
    least, where = scene.min_clearance(qs)
    closest = scene.clearance(qs[where])
    pair = f"{closest.robot_part}->{closest.other}" if closest.robot_part else ""
    return {
        "duration_s": traj.duration,
        "joint_path_length_rad": joint_len,
        "tcp_path_length_m": tcp_len,
        "smoothness": path_smoothness(fine.q),
        "max_jerk": max_jerk,
        "min_clearance_m": finite_or_none(least),
    }, pair


def limit_metrics(ratios: dict[str, float]) -> dict[str, float | None]:
    """`max_vel_ratio`, `max_acc_ratio`, `max_jerk_ratio` from the judge's limit ratios
    (`twin.planning.limit_ratios`; None where it measured nothing)."""
    return {key: finite_or_none(ratios.get(kind)) for kind, key in RATIO_METRICS.items()}


def step_times(result: MotionResult) -> dict[str, float]:
    """{step: seconds} of the planner's own steps, from its info's numeric `<step>_time_s` (the OMPL planners'
    solve, simplify, retime, verify; compiled.rrtconnect's search, certify, ...; the judge's final_check)."""
    info = result.info if isinstance(result.info, dict) else {}
    return {
        k.removesuffix("_time_s"): float(v)
        for k, v in info.items()
        if k.endswith("_time_s") and isinstance(v, (int, float)) and not isinstance(v, bool)
    }


def timing_metrics(result: MotionResult) -> tuple[dict[str, float | None], int | None]:
    """Planning time (total) and, for receding-horizon planners, per-solve statistics and the count."""
    out = empty_timing()
    out["planning_time_s"] = float(result.planning_time_s)
    info = result.info if isinstance(result.info, dict) else {}
    check = info.get("final_check_time_s")
    out["final_check_time_s"] = float(check) if isinstance(check, (int, float)) else None
    solves = info.get("solve_times_s")
    if solves is None:
        return out, None
    st = np.asarray(list(solves), dtype=float)
    if st.size:
        out["solve_time_median_s"] = float(np.median(st))
        out["solve_time_max_s"] = float(st.max())
    return out, int(result.info.get("solves", st.size))


def execute_in_physics(
    world: World, traj: Trajectory, request: MotionRequest, *, kin: URArm, settle_s: float = 0.5
) -> tuple[dict[str, float | int | None], list[str]]:
    """Execute `traj` in `world` (reset first, so the outcome does not depend on earlier runs).

    Returns (contacts, contact_time_s, goal_error_m, goal_error_rad) and the sorted contact pairs
    'robot_link->body'.
    """
    world.reset()
    world.reset_joints(traj.q[0])
    link_name = {i: n for n, i in world.link_indices().items()}
    body_name = {i: n for n, i in world.body_ids().items()}
    dt = world.dt
    pairs: set[str] = set()
    contact_steps = 0

    def observe() -> None:
        nonlocal contact_steps
        hit = False
        for c in world.robot_contacts():
            if c.link_a == -1:  # the base link is fixed to the world and stands on the table
                continue
            hit = True
            pairs.add(f"{link_name.get(c.link_a, c.link_a)}->{body_name.get(c.body_b, c.body_b)}")
        contact_steps += hit

    # a measurement: the whole trajectory is played and every contact counted (a task's protective stop
    # would end it at the first; here the cell holds only what the planning scene knows)
    execute(world, traj, hold_s=math.ceil(settle_s / dt - 1e-9) * dt, on_step=observe, stop_on_contact=False)
    q_end = traj.q[-1]
    q_exec = world.joint_positions()
    if isinstance(request.goal, JointGoal):
        frame, goal_p = "tcp", kin.fk(request.goal.q)[:3, 3]
    else:
        frame, goal_p = request.goal.frame, np.asarray(request.goal.pose.position, dtype=float)
    p_exec = kin.fk(q_exec, frame)[:3, 3]
    return {
        "contacts": len(pairs),
        "contact_time_s": contact_steps * dt,
        "goal_error_m": float(np.linalg.norm(p_exec - goal_p)),
        "goal_error_rad": float(np.abs(q_exec - q_end).max()),
    }, sorted(pairs)


def task_metrics(summary: RunSummary) -> dict[str, float | None]:
    """Task success rate, mean cycle time per placed object and total simulated time of a task run."""
    placed = [o.cycle_time_s for o in summary.objects if o.placed]
    return {
        "task_success_rate": float(summary.success_rate),
        "cycle_time_s": float(np.mean(placed)) if placed else None,
        "sim_time_s": float(summary.sim_time_s),
    }
