"""The cell a task drives: world, kinematics, FCL scene, stage planners, and the motions done so far.

Tasks speak in stages ("hover", "descent", "transfer", ...). Each stage maps to a planner block of the
config (`planners.<group>`), so swapping a planner is a config change; `--planner` replaces `transfer`.

The cell senses (joints, gripper, camera frames for the trace), grasps, and executes checked motions; what it
decides with lives beside it: the choice of a way before moving (`twin.tasks.ways`), the ways round a refused
motion (`twin.tasks.detours`), a grasp judged from the finger position (`twin.tasks.grasping`), a stage's
failure (`twin.tasks.stage_failure`). Its methods stay the one face a task and a plugin use.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from twin.camera import RGBDFrame
from twin.collision import PlanningScene
from twin.config import DEFAULT_PLANNERS, STAGE_GROUPS, STAGES, PlannerBlock, Settings
from twin.errors import ConfigError, PluginCrashed
from twin.executor import MotionRecord, plan_and_execute
from twin.failures import failure_of_plan
from twin.limit_check import RATIO_METRICS
from twin.planning import (
    CheckedPlanner,
    describe_goal_kinds,
    limits_from_settings,
    make_context,
    make_planner,
)
from twin.registry import PluginContext
from twin.tasks import detours, jam
from twin.tasks.grasping import (
    GRIPPER_POLL_S,
    GraspCheck,
    GripperReading,
    GripStatus,
    grasp_check,
    holding_check,
    top_down,
)
from twin.tasks.judge import DisplacementWatch, body_between_fingers
from twin.tasks.recovery import back_off
from twin.tasks.stage_failure import StageFailed, clear_failure, note_failure
from twin.tasks.ways import CHOOSE_CLEARANCE_M, OVER_MARGIN_M, WayChooser, WayDown
from twin.types import CalibrationOutcome, JointGoal, MotionRequest, MotionResult, Pose, PoseGoal, Status

# StageFailed, the gripper's types, top_down, WayDown and the clearances are re-exported: the cell's face to
# tasks and plugins (`twin.plugin`), wherever they live
__all__ = [
    "CHOOSE_CLEARANCE_M",
    "DEFAULT_PLANNERS",
    "OVER_MARGIN_M",
    "STAGES",
    "STAGE_GROUPS",
    "Cell",
    "GraspCheck",
    "GripStatus",
    "GripperReading",
    "RunTrace",
    "Sighting",
    "StageFailed",
    "WayDown",
    "clear_failure",
    "note_failure",
    "planner_metrics",
    "stage_planners",
    "top_down",
]

log = logging.getLogger("twin")

# stages in which the fingers work at an object: a finger touching a loose object is not a fault there
_GRASPING_STAGES = frozenset({"descent", "ascent", "place"})


def stage_planners(settings: Settings, context: PluginContext) -> dict[str, CheckedPlanner]:
    """Every stage planner (each group's block: `PlannerGroups.block`), built up front in the run's `context`:
    a bad name or parameter, or a planner that cannot reach the kind of goal its stages ask for, fails
    (ConfigError, one line) before anything is simulated."""
    out: dict[str, CheckedPlanner] = {}
    for group in sorted(set(STAGE_GROUPS.values())):
        block = settings.planners.block(group)
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


@dataclass(frozen=True)
class Sighting:
    """One capture and what a task made of it: the frame, the camera pose it used (base frame), each object it saw
    as (label, position (3,)) and each obstacle box as (name, lo, hi)."""

    frame: RGBDFrame
    T_base_camera: np.ndarray
    objects: Sequence[tuple[str, np.ndarray]]
    boxes: Sequence[tuple[str, np.ndarray, np.ndarray]] = ()


class RunTrace(Protocol):
    """What a run's recording (`twin.rerun_log.RerunRecording`) is told by the cell: every stage it planned, and
    what every capture saw (`Cell.perceived`)."""

    def motion(
        self, sim_time_s: float, stage: str, planner: str, request: MotionRequest, result: MotionResult
    ) -> None: ...

    def perceived(self, sim_time_s: float, sighting: Sighting) -> None: ...


def planner_metrics(records: Sequence[MotionRecord]) -> dict[str, Any]:
    """Planner metrics over a run's motions `records`: per planner, motions, successes, planning and motion
    time, solves, steps a receding-horizon planner followed without a solve (`fallback_steps`), motions stopped by an
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
    for r in records:
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


@dataclass
class Cell:
    """Everything a task needs to move the robot; built once per run."""

    settings: Settings
    world: Any  # twin.world.World
    # the run's plugin context (its robot is the world's); None: made here, around the world's robot
    context: PluginContext | None = None
    on_stage: Callable[[str], None] | None = None
    records: list[MotionRecord] = field(default_factory=list)
    trace: RunTrace | None = None  # told every planned stage (a recording; None: none)
    # every exception a planner plugin raised in this run ("stage: plugin raised ..."), recovered from or not
    plugin_errors: list[str] = field(default_factory=list)

    planners: dict[str, CheckedPlanner] = field(default_factory=dict)  # built ahead by `stage_planners`, else here
    on_objects: Callable[[int, int], None] | None = None  # told (done, known) objects: `objects_done`
    # how the task knew its camera pose (set by the task; the run summary's `calibration`)
    calibration: CalibrationOutcome | None = None

    def __post_init__(self) -> None:
        context = self.context if self.context is not None else make_context(self.settings, robot=self.world.robot)
        self.context = self.run_context = context  # run_context: the same, typed as always there
        if not self.planners:
            self.planners = stage_planners(self.settings, context)
        self.robot = context.robot
        self.kin = self.robot.arm
        # the cell knows its fixtures; obstacles marked `known: false` are what the task perceives and adds
        self.scene = PlanningScene.from_settings(self.settings, robot=self.robot, unknown_fixtures="ignore")
        self.limits = limits_from_settings(self.settings)
        self.held_body: int | None = (
            None  # the simulated safety monitor's (judge.body_between_fingers); no task decides with it
        )
        self.grasp: GraspCheck | None = None  # the current grasp as sensed when it closed (None: not holding)
        self.current = ""  # what the task works on, shown beside the stage in progress displays
        self.watch = DisplacementWatch(self.world)  # judging only: the referees read it, no task does
        # the choices of a way before moving, in this cell's own scene and kinematics
        self.ways = WayChooser(self.kin, self.scene, float(self.settings.collision.check_resolution_rad))

    def objects_done(self, done: int, total: int) -> None:
        """Tell the progress display (`on_objects`, `twin run`'s) how many of the `total` objects the task knows
        of it is done with (placed or given up on); a task that never says shows its stages only."""
        if self.on_objects is not None:
            self.on_objects(done, total)

    # ---- planners -------------------------------------------------------------------------------
    def block(self, group: str) -> PlannerBlock:
        """The planner block of `group` (the config's, else the group's default)."""
        return self.settings.planners.block(group)

    def planner(self, group: str) -> CheckedPlanner:
        return self.planners[group]

    def stage_planner(self, stage: str) -> CheckedPlanner:
        """The planner of `stage`'s group (`STAGE_GROUPS`)."""
        return self.planners[STAGE_GROUPS[stage]]

    def perceived(
        self,
        frame: RGBDFrame,
        T_base_camera: np.ndarray,
        objects: Sequence[tuple[str, np.ndarray]],
        boxes: Sequence[tuple[str, np.ndarray, np.ndarray]] = (),
    ) -> None:
        """A task's capture and what it made of it (`Sighting`), for the run's trace."""
        if self.trace is not None:
            self.trace.perceived(self.world.sim_time, Sighting(frame, T_base_camera, objects, boxes))

    # ---- motion ---------------------------------------------------------------------------------
    def move(
        self, stage: str, goal: JointGoal | PoseGoal, *, time_limit_s: float = 2.0, retreat: bool = False
    ) -> MotionResult:
        """Plan from the measured joints to `goal` with the stage's planner and execute it through the
        checked loop; StageFailed (with the planner's or the safety stop's reason) if it does not get there.

        `retreat`: a move away after a protective stop; the safety monitor does not stop it for touching
        the loose objects the robot touches as it starts (it is moving off them), only for anything new.

        A start the planner refuses because it is in collision in the planning scene (after a contact, the
        gripper inside an obstacle or object perceived a little off) is backed off from
        (`twin.tasks.recovery.back_off`: a few cm along the way that separates the pair, checked) and the
        stage is planned once more; when that fails, the reason names the pair and why backing off failed."""
        if self.on_stage:
            self.on_stage(f"{self.current}: {stage}" if self.current else stage)
        group = STAGE_GROUPS[stage]
        name = self.block(group).name
        self.watch.before()
        try:
            backed_off = False
            while True:
                request = MotionRequest(
                    self.world.joint_positions(), goal, self.limits, time_limit_s=time_limit_s, seed=self.world.seed
                )
                ignore: tuple[int, ...] = (self.held_body,) if self.held_body is not None else ()
                planned_at = self.world.sim_time
                if retreat:
                    ignore = tuple(sorted(set(ignore) | set(self.world.touched_objects())))
                try:
                    result, record = plan_and_execute(
                        self.world,
                        self.planner(group),
                        request,
                        self.scene,
                        self.run_context,
                        stage=stage,
                        planner_name=name,
                        ignore_bodies=ignore,
                        fingers_may_touch_objects=stage in _GRASPING_STAGES,
                    )
                except PluginCrashed as e:  # the stage fails with the plugin's exception; the run goes on
                    if not any(str(e) in seen for seen in self.plugin_errors):  # a repeat: once is enough
                        log.warning("%s: %s (the stage failed; the run goes on)", stage, e)
                        log.info("the traceback of %s:", e.plugin, exc_info=e.error)  # with -v
                    self.plugin_errors.append(f"{stage}: {e}")
                    raise StageFailed(stage, str(e), failure="plugin_error", planner=name) from e
                self.records.append(record)
                if self.trace is not None:
                    self.trace.motion(planned_at, stage, name, request, result)
                if (
                    backed_off
                    or result.status is not Status.INVALID_START
                    or not self.kin.within_limits(request.start)
                    or not self.scene.in_collision(request.start)
                ):
                    break
                backed = back_off(self)
                if not backed.clear:
                    log.info("%s: the start is in collision (%s); %s", stage, backed.pair, backed.reason)
                    raise StageFailed(
                        stage,
                        f"{name}: {result.status.value}: the start is in collision ({backed.pair}); {backed.reason}",
                        failure=failure_of_plan(result.status.value, result.reason, result.info),
                        planner=name,
                        moved=backed.travel_m > 0.0,
                    )
                log.info("%s: the start was in collision (%s); %s, planning again", stage, backed.pair, backed.reason)
                backed_off = True
            if result.status is not Status.SUCCESS:
                raise StageFailed(
                    stage,
                    f"{name}: {result.status.value}: {result.reason}",
                    failure=failure_of_plan(result.status.value, result.reason, result.info),
                    planner=name,
                    moved=backed_off or record.duration_s > 0.0,
                )
            return result
        finally:
            self.watch.after(stage, name, self.held_body)

    def move_pose(self, stage: str, T_tcp: np.ndarray, **kw: Any) -> MotionResult:
        """Move the tcp to `T_tcp` (4, 4); a stage that asks for a position only (the transfer) gets the
        orientation free and `task.transfer_tolerance_m` on the position."""
        return self.move(stage, self.pose_goal(stage, T_tcp), **kw)

    def pose_goal(self, stage: str, T_tcp: np.ndarray) -> PoseGoal:
        """The goal `move_pose` asks `stage`'s planner for: exact, or the position within a tolerance."""
        pose = Pose.from_matrix(T_tcp)
        if STAGES[stage][1] == "position":
            return PoseGoal(
                pose, position_tolerance_m=self.settings.task.transfer_tolerance_m, orientation_tolerance_rad=None
            )
        return PoseGoal(pose)

    def move_joints(self, stage: str, q: np.ndarray, **kw: Any) -> MotionResult:
        return self.move(stage, JointGoal(np.asarray(q, dtype=float)), **kw)

    # ---- choosing before moving (`twin.tasks.ways`, from the measured joints) ----------------------
    def clearance_at(self, T_tcp: np.ndarray) -> float:
        """`WayChooser.clearance_at`: the arm's distance (m) from the planning scene with its tcp at `T_tcp`."""
        return self.ways.clearance_at(T_tcp)

    def choose_top_down_yaw(
        self,
        points: Sequence[np.ndarray | tuple[float, float, float]],
        yaws: list[float],
        *,
        min_clearance_m: float = CHOOSE_CLEARANCE_M,
    ) -> tuple[float, float]:
        """(yaw, clearance m): the first of `yaws` at which the top-down gripper keeps `min_clearance_m` from
        the planning scene at every one of `points`, else the clearest (`WayChooser.choose_top_down_yaw`)."""
        return self.ways.choose_top_down_yaw(points, yaws, min_clearance_m=min_clearance_m)

    def line_paths(self, starts: Sequence[np.ndarray], T0: np.ndarray, T1: np.ndarray) -> list[np.ndarray | None]:
        """The joint paths of a straight tcp move from `T0` to `T1` from each of `starts` (`WayChooser.line_paths`)."""
        return self.ways.line_paths(starts, T0, T1)

    def choose_way_down(
        self,
        target: np.ndarray | tuple[float, float, float],
        hover: np.ndarray | tuple[float, float, float],
        yaws: Sequence[float],
        *,
        stage: str = "descent",
    ) -> WayDown:
        """The way down to a top-down tcp at `target` from the hover above it at `hover` (xyz each, base frame),
        chosen before anything moves by checking the whole robot (every link, and what it holds) in the
        planning scene along the whole motion: for each of `yaws` (in order of preference) and each IK branch
        of the hover (nearest the measured joints first), the joint path the movel stage follows down
        (`line_paths`) and the ways `reach_hover` may take there from here (the straight joint move or one
        of `move_joints_over`'s others), every `collision.check_resolution_rad`. In the arm's own
        configuration first, then in another: the first way whose way down keeps `CHOOSE_CLEARANCE_M` from
        the scene and which has a clear way there; else the same merely clear; only then a way down with no
        clear way there. The way down chosen is planned by the stage's own planner (without moving) before
        it is returned; a refused one passes to the next.

        The gripper alone may be clear where the arm is not: a cube far behind a wall is reached with the
        upper arm low over it, in some branches into it (`Cell.choose_top_down_yaw` checks the gripper).
        None clear: StageFailed (planned, not moved) naming what runs into what."""
        return self.ways.choose_way_down(
            self.world.joint_positions(),
            target,
            hover,
            yaws,
            planner=self.stage_planner(stage),
            planner_name=self.block(STAGE_GROUPS[stage]).name,
            limits=self.limits,
            seed=self.world.seed,
            stage=stage,
        )

    def safe_height(self) -> float:
        """A tcp height from which the gripper, and what it holds, passes over everything in the planning
        scene (`WayChooser.safe_height`)."""
        return self.ways.safe_height()

    def nearest_turn(self, q: np.ndarray) -> np.ndarray:
        """`q` (6,) with each joint turned by whole turns (within its limits) to the angle nearest the
        measured one: the same posture, reached without a needless full turn (`WayChooser.nearest_turn`)."""
        return self.ways.nearest_turn(q, self.world.joint_positions())

    # ---- the ways round a refused motion (`twin.tasks.detours`) ------------------------------------
    def reach_hover(self, way: WayDown, *, stage: str = "hover") -> MotionResult:
        """Move to `way`'s hover in the IK branch it was chosen in (a joint goal: its way down was checked
        in that branch, not in the one a pose goal may land in), by `move_joints_over`; when that finds no
        clear way there (planned, not moved), over the top in the same branch: straight up to
        `safe_height`, across to the arm above the hover (the IK solution nearest `q_hover`), straight down."""
        return detours.reach_hover(self, way, stage)

    def move_pose_over(self, stage: str, T_tcp: np.ndarray) -> MotionResult:
        """`move_pose`, and when the stage's planner refuses the direct way because it runs into something
        (planned, not moved): to the arm configuration at `T_tcp` (an IK branch, at the turn of each joint
        nearest where it is) whose straight joint motion from here is clear, nearest first, 1 cm clear
        before merely clear (`WayChooser.first_clear`); else over the top: straight up to
        `safe_height`, across at that height with the stage's planner, and straight down to `T_tcp`;
        refused again (the arm's own links in the way: another planner's motion left it in an awkward
        configuration), by way of home."""
        return detours.move_pose_over(self, stage, T_tcp)

    def move_pose_turned(self, stage: str, T_tcp: np.ndarray) -> MotionResult:
        """`move_pose` (a short straight move, e.g. lowering into a bin), and when the stage's planner refuses
        it because the arm runs into something on the way (planned, not moved; e.g. the upper arm into a
        bin wall, in the IK branch another planner's motion left it in): the arm turned first, where it is,
        to another configuration of the same tcp pose (an IK branch at the joints' nearest turns) from which
        the stage's planner plans the move, and then the move. The turn (1 cm clear before merely clear,
        `WayChooser.first_clear`) and the move from there are planned before anything moves; none clear: the
        refusal stands."""
        return detours.move_pose_turned(self, stage, T_tcp)

    def move_joints_over(self, stage: str, q: np.ndarray) -> MotionResult:
        """`move_joints`, and when the stage's planner refuses the direct way because it runs into
        something (planned, not moved), by the first of a few other ways whose straight joint legs are
        clear in the planning scene (checked before anything moves): the wrist joints first, the arm
        joints first, straight up to `safe_height` first, up and then the wrist, or through the upright
        posture (`twin.tasks.ways.other_ways`). A way that is not clear is never started; none clear: the
        refusal stands.

        `q` is a posture: each joint goes to the turn of its angle (q + 2 pi k, within the joint's limits)
        nearest where it is, the same posture without a needless full turn of a wrist (which swings the
        gripper through the arm) after a planner left a joint a turn away."""
        return detours.move_joints_over(self, stage, q)

    def reach_posture(self, stage: str, q: np.ndarray) -> MotionResult:
        """`move_joints_over` (home, the capture pose), and when a contact stops it on the way (an object
        still stuck to a finger after a release touches something): let go, rise, free what is stuck
        (`recover`: the stop that led there names the finger) and try once more."""
        return detours.reach_posture(self, stage, q)

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
        """Close force-limited, settle, and judge the grasp by the finger position alone
        (`twin.tasks.grasping.grasp_check`, against the width range (min, max) m the task expects between the
        fingers, from the perceived class and orientation). `force_n`, `speed_m_s`: a gentler grip than the
        gripper's defaults."""
        self.world.close_gripper(force_n=force_n, speed_m_s=speed_m_s)
        self.settle(self.settings.task.settle_s)
        r = self.read_gripper(speed_m_s=speed_m_s)
        self.scene.set_gripper_opening(
            float(np.clip(r.opening_m, 0.0, self.scene.max_opening_m))
        )  # closed pads read a hair below 0
        # the one ground-truth read here, kept in the judge: it feeds the simulated contact monitor only
        self.held_body = body_between_fingers(self.world)
        check = grasp_check(r, expect_width_m, self.settings.gripper)
        self.grasp = check if check.status is GripStatus.HOLDING else None
        log.debug(
            "grasp: %s at %.1f mm (effort %.0f N, settled %s)",
            check.status.value,
            1000.0 * r.opening_m,
            r.effort_n,
            r.settled,
        )
        return check

    def check_holding(self) -> GraspCheck:
        """Is the grasped object still between the fingers? Judged from the finger position after a short
        poll (fingers whose object just left need a moment to start closing): `twin.tasks.grasping.holding_check`."""
        self.settle(GRIPPER_POLL_S)
        return holding_check(self.read_gripper(), self.grasp, self.settings.gripper)

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
        (a retreat: off whatever the gripper was stopped against). Then make sure nothing stayed between
        the opened fingers (`twin.tasks.jam`): fingers that did not open fully, the wrist camera seeing
        something there, or (without a wrist camera) the stop that led here naming a finger on a loose
        object while the gripper should have been empty. What is stuck is set down on what lies below and
        let go again, a bounded number of tries; the run goes on either way."""
        last = self.records[-1] if self.records else None
        empty = self.grasp is None and self.scene.attached is None  # nothing should have been in the fingers
        stop = last.reason if last is not None and last.status == Status.EXECUTION_STOPPED.value and empty else None
        held = self.scene.attached_box()
        hang = None if held is None else float(held[2][2, 3] + np.abs(held[2][2, :3]) @ (held[1] / 2.0))
        self.release()
        T = self.kin.fk(self.world.joint_positions())
        T[2, 3] = max(T[2, 3], 0.30)
        risen = True
        try:
            self.move_pose("ascent", T, retreat=True)
        except StageFailed:
            log.info("recovery: could not rise from %s", np.round(T[:3, 3], 3).tolist())
            risen = False  # still low: what the wrist camera sees below may be what it let go
        reading = jam.sense_jam(self, stop_reason=stop, camera=risen)
        if reading.jammed:
            jam.free_jam(self, self.kin.fk(self.world.joint_positions()), hang_m=hang, reading=reading)

    # ---- bookkeeping ----------------------------------------------------------------------------

    # ---- bookkeeping ----------------------------------------------------------------------------
    def metrics(self) -> dict[str, Any]:
        """Planner metrics over the run (`planner_metrics` of the motions done so far)."""
        return planner_metrics(self.records)
