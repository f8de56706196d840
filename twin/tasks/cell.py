"""The cell a task drives: world, kinematics, FCL scene, stage planners, and the motions done so far.

Tasks speak in stages ("hover", "descent", "transfer", ...). Each stage maps to a planner block of the
config (`planners.<group>`), so swapping a planner is a config change; `--planner` replaces `transfer`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from twin.collision import PlanningScene
from twin.config import PlannerBlock, Settings
from twin.executor import MotionRecord, plan_and_execute
from twin.planning import limits_from_settings, make_context, make_planner
from twin.types import JointGoal, MotionRequest, MotionResult, Pose, PoseGoal, Status

__all__ = ["Cell", "StageFailed", "STAGE_GROUPS", "stage_block", "stage_planners", "top_down"]

log = logging.getLogger("twin")

# stage -> planner group in `settings.planners`
STAGE_GROUPS = {
    "capture": "movej",
    "align": "movej",
    "hover": "movej",
    "home": "movej",
    "descent": "movel",
    "ascent": "movel",
    "place": "movel",
    "transfer": "transfer",
}
DEFAULT_PLANNERS = {"movej": "ruckig.movej", "movel": "toppra.movel", "transfer": "ruckig.movej"}


class StageFailed(Exception):
    """A stage could not be done; the task logs the reason and moves on to the next object."""

    def __init__(self, stage: str, reason: str):
        super().__init__(f"{stage}: {reason}")
        self.stage = stage
        self.reason = reason


def top_down(xyz: np.ndarray | tuple[float, float, float], yaw: float) -> np.ndarray:
    """(4, 4) tcp pose at `xyz` pointing straight down, fingers closing along (cos yaw, sin yaw, 0)."""
    return Pose.from_xyz_rpy(tuple(float(v) for v in xyz), (math.pi, 0.0, float(yaw))).matrix()


def stage_block(settings: Settings, group: str, planner_override: str | None = None) -> PlannerBlock:
    """The planner block of a stage group: `--planner` for transfer, else the config, else the default."""
    if group == "transfer" and planner_override:
        return PlannerBlock(name=planner_override)
    b = settings.planners.get(group)
    return b if b is not None else PlannerBlock(name=DEFAULT_PLANNERS[group])


def stage_planners(settings: Settings, planner_override: str | None = None) -> dict[str, Any]:
    """Every stage planner, built up front: a bad name or parameter fails before anything is simulated."""
    context = make_context(settings)
    return {g: make_planner(stage_block(settings, g, planner_override), context) for g in sorted(set(STAGE_GROUPS.values()))}


@dataclass
class Cell:
    """Everything a task needs to move the robot; built once per run."""

    settings: Settings
    world: Any  # twin.world.World
    planner_override: str | None = None
    on_stage: Callable[[str], None] | None = None
    records: list[MotionRecord] = field(default_factory=list)

    planners: dict[str, Any] = field(default_factory=dict)  # built ahead by `stage_planners`, else lazily

    def __post_init__(self) -> None:
        self.context = make_context(self.settings)
        self.kin = self.context.kinematics
        self.scene = PlanningScene.from_settings(self.settings)
        self.limits = limits_from_settings(self.settings)
        self.held_body: int | None = None
        self.current = ""  # what the task works on, shown beside the stage in progress displays

    # ---- planners -------------------------------------------------------------------------------
    def block(self, group: str) -> PlannerBlock:
        return stage_block(self.settings, group, self.planner_override)

    def planner(self, group: str) -> Any:
        if group not in self.planners:
            self.planners[group] = make_planner(self.block(group), self.context)
        return self.planners[group]

    # ---- motion ---------------------------------------------------------------------------------
    def move(self, stage: str, goal: JointGoal | PoseGoal, *, time_limit_s: float = 2.0) -> MotionResult:
        """Plan from the measured joints to `goal` with the stage's planner and execute it; StageFailed if not."""
        if self.on_stage:
            self.on_stage(f"{self.current}: {stage}" if self.current else stage)
        group = STAGE_GROUPS[stage]
        name = self.block(group).name
        request = MotionRequest(self.world.joint_positions(), goal, self.limits, time_limit_s=time_limit_s, seed=self.world.seed)
        ignore = (self.held_body,) if self.held_body is not None else ()
        result, record = plan_and_execute(
            self.world, self.planner(group), request, self.scene, self.context, stage=stage, planner_name=name, ignore_bodies=ignore
        )
        self.records.append(record)
        if result.status is not Status.SUCCESS:
            raise StageFailed(stage, f"{name}: {result.status.value}: {result.reason}")
        return result

    def move_pose(self, stage: str, T_tcp: np.ndarray, **kw: Any) -> MotionResult:
        return self.move(stage, PoseGoal(Pose.from_matrix(T_tcp)), **kw)

    def move_joints(self, stage: str, q: np.ndarray, **kw: Any) -> MotionResult:
        return self.move(stage, JointGoal(np.asarray(q, dtype=float)), **kw)

    # ---- gripper --------------------------------------------------------------------------------
    def settle(self, seconds: float) -> None:
        self.world.step(int(round(seconds / self.world.dt)))

    def open_gripper(self, width_m: float | None = None) -> None:
        if width_m is None:
            self.world.open_gripper()
        else:
            self.world.set_gripper_opening(width_m)
        self.settle(self.settings.task.settle_s)
        self.scene.set_gripper_opening(min(self.world.gripper_opening(), self.scene.max_opening_m))

    def close_gripper(self) -> int | None:
        """Close force-limited, settle; returns the body held between the fingers (None if nothing)."""
        self.world.close_gripper()
        self.settle(self.settings.task.settle_s)
        self.held_body = self.world.grasped_object()
        self.scene.set_gripper_opening(min(self.world.gripper_opening(), self.scene.max_opening_m))
        return self.held_body

    def attach(self, name: str, size: np.ndarray, *, below_tcp_m: float = 0.0) -> None:
        """Tell the planning scene the gripper holds a box of `size` (3,), its centre `below_tcp_m` under
        the tcp (along the tcp's z axis, which points down when grasping from above)."""
        T = np.eye(4)
        T[2, 3] = below_tcp_m
        self.scene.attach_box(name, size, T)

    def release(self) -> None:
        self.open_gripper()
        self.scene.detach()
        self.held_body = None

    def recover(self) -> None:
        """After a failed stage: let go, forget the held model, rise straight up to 0.3 m if a planner can."""
        self.release()
        T = self.kin.fk(self.world.joint_positions())
        T[2, 3] = max(T[2, 3], 0.30)
        try:
            self.move_pose("ascent", T)
        except StageFailed:
            log.info("recovery: could not rise from %s", np.round(T[:3, 3], 3).tolist())

    # ---- bookkeeping ----------------------------------------------------------------------------
    def metrics(self) -> dict[str, Any]:
        """Planner metrics over the run: per planner, motions, successes, planning and motion time."""
        out: dict[str, Any] = {}
        for r in self.records:
            m = out.setdefault(r.planner, {"motions": 0, "succeeded": 0, "planning_time_s": 0.0, "motion_time_s": 0.0, "solves": 0})
            m["motions"] += 1
            m["succeeded"] += r.status == "success"
            m["planning_time_s"] += r.planning_time_s
            m["motion_time_s"] += r.duration_s
            m["solves"] += r.solves
        return out
