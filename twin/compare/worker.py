"""One run, start to finish, inside a worker: the function both backends (process pool, Ray) execute.

Why a per-process cache: building the FCL scene and the PyBullet world costs more than a typical plan,
so each worker process builds them once per scene config and reuses them. Nothing a run leaves behind
changes the next run: the world is reset (rebuilt) before every execution, planners are instantiated
per run, and random queries are drawn from a generator seeded by (seed, scenario, index) alone. So a
row depends only on its RunTask, whichever worker, backend or order ran it.
"""

from __future__ import annotations

import logging
import math
import os
import sys
import time
import traceback
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.compare.metrics import (
    empty_metrics,
    empty_timing,
    execute_in_physics,
    task_metrics,
    timing_metrics,
    trajectory_metrics,
)
from twin.compare.spec import RunTask
from twin.errors import ConfigError, TwinError

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.config import Settings
    from twin.kinematics import UR5e
    from twin.types import MotionRequest
    from twin.world import World

__all__ = ["execute_run", "sample_query", "worker_init", "quiet_imports", "TASKS_UNAVAILABLE"]

log = logging.getLogger("twin")

TASKS_UNAVAILABLE = "skipped: twin.tasks not available"
_SAMPLE_TRIES = 2000


@dataclass
class _Cell:
    """A scene config's static cell, built once per worker: settings without loose objects, the FCL
    scene, kinematics, and (on first execution) the PyBullet world."""

    settings: "Settings"
    scene: "PlanningScene"
    kin: "UR5e"
    world: "World | None" = None


_CELLS: dict[tuple[str, tuple[str, ...], str], _Cell] = {}


