"""The cell a task drives: world, kinematics, FCL scene, stage planners, and the motions done so far.

Tasks speak in stages ("hover", "descent", "transfer", ...). Each stage maps to a planner block of the
config (`planners.<group>`), so swapping a planner is a config change; `--planner` replaces `transfer`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np

from twin.collision import PlanningScene
from twin.config import PlannerBlock, Settings
from twin.errors import ConfigError
from twin.executor import MotionRecord, plan_and_execute
from twin.failures import failure_of_plan
from twin.limit_check import RATIO_METRICS
from twin.planning import CheckedPlanner, describe_goal_kinds, limits_from_settings, make_context, make_planner
from twin.types import JointGoal, MotionRequest, MotionResult, Pose, PoseGoal, Status

__all__ = [
    "STAGES",
    "STAGE_GROUPS",
    "Cell",
    "GraspCheck",
    "GripStatus",
    "GripperReading",
    "StageFailed",
    "stage_block",
    "stage_planners",
    "top_down",
]

log = logging.getLogger("twin")

# stage -> (planner group in `settings.planners`, the kind of goal it asks for). A transfer ends above
# the place point and the place move finishes it, so it asks for a position within
# `task.transfer_tolerance_m` with the orientation free; every other stage for an exact goal.
STAGES: dict[str, tuple[str, str]] = {
    "capture": ("movej", "joint"),
    "align": ("movej", "joint"),
    "hover": ("movej", "pose"),
    "home": ("movej", "joint"),
    "descent": ("movel", "pose"),
    "ascent": ("movel", "pose"),
    "place": ("movel", "pose"),
    "transfer": ("transfer", "position"),
}
STAGE_GROUPS = {stage: group for stage, (group, _) in STAGES.items()}
DEFAULT_PLANNERS = {"movej": "ruckig.movej", "movel": "toppra.movel", "transfer": "ruckig.movej"}
# stages in which the fingers work at an object: a finger touching a loose object is not a fault there
_GRASPING_STAGES = frozenset({"descent", "ascent", "place"})


class StageFailed(Exception):
    """A stage could not be done; the task logs the reason and moves on to the next object.

    `failure`: the failure's name (a `twin.failures.FAILURES` key) when the stage knows it, as a motion
    that failed does from its planner's result and the judge's verdict; None leaves it to the reason."""

    def __init__(self, stage: str, reason: str, *, failure: str | None = None):
        super().__init__(f"{stage}: {reason}")
        self.stage = stage
        self.reason = reason
        self.failure = failure


def top_down(xyz: np.ndarray | tuple[float, float, float], yaw: float) -> np.ndarray:
    """(4, 4) tcp pose at `xyz` pointing straight down, fingers closing along (cos yaw, sin yaw, 0)."""
    return Pose.from_xyz_rpy(tuple(float(v) for v in xyz), (math.pi, 0.0, float(yaw))).matrix()


def stage_block(settings: Settings, group: str, planner_override: str | None = None) -> PlannerBlock:
    """The planner block of a stage group: `--planner` for transfer, else the config, else the default."""
    if group == "transfer" and planner_override:
        return PlannerBlock(name=planner_override)
    b = settings.planners.get(group)
    return b if b is not None else PlannerBlock(name=DEFAULT_PLANNERS[group])


def stage_planners(settings: Settings, planner_override: str | None = None) -> dict[str, CheckedPlanner]:
    """Every stage planner, built up front: a bad name or parameter, or a planner that cannot reach the
    kind of goal its stages ask for, fails (ConfigError, one line) before anything is simulated."""
    context = make_context(settings)
    out: dict[str, CheckedPlanner] = {}
    for group in sorted(set(STAGE_GROUPS.values())):
        block = stage_block(settings, group, planner_override)
        planner = make_planner(block, context)
        needed = {kind for g, kind in STAGES.values() if g == group}
        missing = {k for k in needed if not planner.serves(k)}
        if missing:
            stages = ", ".join(s for s, (g, k) in STAGES.items() if g == group and k in missing)
            raise ConfigError(
                f"planners.{group}: {block.name} cannot reach {describe_goal_kinds(missing)}, "
                f"which stages {stages} ask for; it serves {describe_goal_kinds(planner.goal_kinds)}. "
                f"Choose another planner for {group} (`twin planners`)"
            )
        out[group] = planner
    return out


_GRIPPER_POLL_S = 0.02  # the gripper's status is polled this long; free fingers are moving within a step


class GripStatus(Enum):
    """What the gripper's finger position says about a grasp (a Robotiq 2F-85's "object detected" status)."""

    HOLDING = "holding"  # the fingers stopped on something of the expected width, or still hold it
    NOTHING = "nothing"  # the fingers closed (nearly) fully: nothing between them
    WRONG_WIDTH = "wrong_width"  # they stopped on something, but not as wide as the object should be
    LOST = "lost"  # the opening fell below the one sensed at the grasp: the object slipped out or dropped


@dataclass(frozen=True)
class GripperReading:
    """The gripper's sensor readings: opening between the pads (finger encoders), m; whether both fingers
    have stopped; mean finger motor effort, N."""

    opening_m: float
    settled: bool
    effort_n: float


@dataclass(frozen=True)
class GraspCheck:
    """A grasp judged from the gripper's readings alone; `reason` says why it is not HOLDING."""

    status: GripStatus
    opening_m: float
    reason: str = ""
    expect_width_m: tuple[float, float] | None = None  # what the task expected between the fingers, (min, max) m

    @property
    def holding(self) -> bool:
        return self.status is GripStatus.HOLDING


