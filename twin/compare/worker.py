"""One run, start to finish, inside a worker: the function both backends (process pool, Ray) execute.

Why a per-process cache: building the FCL scene and the PyBullet world costs more than a typical plan,
so each worker process builds them once per scene config and reuses them (`twin.problems.cells`).
Nothing a run leaves behind changes the next run: the world is reset (rebuilt) before every execution,
planners are instantiated per run, and random queries are drawn from a generator seeded by (seed,
scenario, index) alone. So a row depends only on its RunTask, whichever worker, backend or order ran it.
"""

from __future__ import annotations

import json
import logging
import math
import os
import sys
import time
import traceback
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.compare.metrics import (
    empty_metrics,
    empty_timing,
    execute_in_physics,
    failure_of_exception,
    failure_of_plan,
    failure_of_task,
    limit_metrics,
    step_times,
    task_metrics,
    timing_metrics,
    trajectory_metrics,
)
from twin.compare.spec import RunTask
from twin.config import PlannerBlock, load_config, with_planner
from twin.errors import TwinError
from twin.planning import limit_ratios, limits_from_settings, make_context, make_planner, plan_with
from twin.problems.cells import QueryCell, cell_for
from twin.problems.sampling import sample_query, straight_free
from twin.rerun_log import RerunRecording
from twin.types import JointGoal, MotionRequest, Pose, PoseGoal

if TYPE_CHECKING:
    from twin.config import Settings
    from twin.world import World

__all__ = [
    "TASKS_UNAVAILABLE",
    "error_row",
    "execute_run",
    "worker_init",
]

log = logging.getLogger("twin")

TASKS_UNAVAILABLE = "skipped: twin.tasks not available"
_QUERIES: dict[tuple[Any, ...], dict[str, Any]] = {}  # random queries drawn in this process (`_drawn_query`)
_STRAIGHT_FREE: dict[tuple[Any, str], bool | None] = {}  # (cell key, query) -> its straight motion is free


# the native thread pools a worker process sizes from the environment when it first loads them: OpenMP
# (open3d's clustering and neighbour searches) and Mesa's llvmpipe (EGL rendering)
THREAD_ENV = ("OMP_NUM_THREADS", "LP_NUM_THREADS")


def worker_init(threads: int | None = None) -> None:
    """Process-pool initializer: C-level writes of PyBullet and planner backends (PyBullet's import banner
    on stderr, solver chatter) go to /dev/null; Python's own stderr (warnings, tracebacks) still reaches
    the terminal through a duplicate of the original fd 2. `threads`: the worker's share of the CPUs, for
    the thread pools of `THREAD_ENV` unless the environment sets them (with one worker per CPU, a worker
    whose renderer and open3d each start a thread per CPU only makes the workers wait for each other: a
    RoboCup task run on each of 2 CPUs took 20 % longer; the results are the same)."""
    if threads is not None:
        for name in THREAD_ENV:
            os.environ.setdefault(name, str(max(1, threads)))
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


def _world(cell: QueryCell) -> World:
    if cell.world is None:
        from twin.world import World  # lazy: pybullet

        cell.world = World(cell.settings, cell.settings.seed, renderer="tiny", robot=cell.robot)
    return cell.world


def _drawn_query(task: RunTask, cell: QueryCell) -> dict[str, Any]:
    """The random query of `task`, drawn once per process: every planner of a sweep plans the same query
    (its generator is seeded by scenario, seed and index alone), so the second planner's draw, often
    hundreds of IK solutions and collision checks for a `straight: blocked` pair, would repeat the first's."""
    assert task.random is not None
    key = (
        task.config,
        task.overrides,
        task.unknown_fixtures,
        json.dumps(task.random, sort_keys=True),
        *task.random_seed(),
    )
    query = _QUERIES.get(key)
    if query is None:
        query = _QUERIES[key] = sample_query(
            task.random,
            np.random.default_rng(task.random_seed()),
            scene=cell.scene,
            kin=cell.kin,
            home=np.asarray(cell.settings.robot.home, dtype=float),
            resolution_rad=cell.settings.collision.check_resolution_rad,
        )
    return query