def worker_init() -> None:
    """Process-pool initializer: C-level writes of PyBullet and planner backends (PyBullet's import banner
    on stderr, solver chatter) go to /dev/null; Python's own stderr (warnings, tracebacks) still reaches
    the terminal through a duplicate of the original fd 2."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        os.close(devnull)
        sys.stderr = os.fdopen(saved, "w", buffering=1)
    except OSError:  # pragma: no cover - nothing to silence then
        pass


def quiet_imports() -> None:
    """Import PyBullet with fd 2 silenced (for in-process runs): its banner is no output of ours."""
    if "pybullet" in sys.modules:
        return
    sys.stderr.flush()
    try:
        saved = os.dup(2)
        devnull = os.open(os.devnull, os.O_WRONLY)
    except OSError:  # pragma: no cover
        return
    try:
        os.dup2(devnull, 2)
        import twin.world  # noqa: F401
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def _cell(config: str, overrides: tuple[str, ...], unknown_fixtures: str) -> _Cell:
    key = (config, overrides, unknown_fixtures)
    cell = _CELLS.get(key)
    if cell is None:
        from twin.collision import PlanningScene
        from twin.config import load_config
        from twin.kinematics import UR5e

        s = load_config(config, overrides)
        # loose objects are unknown to the planning scene; leaving them out of the physics as well keeps
        # "contacts seen in physics" a measure of the trajectory, not of objects the planner never saw
        no_objects = s.world.objects.model_copy(update={"items": []})
        s = s.model_copy(update={"world": s.world.model_copy(update={"objects": no_objects})})
        scene = PlanningScene.from_settings(s)  # without fixtures marked `known: false`
        if unknown_fixtures == "box":  # no perception step in a motion query: report them perfectly
            scene.add_unknown_fixtures(s)
        cell = _CELLS[key] = _Cell(settings=s, scene=scene, kin=UR5e())
    return cell


def _world(cell: _Cell) -> "World":
    if cell.world is None:
        from twin.world import World

        cell.world = World(cell.settings, cell.settings.seed, renderer="tiny")
    return cell.world


def sample_query(
    random: dict[str, Any], rng: np.random.Generator, *, scene: "PlanningScene", kin: "UR5e", home: np.ndarray
) -> dict[str, Any]:
    """A random query (as a QuerySpec dict): start and goal with the TCP pointing down at a random yaw
    (+-90 deg) in the region, the IK branch nearest `home`, clear of the environment and of itself.

    Raises ConfigError when the region yields no valid pair in a few thousand draws.
    """
    from twin.types import Pose

    lo = np.array([random["region_x"][0], random["region_y"][0], random["region_z"][0]])
    hi = np.array([random["region_x"][1], random["region_y"][1], random["region_z"][1]])

    def one() -> tuple[np.ndarray, np.ndarray] | None:
        p = rng.uniform(lo, hi)
        yaw = float(rng.uniform(-0.5 * math.pi, 0.5 * math.pi))  # a parallel gripper is symmetric under pi
        T = Pose.from_xyz_rpy(p, (math.pi, 0.0, yaw)).matrix()
        sols = kin.ik(T)
        if sols.shape[0] == 0:
            return None
        q = sols[int(np.argmin(np.linalg.norm(sols - home, axis=1)))]
        if scene.in_collision(q) or scene.min_distance(q, include_self=False).distance < random["min_clearance_m"]:
            return None
        return q, np.array([*p, math.pi, 0.0, yaw])

    start = goal = None
    for _ in range(_SAMPLE_TRIES):
        if start is None:
            start = one()
            continue
        goal = one()
        if goal is not None and np.linalg.norm(goal[1][:3] - start[1][:3]) >= random["min_travel_m"]:
            break
        goal = None
    if start is None or goal is None:
        raise ConfigError(
            f"no collision-free random query in region x={list(random['region_x'])} y={list(random['region_y'])} "
            f"z={list(random['region_z'])} after {_SAMPLE_TRIES} draws; widen it or lower min_clearance_m"
        )
    out: dict[str, Any] = {"start": start[0].tolist(), "goal": None, "goal_pose": None, "frame": "tcp"}
    if random["goal"] == "joint":
        out["goal"] = goal[0].tolist()
    else:
        out["goal_pose"] = goal[1].tolist()
    return out


def _request(task: RunTask, query: dict[str, Any], settings: "Settings") -> "MotionRequest":
    from twin.planning import limits_from_settings
    from twin.types import JointGoal, MotionRequest, Pose, PoseGoal

    if query.get("goal") is not None:
        goal: Any = JointGoal(query["goal"])
    else:
        x, y, z, r, p, yw = query["goal_pose"]
        goal = PoseGoal(Pose.from_xyz_rpy((x, y, z), (r, p, yw)), frame=query.get("frame", "tcp"))
    return MotionRequest(
        start=query["start"], goal=goal, limits=limits_from_settings(settings),
        time_limit_s=task.time_limit_s, seed=task.seed,
    )


def _run_query(task: RunTask, row: dict[str, Any]) -> None:
    from twin.config import PlannerBlock
    from twin.planning import make_context, make_planner, plan_with

    cell = _cell(task.config, task.overrides, task.unknown_fixtures)
    settings = cell.settings.model_copy(update={"seed": task.seed})
    if task.query is not None:
        query = dict(task.query)
    else:
        assert task.random is not None
        rng = np.random.default_rng(task.random_seed())
        home = np.asarray(settings.robot.home, dtype=float)
        query = sample_query(task.random, rng, scene=cell.scene, kin=cell.kin, home=home)
    row["query"] = query
    request = _request(task, query, settings)
    context = make_context(settings, kinematics=cell.kin)
    planner = make_planner(PlannerBlock(**task.planner), context)
    result = plan_with(planner, request, cell.scene, context)
    timing, solves = timing_metrics(result)
    row["timing"].update({k: v for k, v in timing.items() if v is not None})
    row["status"] = result.status.value
    row["reason"] = result.reason
    row["success"] = result.success
    row["metrics"]["solves"] = solves
    if not result.success or result.trajectory is None:
        return
    traj = result.trajectory
    metrics, row["clearance_pair"] = trajectory_metrics(
        traj, kin=cell.kin, scene=cell.scene, settings=settings, jerk_dt_s=task.jerk_dt_s
    )
    row["metrics"].update(metrics)
    if task.execute:
        phys, pairs = execute_in_physics(_world(cell), traj, request, kin=cell.kin, settle_s=task.settle_s)
        row["metrics"].update(phys)
        row["contact_pairs"] = pairs


def _run_task(task: RunTask, row: dict[str, Any]) -> None:
    try:
        from twin.tasks import run_task
    except ImportError:
        row["status"], row["reason"], row["success"] = "skipped", TASKS_UNAVAILABLE, None
        return
    from twin.config import load_config

    settings = load_config(task.config, task.overrides)
    block = task.planner
    if block.get("params") or block.get("retimer"):
        log.warning("task runs take a planner name only; params/retimer of %s are not passed on", task.planner_id)
    summary = run_task(settings, seed=task.seed, planner=block["name"])
    m = task_metrics(summary)
    row["metrics"].update(m)
    row["success"] = summary.success_rate >= 1.0
    row["status"] = "success" if row["success"] else "incomplete"
    failed = [f"{o.id}: {o.error}" for o in summary.objects if not o.placed]
    row["reason"] = "; ".join(failed)
    row["timing"]["wall_time_s"] = float(summary.wall_time_s)
    row["task"] = summary.to_json()  # per-object outcomes and the run's planner metrics


def json_safe(x: Any) -> Any:
    """`x` with numpy scalars/arrays as plain numbers/lists and NaN/inf as None (JSON has neither)."""
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if x is None or isinstance(x, str):
        return x
    return str(x)


def execute_run(task: RunTask) -> dict[str, Any]:
    """Run one (planner, case, seed) and return its row (a JSON-ready dict).

    A planner that raises (a broken contract, a missing backend) gives a row with status 'error' and
    the message, so one bad run never stops a sweep.
    """
    t0 = time.perf_counter()
    row: dict[str, Any] = {
        "run_id": task.run_id,
        "planner": task.planner_id,
        "planner_name": task.planner["name"],
        "scenario": task.scenario,
        "case": task.case,
        "kind": task.kind,
        "seed": task.seed,
        "status": None,
        "reason": "",
        "success": False,
        "query": task.query,
        "metrics": empty_metrics(),
        "timing": empty_timing(),
        "clearance_pair": None,
        "contact_pairs": [],
        "task": None,
    }
    try:
        if task.kind == "query":
            _run_query(task, row)
        else:
            _run_task(task, row)
    except Exception as e:  # one failing run is a result, not the end of the sweep
        if isinstance(e, TwinError):  # a typed error says what is wrong; its traceback is noise
            log.warning("run %s failed: %s", task.run_id, e)
        else:
            log.warning("run %s failed: %s\n%s", task.run_id, e, traceback.format_exc())
        row["status"], row["reason"], row["success"] = "error", f"{type(e).__name__}: {e}", False
    if row["timing"].get("wall_time_s") is None:
        row["timing"]["wall_time_s"] = time.perf_counter() - t0
    return json_safe(row)
