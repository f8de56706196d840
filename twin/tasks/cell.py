"""The cell a task drives: world, kinematics, FCL scene, stage planners, and the motions done so far.

Tasks speak in stages ("hover", "descent", "transfer", ...). Each stage maps to a planner block of the
config (`planners.<group>`), so swapping a planner is a config change; `--planner` replaces `transfer`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from twin.camera import RGBDFrame
from twin.collision import PlanningScene
from twin.config import PlannerBlock, Settings
from twin.errors import ConfigError, PluginCrashed
from twin.executor import MotionRecord, plan_and_execute
from twin.failures import failure_of_plan
from twin.kinematics import URArm
from twin.limit_check import RATIO_METRICS
from twin.planning import (
    CheckedPlanner,
    colliding_pair,
    describe_goal_kinds,
    limits_from_settings,
    make_context,
    make_planner,
)
from twin.tasks import jam
from twin.tasks.gripper import GRIPPER_POLL_S, GraspCheck, GripperReading, GripStatus, top_down
from twin.tasks.judge import DisplacementWatch, body_between_fingers
from twin.tasks.recovery import back_off
from twin.tasks.stage_failure import PATH_COLLIDES, StageFailed, clear_failure, note_failure, or_refusal
from twin.types import CalibrationOutcome, JointGoal, MotionRequest, MotionResult, Pose, PoseGoal, Status
from twin.urdf_model import primitive_half_extents

# StageFailed, the gripper's types and top_down are re-exported: the cell's face to tasks and plugins
__all__ = [
    "STAGES",
    "STAGE_GROUPS",
    "Cell",
    "GraspCheck",
    "GripStatus",
    "GripperReading",
    "StageFailed",
    "WayDown",
    "clear_failure",
    "note_failure",
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
# a fixed stage's choice (a grasp yaw) is clear when the gripper keeps this far from the planning scene:
# the stage planners' own margin is below it, so a clear choice is not refused for a hair
CHOOSE_CLEARANCE_M = 0.01
# over the top: the tcp's path across passes this far above the highest thing in the planning scene
OVER_MARGIN_M = 0.05
_TURN_MARGIN_RAD = 0.05  # a posture's joints are turned only to angles this far inside their limits
# a straight way down is followed through IK waypoints this far apart (a movel planner's own first spacing);
# a joint turning more than `_LINE_MAX_STEP_RAD` between two of them is a branch change or a singularity
_LINE_STEP_M = 0.02
_LINE_MAX_STEP_RAD = 0.3


def _arm_configuration(kin: URArm, q: np.ndarray) -> tuple[bool, bool]:
    """Which of the arm's IK configurations q (6,) is, as (the tcp in front of the shoulder: along the way the pan
    points the arm, not thrown over behind it; the elbow joint bent positive). Wrist flips do not count."""
    pan = float(q[0])
    reach = np.array([-math.cos(pan), -math.sin(pan)])  # with the pan at 0 the arm reaches towards -x
    return bool(float(reach @ kin.fk(q)[:2, 3]) > 0.0), bool(q[2] > 0.0)


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


@dataclass(frozen=True)
class Sighting:
    """One capture and what a task made of it: the frame, the camera pose it used (base frame), each object it saw
    as (label, position (3,)) and each obstacle box as (name, lo, hi)."""

    frame: RGBDFrame
    T_base_camera: np.ndarray
    objects: Sequence[tuple[str, np.ndarray]]
    boxes: Sequence[tuple[str, np.ndarray, np.ndarray]] = ()


@dataclass(frozen=True, eq=False)
class WayDown:
    """A straight way down to a top-down tcp pose, chosen before anything moves (`Cell.choose_way_down`):
    the yaw; the tcp at the hover and at the bottom, (4, 4) each; the arm at the hover `q_hover` (6,) in the
    IK branch whose way down is clear for the whole arm; the joint path of that way down `path` (k, 6),
    hover first, as the movel stage follows it; and whether it keeps `CHOOSE_CLEARANCE_M` from the
    planning scene all along (`roomy`) or is merely clear."""

    yaw: float
    hover: np.ndarray
    target: np.ndarray
    q_hover: np.ndarray
    path: np.ndarray
    roomy: bool


class RunTrace(Protocol):
    """What a run's recording (`twin.rerun_log.RerunRecording`) is told by the cell: every stage it planned, and
    what every capture saw (`Cell.perceived`)."""

    def motion(
        self, sim_time_s: float, stage: str, planner: str, request: MotionRequest, result: MotionResult
    ) -> None: ...

    def perceived(self, sim_time_s: float, sighting: Sighting) -> None: ...


@dataclass
class Cell:
    """Everything a task needs to move the robot; built once per run."""

    settings: Settings
    world: Any  # twin.world.World
    planner_override: str | None = None
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
        self.watch = DisplacementWatch(self.world)  # judging only: the referees read it, no task does

    def objects_done(self, done: int, total: int) -> None:
        """Tell the progress display (`on_objects`, `twin run`'s) how many of the `total` objects the task knows
        of it is done with (placed or given up on); a task that never says shows its stages only."""
        if self.on_objects is not None:
            self.on_objects(done, total)

    # ---- planners -------------------------------------------------------------------------------
    def block(self, group: str) -> PlannerBlock:
        return stage_block(self.settings, group, self.planner_override)

    def planner(self, group: str) -> CheckedPlanner:
        return self.planners[group]

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
                        self.context,
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
        return self.move(stage, self._pose_goal(stage, T_tcp), **kw)

    def _pose_goal(self, stage: str, T_tcp: np.ndarray) -> PoseGoal:
        pose = Pose.from_matrix(T_tcp)
        if STAGES[stage][1] == "position":
            return PoseGoal(
                pose, position_tolerance_m=self.settings.task.transfer_tolerance_m, orientation_tolerance_rad=None
            )
        return PoseGoal(pose)

    def move_joints(self, stage: str, q: np.ndarray, **kw: Any) -> MotionResult:
        return self.move(stage, JointGoal(np.asarray(q, dtype=float)), **kw)

    # ---- choosing before moving -----------------------------------------------------------------
    # A stage the compared planner does not plan must not fail where an equivalent choice would not: each
    # picks, in the planning scene, a grasp yaw that is clear, and goes over the top of the scene when its
    # planner refuses the direct way. Only planning is tried; nothing moves until a choice is made.
    def clearance_at(self, T_tcp: np.ndarray) -> float:
        """Signed distance (m) from the planning scene of the arm with its tcp at `T_tcp` (4, 4), in the
        clearest of its IK branches (which one a planner takes there is its choice; the gripper, and what
        it holds, stand the same in every one); -inf when out of reach."""
        sols = self.kin.ik(T_tcp, all_wraps=False)
        if len(sols) == 0:
            return -math.inf
        return max(float(self.scene.min_distance(q, include_self=False).distance) for q in sols)

    def choose_top_down_yaw(
        self,
        points: Sequence[np.ndarray | tuple[float, float, float]],
        yaws: list[float],
        *,
        min_clearance_m: float = CHOOSE_CLEARANCE_M,
    ) -> tuple[float, float]:
        """(yaw, clearance m): the first of `yaws` (in order of preference) at which the tcp pointing down
        stays `min_clearance_m` clear of the planning scene at every one of `points` (e.g. a grasp, the
        hover above it and the way between), else the one with the most clearance."""
        if not yaws:
            raise ValueError("choose_top_down_yaw needs at least one yaw")
        best, best_c = yaws[0], -math.inf
        for yaw in yaws:
            c = min(self.clearance_at(top_down(p, yaw)) for p in points)
            if c >= min_clearance_m:
                return yaw, c
            if c > best_c + 1e-4:
                best, best_c = yaw, c
        log.info(
            "no yaw keeps the gripper %.0f mm clear of the planning scene; the clearest, %.0f deg, keeps %.1f mm",
            1e3 * min_clearance_m,
            math.degrees(best),
            1e3 * best_c,
        )
        return best, best_c

    def line_paths(self, starts: Sequence[np.ndarray], T0: np.ndarray, T1: np.ndarray) -> list[np.ndarray | None]:
        """The joint path (k, 6) that a straight tcp move from `T0` to `T1` (4, 4, the same orientation: a way
        straight down or up) follows from each of `starts` (the arm at `T0`, (6,) each): IK waypoints
        `_LINE_STEP_M` apart, each the solution nearest the one before (at its nearest turn), as the movel
        stages' planners keep the start's IK branch. None for a start from which the line leaves reach or
        the joint limits, or a joint jumps (a branch change, a singularity): ways those planners refuse.
        One IK per waypoint serves every start."""
        T0, T1 = np.asarray(T0, dtype=float), np.asarray(T1, dtype=float)
        if np.abs(T0[:3, :3] - T1[:3, :3]).max() > 1e-6:
            raise ValueError("line_paths follows a straight move of one orientation; T0 and T1 turn")
        n = max(1, math.ceil(float(np.linalg.norm(T1[:3, 3] - T0[:3, 3])) / _LINE_STEP_M))
        lo, hi = self.kin.joint_limits[:, 0], self.kin.joint_limits[:, 1]
        paths: list[list[np.ndarray] | None] = [[np.asarray(q, dtype=float)] for q in starts]
        for i in range(1, n + 1):
            T = T0.copy()
            T[:3, 3] = T0[:3, 3] + (i / n) * (T1[:3, 3] - T0[:3, 3])
            sols = self.kin.ik(T, all_wraps=False)
            for k, path in enumerate(paths):
                if path is None:
                    continue
                if len(sols) == 0:
                    paths[k] = None
                    continue
                prev = path[-1]
                near = sols + 2.0 * math.pi * np.round((prev - sols) / (2.0 * math.pi))
                step = np.abs(near - prev).max(axis=1)
                j = int(np.argmin(step))
                q = near[j]
                if step[j] > _LINE_MAX_STEP_RAD or np.any(q < lo) or np.any(q > hi):
                    paths[k] = None
                else:
                    path.append(q)
        return [None if p is None else np.array(p) for p in paths]

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
        q0 = self.world.joint_positions()
        res = float(self.settings.collision.check_resolution_rad)
        planner = self.planner(STAGE_GROUPS[stage])
        tried: dict[float, list[tuple[np.ndarray, np.ndarray]]] = {}

        def ways(yaw: float) -> list[tuple[np.ndarray, np.ndarray]]:
            """(q at the hover, path down) of every branch whose way down is within reach, nearest first."""
            if yaw not in tried:
                Th, Tt = top_down(hover, yaw), top_down(target, yaw)
                sols = [q for q in self._branches(Th) if self.kin.within_limits(q)]
                paths = self.line_paths(sols, Th, Tt)
                tried[yaw] = [(q, p) for q, p in zip(sols, paths, strict=True) if p is not None]
            return tried[yaw]

        refused: dict[int, str] = {}  # the planner's refusals, by id of the way's q_hover: not planned twice
        padded = self.scene.padded(CHOOSE_CLEARANCE_M)
        raised = self._raised(q0)

        def reachable(q_hover: np.ndarray, scene: PlanningScene) -> bool:
            """Whether `reach_hover` has a way from here to `q_hover` that is free in `scene`: the straight
            joint move, or one of `move_joints_over`'s other ways."""
            q = self.nearest_turn(q_hover)
            legs = [[q0, q]] + [[q0, *via, q] for _, via, _ in self._other_ways(q0, q, raised)]
            return any(scene.check_path(np.array(way), resolution_rad=res).free for way in legs)

        def first(same_arm: bool, scene: PlanningScene, there: bool) -> WayDown | None:
            """The first way (yaw in order, branch nearest first) among the branches in the arm's present
            configuration (`same_arm`: `_arm_configuration`) or among the others, whose way down (and, `there`,
            whose move there) is free in `scene`, and which the stage's planner plans."""
            for yaw in yaws:
                for q_hover, path in ways(yaw):
                    if (_arm_configuration(self.kin, q_hover) == arm0) is not same_arm or id(q_hover) in refused:
                        continue
                    if there and not reachable(q_hover, scene):
                        continue
                    if not scene.check_path(path, resolution_rad=res).free:
                        continue
                    way = WayDown(
                        float(yaw), top_down(hover, yaw), top_down(target, yaw), q_hover, path, scene is padded
                    )
                    goal = PoseGoal(Pose.from_matrix(way.target))
                    plan = planner.plan(MotionRequest(q_hover, goal, self.limits, seed=self.world.seed), self.scene)
                    if plan.status is Status.SUCCESS:
                        return way
                    refused[id(q_hover)] = f"{plan.status.value}: {plan.reason}"
            return None

        arm0 = _arm_configuration(self.kin, q0)
        # the arm as it is before the arm thrown over: a flipped shoulder or elbow 1 cm clear of a neighbour at the
        # hover leaves the transfers after it a folded wrist to carry into the bins (its gripper into its forearm)
        # a way down with no clear way there is the last resort, in either configuration: reach_hover would
        # refuse it, after the task has committed to it
        order = [(same, scene, True) for same in (True, False) for scene in (padded, self.scene)]
        order += [(same, scene, False) for same in (True, False) for scene in (padded, self.scene)]
        for same_arm, scene, there in order:
            found = first(same_arm, scene, there)
            if found is not None:
                return found
        raise self._no_way_down(stage, target, yaws, tried, list(refused.values()))

    def _no_way_down(
        self,
        stage: str,
        target: np.ndarray | tuple[float, float, float],
        yaws: Sequence[float],
        tried: dict[float, list[tuple[np.ndarray, np.ndarray]]],
        refused: list[str],
    ) -> StageFailed:
        """Why `choose_way_down` found no way: what runs into what, counted over the ways it tried."""
        pairs: dict[str, int] = {}
        for ways in tried.values():
            for _, path in ways:
                hit = self.scene.check_path(path, resolution_rad=float(self.settings.collision.check_resolution_rad))
                if hit.q is not None:
                    pair = colliding_pair(self.scene, hit.q)
                    pairs[pair] = pairs.get(pair, 0) + 1
        n = sum(len(w) for w in tried.values())
        what = ", ".join(f"{p} in {k}" for p, k in sorted(pairs.items(), key=lambda kv: -kv[1]))
        if refused:
            what = ", ".join(filter(None, [what, f"{len(refused)} refused by the planner ({refused[0]})"]))
        xyz = ", ".join(f"{float(v):.3f}" for v in target)
        if n == 0:  # no branch of any yaw follows the line: out of reach, past a joint limit or a singularity
            reason = f"no way down to ({xyz}) is within reach: in no IK branch of {len(yaws)} yaws"
            failure = "ik_failure"
        else:
            reason = (
                f"no way down to ({xyz}) is clear for the whole arm: {n} ways tried ({len(yaws)} yaws x their "
                f"IK branches within reach)" + (f"; {what}" if what else "")
            )
            failure = "collision"
        log.info("%s: %s", stage, reason)
        return StageFailed(stage, reason, failure=failure, planner=self.block(STAGE_GROUPS[stage]).name, moved=False)

    def reach_hover(self, way: WayDown, *, stage: str = "hover") -> MotionResult:
        """Move to `way`'s hover in the IK branch it was chosen in (a joint goal: its way down was checked
        in that branch, not in the one a pose goal may land in), by `move_joints_over`; when that finds no
        clear way there (planned, not moved), over the top in the same branch: straight up to
        `safe_height`, across to the arm above the hover (the IK solution nearest `q_hover`), straight down."""
        done = or_refusal(lambda: self.move_joints_over(stage, way.q_hover))
        if isinstance(done, MotionResult):
            return done
        above = np.array(way.hover, dtype=float)
        above[2, 3] = max(above[2, 3], self.safe_height())
        sols = [self.nearest_turn(q) for q in self.kin.ik(above, all_wraps=False)]
        if above[2, 3] <= way.hover[2, 3] or not sols:
            raise done
        q_above = min(sols, key=lambda q: float(np.abs(q - way.q_hover).max()))
        log.info("%s: no clear way to the chosen hover (%s); over the top", stage, done.reason)
        self._rise_to_safe_height()
        self.move_joints_over(stage, q_above)
        return self.move_pose("descent", way.hover)

    def safe_height(self) -> float:
        """A tcp height from which the gripper, and what it holds, passes over everything in the planning
        scene: the top of its highest object, plus what hangs below the tcp, plus `OVER_MARGIN_M`."""
        top = 0.0
        for shapes in self.scene.environment_shapes().values():
            for kind, size, T in shapes:
                top = max(top, float(T[2, 3] + np.abs(T[2, :3]) @ primitive_half_extents(kind, size)))
        hang = 0.0
        held = self.scene.attached_box()
        if held is not None:
            _, held_size, T_held = held
            hang = float(T_held[2, 3] + np.abs(T_held[2, :3]) @ (held_size / 2.0))  # the tcp's z points down
        return top + max(hang, 0.0) + OVER_MARGIN_M

    def move_pose_over(self, stage: str, T_tcp: np.ndarray) -> MotionResult:
        """`move_pose`, and when the stage's planner refuses the direct way because it runs into something
        (planned, not moved): to the arm configuration at `T_tcp` (an IK branch, at the turn of each joint
        nearest where it is) whose straight joint motion from here is clear, nearest first, 1 cm clear
        before merely clear (`_first_clear`); else over the top: straight up to
        `safe_height`, across at that height with the stage's planner, and straight down to `T_tcp`;
        refused again (the arm's own links in the way: another planner's motion left it in an awkward
        configuration), by way of home."""
        done = or_refusal(lambda: self.move_pose(stage, T_tcp))
        if isinstance(done, MotionResult):
            return done
        why = done.reason
        q0 = self.world.joint_positions()
        sols = self._branches(T_tcp)
        i = self._first_clear([[q0, q] for q in sols])
        if i is not None:
            log.info("%s: the direct way runs into something (%s); going to a clear configuration", stage, why)
            done = or_refusal(lambda: self.move_joints(stage, sols[i]))
            if isinstance(done, MotionResult):
                return done
            why = done.reason
        log.info("%s: the direct way runs into something (%s); going over the top", stage, why)
        above = np.array(T_tcp, dtype=float)
        above[2, 3] = max(above[2, 3], self.safe_height())
        try:
            self._rise_to_safe_height()
            result = self.move_pose(stage, above)
        except StageFailed as e:
            if e.moved or e.failure not in PATH_COLLIDES:
                raise
            log.info("%s: over the top runs into something too (%s); by way of home", stage, e.reason)
            self.move_joints_over("home", np.asarray(self.settings.robot.home, dtype=float))
            result = self.move_pose(stage, above)
        if above[2, 3] > T_tcp[2, 3]:
            result = self.move_pose("descent", T_tcp)
        return result

    def move_pose_turned(self, stage: str, T_tcp: np.ndarray) -> MotionResult:
        """`move_pose` (a short straight move, e.g. lowering into a bin), and when the stage's planner refuses
        it because the arm runs into something on the way (planned, not moved; e.g. the upper arm into a
        bin wall, in the IK branch another planner's motion left it in): the arm turned first, where it is,
        to another configuration of the same tcp pose (an IK branch at the joints' nearest turns) from which
        the stage's planner plans the move, and then the move. The turn (1 cm clear before merely clear,
        `_first_clear`) and the move from there are planned before anything moves; none clear: the refusal
        stands."""
        refused = or_refusal(lambda: self.move_pose(stage, T_tcp))
        if isinstance(refused, MotionResult):
            return refused
        q0 = self.world.joint_positions()
        turns = [q for q in self._branches(self.kin.fk(q0)) if float(np.abs(q - q0).max()) > 1e-3]
        planner, goal = self.planner(STAGE_GROUPS[stage]), self._pose_goal(stage, T_tcp)
        turns = [
            q
            for q in turns
            if planner.plan(MotionRequest(q, goal, self.limits, seed=self.world.seed), self.scene).status
            is Status.SUCCESS
        ]
        i = self._first_clear([[q0, q] for q in turns])
        if i is None:
            raise refused
        log.info("%s: the way runs into something (%s); turning the arm where it is first", stage, refused.reason)
        self.move_joints("align", turns[i])
        return self.move_pose(stage, T_tcp)

    def _branches(self, T_tcp: np.ndarray) -> list[np.ndarray]:
        """The arm configurations (6,) at `T_tcp` (4, 4): each IK branch once, at the turn of each joint
        nearest where it is (a way that swings a wrist a full turn to keep clear leaves the arm a turn from
        where the next planner expects it), nearest first."""
        q0 = self.world.joint_positions()
        return sorted(
            (self.nearest_turn(q) for q in self.kin.ik(T_tcp, all_wraps=False)),
            key=lambda q: float(np.abs(q - q0).max()),
        )

    def move_joints_over(self, stage: str, q: np.ndarray) -> MotionResult:
        """`move_joints`, and when the stage's planner refuses the direct way because it runs into
        something (planned, not moved), by the first of a few other ways whose straight joint legs are
        clear in the planning scene (checked before anything moves): the wrist joints first, the arm
        joints first, straight up to `safe_height` first, up and then the wrist, or through the upright
        posture. A way that is not clear is never started; none clear: the refusal stands.

        `q` is a posture: each joint goes to the turn of its angle (q + 2 pi k, within the joint's limits)
        nearest where it is, the same posture without a needless full turn of a wrist (which swings the
        gripper through the arm) after a planner left a joint a turn away."""
        q = self.nearest_turn(np.asarray(q, dtype=float))
        refused = or_refusal(lambda: self.move_joints(stage, q))
        if isinstance(refused, MotionResult):
            return refused
        q0 = self.world.joint_positions()
        ways = self._other_ways(q0, q, self._raised(q0))
        i = self._first_clear([[q0, *via, q] for _, via, _ in ways])
        if i is not None:
            name, via, rises = ways[i]
            log.info("%s: the direct way runs into something (%s); going %s", stage, refused.reason, name)
            if rises:
                self._rise_to_safe_height()
            for qv in via[1:] if rises else via:
                self.move_joints(stage, qv)
            return self.move_joints(stage, q)
        log.info(
            "%s: the direct way runs into something and no other way is clear from %s",
            stage,
            np.round(q0, 3).tolist(),
        )
        raise refused

    def _other_ways(
        self, q0: np.ndarray, q: np.ndarray, raised: np.ndarray | None
    ) -> list[tuple[str, list[np.ndarray], bool]]:
        """The ways `move_joints_over` tries from `q0` to `q` when the straight joint move is refused, in
        order: (name, the joints it passes through, whether its first leg is the rise straight up to
        `raised`, `_raised(q0)`)."""
        ways: list[tuple[str, list[np.ndarray], bool]] = [
            ("wrist first", [np.concatenate([q0[:3], q[3:]])], False),
            ("arm first", [np.concatenate([q[:3], q0[3:]])], False),
        ]
        if raised is not None:
            ways += [
                ("up first", [raised], True),
                ("up, then the wrist", [raised, np.concatenate([raised[:3], q[3:]])], True),
            ]
        # the arm straight up (the "candle" posture): from it the elbow and wrist unfold either way, which a
        # straight joint motion between two elbow branches cannot do without folding through itself
        upright = np.array([q0[0], -math.pi / 2, 0.0, -math.pi / 2, 0.0, q0[5]])
        ways.append(("through the upright posture", [upright], False))
        return ways

    def reach_posture(self, stage: str, q: np.ndarray) -> MotionResult:
        """`move_joints_over` (home, the capture pose), and when a contact stops it on the way (an object
        still stuck to a finger after a release touches something): let go, rise, free what is stuck
        (`recover`: the stop that led there names the finger) and try once more."""
        try:
            return self.move_joints_over(stage, q)
        except StageFailed as e:
            if e.failure != "execution_contact":
                raise
            log.info("%s: stopped on the way (%s); recovering and trying again", stage, e.reason)
        self.recover()
        return self.move_joints_over(stage, q)

    def _first_clear(self, ways: Sequence[Sequence[np.ndarray]]) -> int | None:
        """The index of the first of `ways` (each the joints its straight legs pass through, in order of
        preference) that keeps `CHOOSE_CLEARANCE_M` from the planning scene all along (checked every 0.01
        rad, as the stage planners check), else of the first that is clear at all, else None. A way that
        only grazes the modelled scene meets the real one: perception's box is a few mm off and the arm,
        tracking a fast motion, a few mm off its plan (measured: a way 0.1 mm clear in planning, 1.9 mm of
        the real obstacle, stopped by the upper arm touching it)."""
        padded = self.scene.padded(CHOOSE_CLEARANCE_M)
        for scene in (padded, self.scene):
            for i, way in enumerate(ways):
                if scene.check_path(np.array(way)).free:
                    return i
        return None

    def nearest_turn(self, q: np.ndarray) -> np.ndarray:
        """`q` (6,) with each joint turned by whole turns (within its limits, `_TURN_MARGIN_RAD` inside them:
        a joint that arrives a hair past a limit is a start every planner refuses) to the angle nearest the
        measured one: the same posture, reached without a needless full turn."""
        q0 = self.world.joint_positions()
        lo, hi = self.kin.joint_limits[:, 0], self.kin.joint_limits[:, 1]
        out = np.array(q, dtype=float)
        for j in range(len(out)):
            turns = out[j] + 2.0 * math.pi * np.arange(-2, 3)
            turns = turns[(turns >= lo[j] + _TURN_MARGIN_RAD) & (turns <= hi[j] - _TURN_MARGIN_RAD)]
            if len(turns):
                out[j] = float(turns[np.argmin(np.abs(turns - q0[j]))])
        return out

    def _raised(self, q: np.ndarray) -> np.ndarray | None:
        """The joints (6,) with the tcp straight above where it is at `q`, at `safe_height` (the IK solution
        nearest `q`); None when it is there already or that is out of reach."""
        T = self.kin.fk(q)
        z = self.safe_height()
        if T[2, 3] >= z:
            return None
        T[2, 3] = z
        sols = self.kin.ik(T)
        if len(sols) == 0:
            return None
        return np.asarray(sols[int(np.argmin(np.abs(sols - q).sum(axis=1)))], dtype=float)

    def _rise_to_safe_height(self) -> float:
        """Move the tcp straight up to `safe_height` (no move when it is there already); that height."""
        z = self.safe_height()
        T = self.kin.fk(self.world.joint_positions())
        if T[2, 3] < z:
            T[2, 3] = z
            self.move_pose("ascent", T)
        return z

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
        g = self.settings.gripper
        self.world.close_gripper(force_n=force_n, speed_m_s=speed_m_s)
        self.settle(self.settings.task.settle_s)
        r = self.read_gripper(speed_m_s=speed_m_s)
        self.scene.set_gripper_opening(
            float(np.clip(r.opening_m, 0.0, self.scene.max_opening_m))
        )  # closed pads read a hair below 0
        # the one ground-truth read here, kept in the judge: it feeds the simulated contact monitor only
        self.held_body = body_between_fingers(self.world)
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
        self.settle(GRIPPER_POLL_S)  # fingers whose object just left need a moment to start closing
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