def _request(task: RunTask, query: dict[str, Any], settings: Settings) -> MotionRequest:
    if query.get("goal") is not None:
        goal: Any = JointGoal(query["goal"])
    else:
        x, y, z, r, p, yw = query["goal_pose"]
        pose = Pose.from_xyz_rpy((x, y, z), (r, p, yw))
        if query.get("orientation_free"):
            tol = query.get("position_tolerance_m") or 0.03
            goal = PoseGoal(
                pose, frame=query.get("frame", "tcp"), position_tolerance_m=tol, orientation_tolerance_rad=None
            )
        elif query.get("position_tolerance_m"):
            goal = PoseGoal(pose, frame=query.get("frame", "tcp"), position_tolerance_m=query["position_tolerance_m"])
        else:
            goal = PoseGoal(pose, frame=query.get("frame", "tcp"))
    return MotionRequest(
        start=query["start"],
        goal=goal,
        limits=limits_from_settings(settings),
        time_limit_s=task.time_limit_s,
        seed=task.seed,
    )


def _run_query(task: RunTask, row: dict[str, Any], rerun: str | None = None) -> None:
    cell = cell_for(task.config, task.overrides, task.unknown_fixtures, task.problems, task.query_index)
    settings = cell.settings.model_copy(update={"seed": task.seed})
    query = dict(task.query) if task.query is not None else dict(_drawn_query(task, cell))
    row["query"] = query
    key = (cell.key, json.dumps(query, sort_keys=True))
    if key not in _STRAIGHT_FREE:  # the same for every planner of the query
        _STRAIGHT_FREE[key] = straight_free(
            query, scene=cell.scene, kin=cell.kin, resolution_rad=settings.collision.check_resolution_rad
        )
    row["straight_free"] = _STRAIGHT_FREE[key]
    request = _request(task, query, settings)
    context = make_context(settings, robot=cell.robot)
    planner = make_planner(PlannerBlock(**task.planner), context)
    result = plan_with(planner, request, cell.scene, context)
    timing, solves = timing_metrics(result)
    row["timing"].update({k: v for k, v in timing.items() if v is not None})
    row["step_times_s"] = step_times(result)
    row["status"] = result.status.value
    row["reason"] = result.reason
    row["success"] = result.success
    row["failure"] = failure_of_plan(result.status.value, result.reason, result.info)
    row["metrics"]["solves"] = solves
    fallback = result.info.get("fallback_steps") if isinstance(result.info, dict) else None
    row["metrics"]["fallback_steps"] = None if fallback is None else int(fallback)
    row["metrics"].update(limit_metrics(limit_ratios(result)))  # a refused motion's too: why it was refused
    if rerun is not None:  # `twin replay`: the query, its plan and its verdict as a recording
        recording = RerunRecording(rerun, scene=cell.scene, kin=cell.kin, recording_id=task.run_id)
        recording.query(request, result, task.planner_id)
        recording.close()
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


def _run_task(task: RunTask, row: dict[str, Any], rerun: str | None = None) -> None:
    try:
        from twin.tasks import run_task  # lazy: tests substitute twin.tasks.run_task
    except ImportError:
        row["status"], row["reason"], row["success"] = "skipped", TASKS_UNAVAILABLE, None
        return
    # the whole planner block (params, retimer) is the transfer planner, so two variants of one planner
    # are two different task runs
    block = PlannerBlock(**task.planner)
    settings = with_planner(load_config(task.config, task.overrides), "transfer", block)
    summary = run_task(settings, seed=task.seed, config_name=os.path.basename(task.config), rerun=rerun)
    m = task_metrics(summary)
    row["metrics"].update(m)
    row["success"] = summary.success_rate >= 1.0
    row["status"] = "success" if row["success"] else "incomplete"
    failed = [o for o in summary.objects if not o.placed]
    row["reason"] = "; ".join(f"{o.id}: {o.error}" for o in failed)
    # the first object not placed, by the name its failed stage gave (the reason's words for older outcomes)
    row["failure"] = (failed[0].failure or failure_of_task([failed[0].error or ""])) if failed else None
    row.update(task_attribution(failed))
    # the judge's limit ratios over the compared (transfer) planner's motions
    transfer = summary.metrics.get(block.name, {}) if isinstance(summary.metrics, dict) else {}
    row["metrics"].update({k: transfer.get(k) for k in limit_metrics({})})
    if transfer.get("motions"):
        row["timing"]["task_planning_time_s"] = float(transfer["planning_time_s"]) / int(transfer["motions"])
    row["timing"]["wall_time_s"] = float(summary.wall_time_s)
    row["task"] = summary.to_json()  # per-object outcomes and the run's planner metrics