@dataclass
class Cell:
    """Everything a task needs to move the robot; built once per run."""

    settings: Settings
    world: Any  # twin.world.World
    planner_override: str | None = None
    on_stage: Callable[[str], None] | None = None
    records: list[MotionRecord] = field(default_factory=list)

    planners: dict[str, CheckedPlanner] = field(default_factory=dict)  # built ahead by `stage_planners`, else here

    def __post_init__(self) -> None:
        if not self.planners:
            self.planners = stage_planners(self.settings, self.planner_override)
        self.context = make_context(self.settings)
        self.kin = self.context.kinematics
        # the cell knows its fixtures; obstacles marked `known: false` are what the task perceives and adds
        self.scene = PlanningScene.from_settings(self.settings, unknown_fixtures="ignore")
        self.limits = limits_from_settings(self.settings)
        self.held_body: int | None = (
            None  # the simulated safety monitor's (judge.body_between_fingers); no task decides with it
        )
        self.grasp: GraspCheck | None = None  # the current grasp as sensed when it closed (None: not holding)
        self.current = ""  # what the task works on, shown beside the stage in progress displays

    # ---- planners -------------------------------------------------------------------------------
    def block(self, group: str) -> PlannerBlock:
        return stage_block(self.settings, group, self.planner_override)

    def planner(self, group: str) -> CheckedPlanner:
        return self.planners[group]

    # ---- motion ---------------------------------------------------------------------------------
    def move(
        self, stage: str, goal: JointGoal | PoseGoal, *, time_limit_s: float = 2.0, retreat: bool = False
    ) -> MotionResult:
        """Plan from the measured joints to `goal` with the stage's planner and execute it through the
        checked loop; StageFailed (with the planner's or the safety stop's reason) if it does not get there.

        `retreat`: a move away after a protective stop; the safety monitor does not stop it for touching
        the loose objects the robot touches as it starts (it is moving off them), only for anything new."""
        if self.on_stage:
            self.on_stage(f"{self.current}: {stage}" if self.current else stage)
        group = STAGE_GROUPS[stage]
        name = self.block(group).name
        request = MotionRequest(
            self.world.joint_positions(), goal, self.limits, time_limit_s=time_limit_s, seed=self.world.seed
        )
        ignore: tuple[int, ...] = (self.held_body,) if self.held_body is not None else ()
        if retreat:
            ignore = tuple(sorted(set(ignore) | set(self.world.touched_objects())))
        result, record = plan_and_execute(
            self.world,
            self.planner(group),
            request,
            self.scene,
            self.context,
            stage=stage,
            planner_name=name,
            ignore_bodies=ignore,
            fingers_may_touch_objects=stage in _GRASPING_STAGES,
        )
        self.records.append(record)
        if result.status is not Status.SUCCESS:
            raise StageFailed(
                stage,
                f"{name}: {result.status.value}: {result.reason}",
                failure=failure_of_plan(result.status.value, result.reason, result.info),
            )
        return result

    def move_pose(self, stage: str, T_tcp: np.ndarray, **kw: Any) -> MotionResult:
        """Move the tcp to `T_tcp` (4, 4); a stage that asks for a position only (the transfer) gets the
        orientation free and `task.transfer_tolerance_m` on the position."""
        pose = Pose.from_matrix(T_tcp)
        if STAGES[stage][1] == "position":
            goal = PoseGoal(
                pose, position_tolerance_m=self.settings.task.transfer_tolerance_m, orientation_tolerance_rad=None
            )
        else:
            goal = PoseGoal(pose)
        return self.move(stage, goal, **kw)

    def move_joints(self, stage: str, q: np.ndarray, **kw: Any) -> MotionResult:
        return self.move(stage, JointGoal(np.asarray(q, dtype=float)), **kw)

    # ---- gripper --------------------------------------------------------------------------------
    def settle(self, seconds: float) -> None:
        self.world.step(round(seconds / self.world.dt))

    def open_gripper(self, width_m: float | None = None) -> None:
        if width_m is None:
            self.world.open_gripper()
        else:
            self.world.set_gripper_opening(width_m)
        self.settle(self.settings.task.settle_s)
        self.scene.set_gripper_opening(float(np.clip(self.world.gripper_opening(), 0.0, self.scene.max_opening_m)))

    def read_gripper(self, *, wait_s: float | None = None, speed_m_s: float | None = None) -> GripperReading:
        """The gripper's readings once both fingers have stopped, waiting at most `wait_s` for that (default:
        a full stroke at `speed_m_s` (default gripper.speed_m_s), or task.settle_s if longer): fingers still
        moving say nothing yet about what is between them."""
        g = self.settings.gripper
        speed = g.speed_m_s if speed_m_s is None else float(speed_m_s)
        wait = max(self.settings.task.settle_s, g.max_opening_m / speed) if wait_s is None else float(wait_s)
        for _ in range(round(wait / self.world.dt)):
            if self.world.gripper_settled():
                break
            self.world.step()
        return GripperReading(self.world.gripper_opening(), self.world.gripper_settled(), self.world.gripper_effort())

    def close_gripper(
        self,
        expect_width_m: tuple[float, float] | None = None,
        *,
        force_n: float | None = None,
        speed_m_s: float | None = None,
    ) -> GraspCheck:
        """Close force-limited, settle, and judge the grasp by the finger position alone, as the 2F-85's
        "object detected" status does: holding when the fingers stopped clearly above fully closed
        (`gripper.object_min_opening_m`) and, when the task knows the width range (min, max) m that should
        lie between the fingers (from the perceived class and orientation), no more than
        `gripper.width_over_tolerance_m` wider and no more than `gripper.width_under_tolerance_m` narrower.
        `force_n`, `speed_m_s`: a gentler grip than the gripper's defaults."""
        from twin.tasks.judge import body_between_fingers  # the one ground-truth read here, kept in the judge

        g = self.settings.gripper
        self.world.close_gripper(force_n=force_n, speed_m_s=speed_m_s)
        self.settle(self.settings.task.settle_s)
        r = self.read_gripper(speed_m_s=speed_m_s)
        self.scene.set_gripper_opening(
            float(np.clip(r.opening_m, 0.0, self.scene.max_opening_m))
        )  # closed pads read a hair below 0
        self.held_body = body_between_fingers(self.world)  # feeds the simulated contact monitor only
        self.grasp = None
        mm = 1000.0 * r.opening_m
        if r.opening_m <= g.object_min_opening_m:
            check = GraspCheck(
                GripStatus.NOTHING,
                r.opening_m,
                f"nothing between the fingers after closing (they closed to {mm:.1f} mm)",
                expect_width_m,
            )
        elif expect_width_m is not None and not (
            expect_width_m[0] - g.width_under_tolerance_m <= r.opening_m <= expect_width_m[1] + g.width_over_tolerance_m
        ):
            lo, hi = (1000.0 * w for w in expect_width_m)
            want = f"{lo:.0f} mm" if abs(hi - lo) < 0.5 else f"{lo:.0f}-{hi:.0f} mm"
            check = GraspCheck(
                GripStatus.WRONG_WIDTH,
                r.opening_m,
                f"the fingers stopped at {mm:.1f} mm, but the object should be {want} across "
                f"(-{1000 * g.width_under_tolerance_m:.0f}/+{1000 * g.width_over_tolerance_m:.0f} mm)",
                expect_width_m,
            )
        else:
            check = GraspCheck(GripStatus.HOLDING, r.opening_m, "", expect_width_m)
            self.grasp = check
        log.debug("grasp: %s at %.1f mm (effort %.0f N, settled %s)", check.status.value, mm, r.effort_n, r.settled)
        return check

    def check_holding(self) -> GraspCheck:
        """Is the grasped object still between the fingers? The force-limited fingers keep closing when it
        leaves, so it is lost when the opening fell more than `gripper.slip_tolerance_m` below the opening
        sensed at the grasp and also below the narrowest the object itself can be held at (its expected
        width less `gripper.width_under_tolerance_m`): a box caught across its edges that turns square in
        the fingers narrows the opening by up to a third of its width and is still held."""
        g = self.settings.gripper
        self.settle(_GRIPPER_POLL_S)  # fingers whose object just left need a moment to start closing
        r = self.read_gripper()
        if self.grasp is None:
            return GraspCheck(GripStatus.NOTHING, r.opening_m, "no grasp closed on an object")
        floor = self.grasp.opening_m - g.slip_tolerance_m
        if self.grasp.expect_width_m is not None:
            floor = min(floor, self.grasp.expect_width_m[0] - g.width_under_tolerance_m)
        if r.opening_m < floor:
            return GraspCheck(
                GripStatus.LOST,
                r.opening_m,
                f"the fingers closed from {1000 * self.grasp.opening_m:.1f} mm at the grasp to "
                f"{1000 * r.opening_m:.1f} mm",
                self.grasp.expect_width_m,
            )
        return GraspCheck(GripStatus.HOLDING, r.opening_m, "", self.grasp.expect_width_m)

    def attach(self, name: str, size: np.ndarray, *, below_tcp_m: float = 0.0) -> None:
        """Tell the planning scene the gripper holds a box of `size` (3,), its centre `below_tcp_m` under
        the tcp (along the tcp's z axis, which points down when grasping from above)."""
        T = np.eye(4)
        T[2, 3] = below_tcp_m
        self.scene.attach_box(name, size, T)

    def release(self, width_m: float | None = None) -> None:
        """Let go: open to `width_m` (default fully) and forget the held object."""
        self.open_gripper(width_m)
        self.scene.detach()
        self.held_body = None
        self.grasp = None

    def recover(self) -> None:
        """After a failed stage: let go, forget the held model, rise straight up to 0.3 m if a planner can
        (a retreat: off whatever the gripper was stopped against)."""
        self.release()
        T = self.kin.fk(self.world.joint_positions())
        T[2, 3] = max(T[2, 3], 0.30)
        try:
            self.move_pose("ascent", T, retreat=True)
        except StageFailed:
            log.info("recovery: could not rise from %s", np.round(T[:3, 3], 3).tolist())

    # ---- bookkeeping ----------------------------------------------------------------------------
    def metrics(self) -> dict[str, Any]:
        """Planner metrics over the run: per planner, motions, successes, planning and motion time, solves,
        steps a receding-horizon planner followed without a solve (`fallback_steps`), motions stopped by an
        unexpected contact, and the largest joint velocity, acceleration and jerk over their limits that the
        judge measured in any of its motions (`max_vel_ratio`, ...; None when it judged none)."""
        out: dict[str, Any] = {}
        keys = (
            "motions",
            "succeeded",
            "planning_time_s",
            "motion_time_s",
            "solves",
            "fallback_steps",
            "unexpected_contacts",
            "collisions",
        )
        for r in self.records:
            m = out.setdefault(r.planner, dict.fromkeys(keys, 0))
            m["motions"] += 1
            m["succeeded"] += r.status == "success"
            m["planning_time_s"] += r.planning_time_s
            m["motion_time_s"] += r.duration_s
            m["solves"] += r.solves
            m["fallback_steps"] += r.fallback_steps
            m["unexpected_contacts"] += r.unexpected_contacts
            m["collisions"] += r.status == "collision"
            for kind, key in RATIO_METRICS.items():
                if kind in r.limit_ratios:
                    m[key] = max(m.get(key) or 0.0, r.limit_ratios[kind])
        for m in out.values():
            for key in RATIO_METRICS.values():
                m.setdefault(key, None)
        return out
