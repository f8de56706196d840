"""Execute trajectories on the simulated arm: joint position control at the physics rate.

One-shot plans are played open-loop (the position controller tracks q(t) with qd(t) as feed-forward);
receding-horizon planners run closed-loop: every segment starts from the measured joint state.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.planning import OneShotPlanner, RecedingHorizonPlanner, plan_with
from twin.registry import PluginContext
from twin.types import MotionRequest, MotionResult, Status, Trajectory

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.world import World

__all__ = ["ExecutionReport", "execute", "plan_and_execute", "MotionRecord"]

log = logging.getLogger("twin")


@dataclass(frozen=True)
class ExecutionReport:
    """How the arm followed a trajectory: simulated seconds, the worst tracking error, where it ended."""

    sim_duration_s: float
    max_tracking_error_rad: float
    final_q: np.ndarray
    unexpected_contacts: int


@dataclass
class MotionRecord:
    """One planned and executed motion, for run metrics."""

    stage: str
    planner: str
    status: str
    reason: str
    planning_time_s: float
    duration_s: float
    solves: int = 0
    info: dict[str, Any] = field(default_factory=dict)


def execute(
    world: "World",
    traj: Trajectory,
    *,
    hold_s: float = 0.0,
    ignore_bodies: tuple[int, ...] = (),
    on_step: Callable[[], None] | None = None,
) -> ExecutionReport:
    """Play `traj` on the arm at the physics rate, then hold its last point for `hold_s`.

    Counts steps in which the arm touches something other than `ignore_bodies` (a held object or the
    object being grasped) as unexpected contacts (sampled every 8 steps); `on_step` is called after
    every physics step, for callers that measure more.
    """
    dt = world.dt
    n = int(np.ceil(traj.duration / dt - 1e-9))
    worst = 0.0
    contacts = 0
    if n:
        qs, qds, _ = traj.sample(np.minimum(np.arange(1, n + 1) * dt, traj.duration) + traj.t[0])
    for k in range(n):
        world.set_joint_targets(qs[k], qds[k])
        world.step()
        if on_step is not None:
            on_step()
        worst = max(worst, float(np.abs(world.joint_positions() - qs[k]).max()))
        if (k + 1) % 8 == 0 and world.robot_contacts(ignore=ignore_bodies):
            contacts += 1
    world.set_joint_targets(traj.q[-1])
    hold = int(round(hold_s / dt))
    for _ in range(hold):
        world.step()
        if on_step is not None:
            on_step()
    return ExecutionReport(n * dt + hold * dt, worst, world.joint_positions(), contacts)


def plan_and_execute(
    world: "World",
    planner: Any,
    request: MotionRequest,
    scene: "PlanningScene",
    context: PluginContext,
    *,
    stage: str,
    planner_name: str,
    hold_s: float = 0.1,
    ignore_bodies: tuple[int, ...] = (),
) -> tuple[MotionResult, MotionRecord]:
    """Plan with a one-shot planner and play the result, or run a receding-horizon planner closed-loop."""
    if isinstance(planner, RecedingHorizonPlanner) and not isinstance(planner, OneShotPlanner):
        return _closed_loop(world, planner, request, scene, stage=stage, planner_name=planner_name, hold_s=hold_s, ignore_bodies=ignore_bodies)
    result = plan_with(planner, request, scene, context)
    record = MotionRecord(stage, planner_name, result.status.value, result.reason, result.planning_time_s, 0.0)
    if result.success:
        assert result.trajectory is not None
        rep = execute(world, result.trajectory, hold_s=hold_s, ignore_bodies=ignore_bodies)
        record.duration_s = result.trajectory.duration
        record.info["max_tracking_error_rad"] = rep.max_tracking_error_rad
        record.info["unexpected_contacts"] = rep.unexpected_contacts
    return result, record


def _closed_loop(
    world: "World",
    planner: RecedingHorizonPlanner,
    request: MotionRequest,
    scene: "PlanningScene",
    *,
    stage: str,
    planner_name: str,
    hold_s: float,
    ignore_bodies: tuple[int, ...],
    max_segments: int = 1000,
) -> tuple[MotionResult, MotionRecord]:
    t0 = time.perf_counter()
    planner.reset(request, scene)
    solve_times: list[float] = []
    duration = 0.0
    contacts = 0
    result: MotionResult | None = None
    for _ in range(max_segments):
        out = planner.step(world.joint_positions())
        if isinstance(out, MotionResult):
            result = out
            break
        solve_times.append(out.solve_time_s)
        rep = execute(world, out.trajectory, ignore_bodies=ignore_bodies)
        duration += out.trajectory.duration
        contacts += rep.unexpected_contacts
    if result is None:
        result = MotionResult(Status.NO_SOLUTION, f"no end after {max_segments} segments")
    if hold_s:
        world.step(int(round(hold_s / world.dt)))
    elapsed = time.perf_counter() - t0
    record = MotionRecord(
        stage, planner_name, result.status.value, result.reason, float(sum(solve_times)) or elapsed, duration,
        solves=len(solve_times), info={"solve_times_s": solve_times, "unexpected_contacts": contacts},
    )
    return result, record
