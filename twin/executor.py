"""Execute checked motion on the simulated arm: joint position control at the physics rate.

Every planner reaches the arm through `CheckedPlanner.drive` (`twin.planning`): a one-shot plan is one
checked piece, a receding-horizon planner one checked piece per step from the measured joint state. This
module is the plant on the other side: it plays each piece (the position controller tracks q(t) with
qd(t) as feed-forward) and watches the contacts as a real cell's protective stop would. A robot link
touching anything it should not (see `World.unexpected_contacts`) stops the arm where it is and ends
the motion with `Status.EXECUTION_STOPPED` and a reason ("unexpected contact: forearm_link with table").
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.planning import as_checked, limit_ratios
from twin.registry import PluginContext
from twin.types import MotionRequest, MotionResult, Trajectory

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.world import World

__all__ = ["CONTACT_CHECK_S", "ExecutionReport", "MotionRecord", "WorldPlant", "execute", "plan_and_execute"]

log = logging.getLogger("twin")

# simulated seconds between two looks at the contacts (the protective stop's reaction), whatever the physics rate
CONTACT_CHECK_S = 1.0 / 60.0


@dataclass(frozen=True)
class ExecutionReport:
    """How the arm followed a trajectory: simulated seconds, the worst tracking error, where it ended, and
    the unexpected contact that stopped it (None when it ran to the end)."""

    sim_duration_s: float
    max_tracking_error_rad: float
    final_q: np.ndarray
    stopped_by: str | None = None


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
    fallback_steps: int = 0
    unexpected_contacts: int = 0
    info: dict[str, Any] = field(default_factory=dict)
    limit_ratios: dict[str, float] = field(default_factory=dict)  # the judge's (twin.planning.limit_ratios)


def execute(
    world: World,
    traj: Trajectory,
    *,
    hold_s: float = 0.0,
    ignore_bodies: tuple[int, ...] = (),
    fingers_may_touch_objects: bool = False,
    stop_on_contact: bool = True,
    on_step: Callable[[], None] | None = None,
) -> ExecutionReport:
    """Play `traj` on the arm at the physics rate, then hold its last point for `hold_s`.

    Every `CONTACT_CHECK_S` the contacts are read: an unexpected one (anything but
    `ignore_bodies`; see `World.unexpected_contacts`) stops the arm at its measured position when
    `stop_on_contact`, and is reported. `on_step` is called after every physics step.
    """
    dt = world.dt
    n = int(np.ceil(traj.duration / dt - 1e-9))
    check_every = max(1, round(CONTACT_CHECK_S / dt))
    worst = 0.0
    stopped: str | None = None
    steps = 0
    if n:
        qs, qds, _ = traj.sample(np.minimum(np.arange(1, n + 1) * dt, traj.duration) + traj.t[0])
        measured = np.empty((n, 6))  # the joints after each step: the tracking error is taken once, at the end
    for k in range(n):
        world.set_joint_targets(qs[k], qds[k])
        world.step()
        steps += 1
        if on_step is not None:
            on_step()
        measured[k] = world.joint_positions()
        if stop_on_contact and (k + 1) % check_every == 0:
            hits = world.unexpected_contacts(ignore=ignore_bodies, fingers_may_touch_objects=fingers_may_touch_objects)
            if hits:
                stopped = "unexpected contact: " + ", ".join(f"{a} with {b}" for a, b in hits)
                break
    if steps:
        worst = max(worst, float(np.abs(measured[:steps] - qs[:steps]).max()))
    if stopped is not None:
        world.set_joint_targets(world.joint_positions())  # protective stop: hold where it is
        log.info("execution stopped: %s", stopped)
        return ExecutionReport(steps * dt, worst, world.joint_positions(), stopped)
    world.set_joint_targets(traj.q[-1])
    hold = int(round(hold_s / dt))
    for _ in range(hold):
        world.step()
        if on_step is not None:
            on_step()
    return ExecutionReport(n * dt + hold * dt, worst, world.joint_positions())


class WorldPlant:
    """The simulated arm as a plant for `CheckedPlanner.drive`: encoders in, checked pieces out, contacts watched."""

    def __init__(self, world: World, *, ignore_bodies: tuple[int, ...] = (), fingers_may_touch_objects: bool = False):
        self.world = world
        self.ignore_bodies = ignore_bodies
        self.fingers_may_touch_objects = fingers_may_touch_objects
        self.duration_s = 0.0
        self.max_tracking_error_rad = 0.0
        self.stops: list[str] = []

    def measured_q(self) -> np.ndarray:
        return self.world.joint_positions()

    def run(self, traj: Trajectory) -> str | None:
        rep = execute(
            self.world, traj, ignore_bodies=self.ignore_bodies, fingers_may_touch_objects=self.fingers_may_touch_objects
        )
        self.duration_s += rep.sim_duration_s
        self.max_tracking_error_rad = max(self.max_tracking_error_rad, rep.max_tracking_error_rad)
        if rep.stopped_by is not None:
            self.stops.append(rep.stopped_by)
        return rep.stopped_by


def plan_and_execute(
    world: World,
    planner: Any,
    request: MotionRequest,
    scene: PlanningScene,
    context: PluginContext,
    *,
    stage: str,
    planner_name: str,
    hold_s: float = 0.1,
    ignore_bodies: tuple[int, ...] = (),
    fingers_may_touch_objects: bool = False,
) -> tuple[MotionResult, MotionRecord]:
    """Plan and execute one motion through the single checked loop (`CheckedPlanner.drive`), then hold."""
    planner = as_checked(planner, context, name=planner_name)
    plant = WorldPlant(world, ignore_bodies=ignore_bodies, fingers_may_touch_objects=fingers_may_touch_objects)
    result = planner.drive(request, scene, plant)
    if hold_s and not plant.stops:
        world.step(int(round(hold_s / world.dt)))
    info = result.info
    record = MotionRecord(
        stage,
        planner_name,
        result.status.value,
        result.reason,
        result.planning_time_s,
        plant.duration_s,
        solves=int(info.get("solves", 0)),
        fallback_steps=int(info.get("fallback_steps", 0)),
        unexpected_contacts=len(plant.stops),
        limit_ratios=limit_ratios(result),
        info={
            "max_tracking_error_rad": plant.max_tracking_error_rad,
            "solve_times_s": list(info.get("solve_times_s", [])),
        },
    )
    return result, record
