"""Choosing before moving: which way a fixed stage takes, decided in the planning scene before anything moves.

A stage the compared planner does not plan must not fail where an equivalent choice would not: each picks, in
the planning scene, a grasp yaw that is clear, a way down that is clear for the whole arm, and the ways round
a direct motion its planner refuses. Only planning and collision checks happen here; the cell moves
(`twin.tasks.detours` follows the choices). The measured joints are handed in, so a choice reads nothing the
cell has not sensed.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twin.collision import PlanningScene
from twin.planning import CheckedPlanner, colliding_pair
from twin.robot.kinematics import URArm
from twin.robot.urdf_model import primitive_half_extents
from twin.tasks.grasping import top_down
from twin.tasks.stage_failure import StageFailed
from twin.types import Limits, MotionRequest, Pose, PoseGoal, Status

__all__ = [
    "CHOOSE_CLEARANCE_M",
    "OVER_MARGIN_M",
    "WayChooser",
    "WayDown",
    "arm_configuration",
    "other_ways",
]

log = logging.getLogger("twin")

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


def arm_configuration(kin: URArm, q: np.ndarray) -> tuple[bool, bool]:
    """Which of the arm's IK configurations q (6,) is, as (the tcp in front of the shoulder: along the way the pan
    points the arm, not thrown over behind it; the elbow joint bent positive). Wrist flips do not count."""
    pan = float(q[0])
    reach = np.array([-math.cos(pan), -math.sin(pan)])  # with the pan at 0 the arm reaches towards -x
    return bool(float(reach @ kin.fk(q)[:2, 3]) > 0.0), bool(q[2] > 0.0)


def other_ways(q0: np.ndarray, q: np.ndarray, raised: np.ndarray | None) -> list[tuple[str, list[np.ndarray], bool]]:
    """The ways `move_joints_over` tries from `q0` to `q` when the straight joint move is refused, in
    order: (name, the joints it passes through, whether its first leg is the rise straight up to
    `raised`, `WayChooser.raised(q0)`)."""
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


@dataclass(frozen=True, eq=False)
class WayChooser:
    """The cell's choices of a way, made in its planning scene with its kinematics (the cell's own objects,
    shared, not copies): clear grasp yaws, ways down, postures at their nearest turn, ways round a refused
    motion. `check_resolution_rad`: the joint step at which a way is checked (`collision.check_resolution_rad`)."""

    kin: URArm
    scene: PlanningScene
    check_resolution_rad: float

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
        q0: np.ndarray,
        target: np.ndarray | tuple[float, float, float],
        hover: np.ndarray | tuple[float, float, float],
        yaws: Sequence[float],
        *,
        planner: CheckedPlanner,
        planner_name: str,
        limits: Limits,
        seed: int,
        stage: str = "descent",
    ) -> WayDown:
        """The way down to a top-down tcp at `target` from the hover above it at `hover` (xyz each, base frame),
        from the arm at `q0` (6,), measured: `Cell.choose_way_down` says how it is chosen. Each way down found
        clear is planned by the stage's `planner` (named `planner_name`, with `limits` and `seed`) before it
        is returned; a refused one passes to the next. None clear: StageFailed (planned, not moved)."""
        res = float(self.check_resolution_rad)
        tried: dict[float, list[tuple[np.ndarray, np.ndarray]]] = {}

        def ways(yaw: float) -> list[tuple[np.ndarray, np.ndarray]]:
            """(q at the hover, path down) of every branch whose way down is within reach, nearest first."""
            if yaw not in tried:
                Th, Tt = top_down(hover, yaw), top_down(target, yaw)
                sols = [q for q in self.branches(Th, q0) if self.kin.within_limits(q)]
                paths = self.line_paths(sols, Th, Tt)
                tried[yaw] = [(q, p) for q, p in zip(sols, paths, strict=True) if p is not None]
            return tried[yaw]

        refused: dict[int, str] = {}  # the planner's refusals, by id of the way's q_hover: not planned twice
        padded = self.scene.padded(CHOOSE_CLEARANCE_M)
        raised = self.raised(q0)

        def reachable(q_hover: np.ndarray, scene: PlanningScene) -> bool:
            """Whether `reach_hover` has a way from here to `q_hover` that is free in `scene`: the straight
            joint move, or one of `move_joints_over`'s other ways."""
            q = self.nearest_turn(q_hover, q0)
            legs = [[q0, q]] + [[q0, *via, q] for _, via, _ in other_ways(q0, q, raised)]
            return any(scene.check_path(np.array(way), resolution_rad=res).free for way in legs)

        def first(same_arm: bool, scene: PlanningScene, there: bool) -> WayDown | None:
            """The first way (yaw in order, branch nearest first) among the branches in the arm's present
            configuration (`same_arm`: `arm_configuration`) or among the others, whose way down (and, `there`,
            whose move there) is free in `scene`, and which the stage's planner plans."""
            for yaw in yaws:
                for q_hover, path in ways(yaw):
                    if (arm_configuration(self.kin, q_hover) == arm0) is not same_arm or id(q_hover) in refused:
                        continue
                    if there and not reachable(q_hover, scene):
                        continue
                    if not scene.check_path(path, resolution_rad=res).free:
                        continue
                    way = WayDown(
                        float(yaw), top_down(hover, yaw), top_down(target, yaw), q_hover, path, scene is padded
                    )
                    goal = PoseGoal(Pose.from_matrix(way.target))
                    plan = planner.plan(MotionRequest(q_hover, goal, limits, seed=seed), self.scene)
                    if plan.status is Status.SUCCESS:
                        return way
                    refused[id(q_hover)] = f"{plan.status.value}: {plan.reason}"
            return None

        arm0 = arm_configuration(self.kin, q0)
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
        raise self._no_way_down(stage, planner_name, target, yaws, tried, list(refused.values()))

    def _no_way_down(
        self,
        stage: str,
        planner_name: str,
        target: np.ndarray | tuple[float, float, float],
        yaws: Sequence[float],
        tried: dict[float, list[tuple[np.ndarray, np.ndarray]]],
        refused: list[str],
    ) -> StageFailed:
        """Why `choose_way_down` found no way: what runs into what, counted over the ways it tried."""
        pairs: dict[str, int] = {}
        for ways in tried.values():
            for _, path in ways:
                hit = self.scene.check_path(path, resolution_rad=float(self.check_resolution_rad))
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
        return StageFailed(stage, reason, failure=failure, planner=planner_name, moved=False)

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

    def first_clear(self, ways: Sequence[Sequence[np.ndarray]]) -> int | None:
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

    def nearest_turn(self, q: np.ndarray, q0: np.ndarray) -> np.ndarray:
        """`q` (6,) with each joint turned by whole turns (within its limits, `_TURN_MARGIN_RAD` inside them:
        a joint that arrives a hair past a limit is a start every planner refuses) to the angle nearest the
        one in `q0` (6,), the measured joints: the same posture, reached without a needless full turn."""
        lo, hi = self.kin.joint_limits[:, 0], self.kin.joint_limits[:, 1]
        out = np.array(q, dtype=float)
        for j in range(len(out)):
            turns = out[j] + 2.0 * math.pi * np.arange(-2, 3)
            turns = turns[(turns >= lo[j] + _TURN_MARGIN_RAD) & (turns <= hi[j] - _TURN_MARGIN_RAD)]
            if len(turns):
                out[j] = float(turns[np.argmin(np.abs(turns - q0[j]))])
        return out

    def branches(self, T_tcp: np.ndarray, q0: np.ndarray) -> list[np.ndarray]:
        """The arm configurations (6,) at `T_tcp` (4, 4): each IK branch once, at the turn of each joint
        nearest the measured `q0` (a way that swings a wrist a full turn to keep clear leaves the arm a turn
        from where the next planner expects it), nearest first."""
        return sorted(
            (self.nearest_turn(q, q0) for q in self.kin.ik(T_tcp, all_wraps=False)),
            key=lambda q: float(np.abs(q - q0).max()),
        )

    def raised(self, q: np.ndarray) -> np.ndarray | None:
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