def task_attribution(failed: list[Any]) -> dict[str, Any]:
    """Where a task row failed (its first object not placed, `ObjectOutcome`s): the stage and the planner
    that planned it, and whether that stage was one the compared planner plans (`failure_in`: "planner";
    its stages are those of the `transfer` group, physics during its motion included: an object dropped in
    its transfer is its failure) or one it does not ("elsewhere": the fixed stages, perception, grasping).
    Also the count of objects lost each way."""
    from twin.tasks.cell import STAGE_GROUPS  # lazy: fcl, scipy

    def mine(o: Any) -> bool:
        return STAGE_GROUPS.get(o.stage or "") == "transfer"

    first = failed[0] if failed else None
    return {
        "failed_stage": first.stage if first else None,
        "failed_planner": first.planner if first else None,
        "failure_in": None if first is None else ("planner" if mine(first) else "elsewhere"),
        "objects_failed_in_planner": sum(mine(o) for o in failed),
        "objects_failed_elsewhere": sum(not mine(o) for o in failed),
    }


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


def execute_run(task: RunTask, *, rerun: str | None = None) -> dict[str, Any]:
    """Run one (planner, case, seed) and return its row (a JSON-ready dict); `rerun`: also write a Rerun recording
    of it there (`twin replay`).

    A planner that raises (a broken contract, a missing backend) gives a row with status 'error' and
    the message, so one bad run never stops a sweep.
    """
    t0 = time.perf_counter()
    row = _new_row(task)
    try:
        if task.kind == "query":
            _run_query(task, row, rerun)
        else:
            _run_task(task, row, rerun)
    except Exception as e:  # noqa: BLE001 - one failing run is a result, not the end of the sweep
        if isinstance(e, TwinError):  # a typed error says what is wrong; its traceback is noise
            log.warning("run %s failed: %s", task.run_id, e)
        else:
            log.warning("run %s failed: %s\n%s", task.run_id, e, traceback.format_exc())
        row["status"], row["reason"], row["success"] = "error", f"{type(e).__name__}: {e}", False
        row["failure"] = failure_of_exception(e)
    if row["timing"].get("wall_time_s") is None:
        row["timing"]["wall_time_s"] = time.perf_counter() - t0
    return json_safe(row)


def error_row(task: RunTask, reason: str, *, wall_time_s: float | None = None) -> dict[str, Any]:
    """The row of a run that never returned its own (its worker was stopped or died): status 'error'."""
    row = _new_row(task)
    row["status"], row["reason"], row["success"] = "error", reason, False
    row["failure"] = "error"
    row["timing"]["wall_time_s"] = wall_time_s
    return json_safe(row)


def _new_row(task: RunTask) -> dict[str, Any]:
    return {
        "run_id": task.run_id,
        "planner": task.planner_id,
        "planner_name": task.planner["name"],
        "scenario": task.scenario,
        "case": task.case,
        "kind": task.kind,
        "seed": task.seed,
        "sweep": dict(task.sweep) if task.sweep else None,  # the sweep level {key: value}; None without a sweep
        "sweep_axes": list(task.sweep_axes) if task.sweep else None,  # the swept keys whose axis it lies on
        "status": None,
        "reason": "",
        "success": False,
        "failure": None,  # a FAILURES key when the run failed (twin.compare.metrics)
        "query": task.query,
        "time_limit_s": task.time_limit_s if task.kind == "query" else None,
        "straight_free": None,
        "metrics": empty_metrics(),
        "timing": empty_timing(),
        "step_times_s": {},  # a planner's own steps (its info's `<step>_time_s`: search, simplify, retime, ...)
        "clearance_pair": None,
        "contact_pairs": [],
        "task": None,
    }
