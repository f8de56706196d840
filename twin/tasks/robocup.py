"""The RoboCup ARM sorting task (seed 002): the 7-stage state machine with perception in the loop.

Per object: capture pose -> perceive -> choose a target -> (1) base-first alignment -> (2) pre-grasp
hover `hover_m` above (MoveJ) -> (3) descent (MoveL) -> (4) close and settle -> (5) ascent (MoveL) ->
(6) transfer to the bin of its class (MoveJ) -> (7) release; then home. A failed object is retried from a
fresh perception (`retries` times), then skipped with its reason; the run goes on.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from twin.config import Settings
from twin.kinematics import wrap_to_pi
from twin.perception.capture import capture_frame
from twin.perception.pipeline import camera_extrinsics, make_detector, perceive_robocup
from twin.perception.robocup import ObjectEstimate
from twin.scene_layout import OBJECT_TEMPLATES
from twin.tasks.cell import Cell, StageFailed, top_down
from twin.types import ObjectOutcome

if TYPE_CHECKING:
    from twin.world import World

__all__ = ["run_robocup", "bin_for", "feasible_cube_yaw"]

log = logging.getLogger("twin")

_BIN_HALF_M = 0.15  # bins are 0.30 x 0.30 m (urdf/bin_*.urdf)
_BIN_WALL_M = 0.12
_BIN_FLOOR_M = 0.01
_RELEASE_GAP_M = 0.03  # the object's bottom above the bin floor when the gripper opens
_SAME_OBJECT_M = 0.04  # a later estimate this close to a failed one (same label) is the same object


@dataclass
class _Target:
    """One object as the robot knows it: where it was seen and what happened when it tried."""

    label: str
    cls: str
    color: str | None
    position: np.ndarray
    attempts: int = 0
    done: bool = False
    error: str | None = None
    cycle_time_s: float = 0.0
    first_estimate: np.ndarray | None = None
    true_ids: set[int] = field(default_factory=set)


def bin_for(cls: str, color: str | None, settings: Settings) -> str:
    """The fixture name of the bin for a class (a `cube_red`-style key wins over `cube`)."""
    bins = settings.task.robocup.bins
    if color and f"{cls}_{color}" in bins:
        return bins[f"{cls}_{color}"]
    return bins.get(cls, settings.task.robocup.default_bin)


def _bin_centres(settings: Settings) -> dict[str, np.ndarray]:
    """Centres of the fixtures the class-to-bin map names (a bin named there but missing is a KeyError later)."""
    task = settings.task.robocup
    named = set(task.bins.values()) | {task.default_bin}
    return {f.name: np.array(f.position) for f in settings.world.fixtures if f.name in named}


def _in_any_bin(p: np.ndarray, bins: dict[str, np.ndarray]) -> bool:
    return any(abs(p[0] - c[0]) < _BIN_HALF_M and abs(p[1] - c[1]) < _BIN_HALF_M for c in bins.values())


def feasible_cube_yaw(est: ObjectEstimate, yaw: float, max_opening_m: float) -> float:
    """The seed grips cubes diagonally (+45 deg, edge-to-edge self-locking), but across a 75 mm cube's
    diagonal that spans 106 mm, more than the 85 mm stroke: fall back to a face grip where it cannot fit."""
    if est.cls != "cube":
        return yaw
    side = OBJECT_TEMPLATES["cube"].size[0]
    return yaw - math.pi / 4 if side * math.sqrt(2.0) > max_opening_m else yaw


def _pan_towards(x: float, y: float) -> float:
    """Shoulder pan that faces the point (x, y): with pan 0 the arm reaches towards -x."""
    return float(wrap_to_pi(math.atan2(y, x) + math.pi))


def _pick_and_place(cell: Cell, est: ObjectEstimate, bin_xy: np.ndarray, slot_index: int) -> None:
    task = cell.settings.task.robocup
    x, y, z_grasp, yaw, _, _, w_grip = (float(v) for v in est.grasp)
    yaw = feasible_cube_yaw(est, yaw, cell.settings.gripper.max_opening_m)
    # (1) base-first alignment
    q = cell.world.joint_positions().copy()
    pan = _pan_towards(x, y)
    q[0] = q[0] + (pan - q[0] + math.pi) % (2 * math.pi) - math.pi
    cell.move_joints("align", q)
    # (2) pre-grasp hover, gripper opened to the lookup width
    cell.open_gripper(min(w_grip, cell.settings.gripper.max_opening_m))
    hover = top_down((x, y, z_grasp + task.hover_m), yaw)
    cell.move_pose("hover", hover)
    # (3) descent
    cell.move_pose("descent", top_down((x, y, z_grasp), yaw))
    # (4) close and settle
    if cell.close_gripper() is None:
        raise StageFailed("grasp", "nothing between the fingers after closing")
    # (5) ascent
    cell.move_pose("ascent", hover)
    if cell.world.grasped_object() is None:
        raise StageFailed("ascent", "the object slipped out of the gripper")
    ext = np.array(OBJECT_TEMPLATES[est.cls].extents(est.orientation == "horizontal"))
    short, long_ = sorted((float(ext[0]), float(ext[1])))
    # the fingers close along the tcp's x axis, across the object's short side
    cell.attach(est.cls, np.array([short, long_, ext[2]]), below_tcp_m=z_grasp - ext[2] / 2)
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    half_xy = 0.5 * np.array([c * short + s * long_, s * short + c * long_])  # its footprint's AABB, world
    # (6) transfer above the bin slot, the object's bottom `place_clearance_m` above the walls
    slot = np.asarray(bin_xy[:2], dtype=float) + _slot_offset(slot_index, half_xy)
    cell.move_pose("transfer", top_down((slot[0], slot[1], _BIN_WALL_M + task.place_clearance_m + z_grasp), yaw))
    if cell.world.grasped_object() is None:
        raise StageFailed("transfer", "the object was dropped while carrying it")
    # (7) place: lower it into the bin (a tall object dropped from above the walls topples out), release
    cell.move_pose("place", top_down((slot[0], slot[1], _BIN_FLOOR_M + _RELEASE_GAP_M + z_grasp), yaw))
    cell.release()
    cell.move_pose("ascent", top_down((slot[0], slot[1], _BIN_WALL_M + task.place_clearance_m + z_grasp), yaw))


def _slot_offset(k: int, half_xy: np.ndarray) -> np.ndarray:
    """Where in the bin the k-th object goes: the four quarters in turn, as far out as its footprint
    (half extents `half_xy`, world axes) allows inside the walls."""
    reach = np.clip(_BIN_HALF_M - 0.01 - half_xy - 0.005, 0.0, 0.07)
    signs = [(1, 1), (-1, -1), (1, -1), (-1, 1)][k % 4]
    return reach * np.array(signs, dtype=float)


def run_robocup(cell: Cell) -> list[ObjectOutcome]:
    """Sort every object on the table into its bin; one outcome per true object, judged at the end."""
    settings, world = cell.settings, cell.world
    task = settings.task.robocup
    truth = {o.id: o for o in world.objects()}
    bins = _bin_centres(settings)
    detector = make_detector(settings)
    targets: list[_Target] = []
    placed_in: dict[str, int] = {}
    home = np.array(settings.robot.home)
    capture_q = np.array(settings.camera.capture_pose)
    for _ in range(3 * len(truth) + 3):
        if world.sim_time > settings.task.max_sim_time_s:
            log.info("robocup: run time limit reached")
            break
        cell.current = "scene"
        try:
            cell.move_joints("capture", capture_q)
        except StageFailed as e:
            log.warning("robocup: cannot reach the capture pose: %s", e)
            break
        cap = capture_frame(world, settings, move=False)
        T_bc = camera_extrinsics(settings, cap, None)
        gt = world.objects() if getattr(detector, "needs_ground_truth", False) else None
        seen = perceive_robocup(cap.frame, T_bc, settings, detector, ground_truth=gt, seed=world.seed)
        est = _choose(seen.objects, targets, bins, task.retries)
        if est is None:
            break
        _update_obstacles(cell, seen.objects, est, bins)
        tgt = _target_for(est, targets)
        tgt.attempts += 1
        tgt.true_ids |= _true_match(world, est)  # metrics only: which true object this was
        cell.current = est.label
        t0 = world.sim_time
        try:
            bin_name = bin_for(est.cls, est.color, settings)
            _pick_and_place(cell, est, bins[bin_name], placed_in.get(bin_name, 0))
            placed_in[bin_name] = placed_in.get(bin_name, 0) + 1
            tgt.done, tgt.error = True, None
        except StageFailed as e:
            tgt.error = str(e)
            log.info("robocup: %s attempt %d failed: %s", est.label, tgt.attempts, e)
            cell.recover()
        except KeyError:
            tgt.done, tgt.error = True, f"no bin named {bin_for(est.cls, est.color, settings)!r} among the fixtures"
        tgt.cycle_time_s += world.sim_time - t0
        try:
            cell.move_joints("home", home)
        except StageFailed as e:
            log.info("robocup: could not return home: %s", e)
    cell.settle(1.0)
    return _judge(cell, truth, targets, bins)


def _update_obstacles(cell: Cell, estimates: tuple[ObjectEstimate, ...], target: ObjectEstimate, bins: dict) -> None:
    """Every other perceived object on the table becomes a box in the planning scene (the target is left
    out: the fingers close around it)."""
    for name in [n for n in cell.scene.boxes() if n.startswith("seen_")]:
        cell.scene.remove(name)
    for i, est in enumerate(estimates):
        if est is target or _in_any_bin(est.position, bins):
            continue
        ext = np.array(OBJECT_TEMPLATES[est.cls].extents(est.orientation == "horizontal"))
        short, long_ = sorted((float(ext[0]), float(ext[1])))
        # the grasp yaw closes across the short side (cubes: across a face, 45 deg off the seed's yaw)
        yaw = est.yaw - math.pi / 4 if est.cls == "cube" else est.yaw
        T = np.eye(4)
        T[:3, :3] = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
        T[:3, 3] = [est.position[0], est.position[1], ext[2] / 2 + 0.002]
        cell.scene.add_box(f"seen_{i}_{est.label}", np.array([short, long_, ext[2]]), T)


def _choose(estimates: tuple[ObjectEstimate, ...], targets: list[_Target], bins: dict, retries: int) -> ObjectEstimate | None:
    """The most confident estimate that is on the table (not in a bin) and not given up on."""
    best = None
    for est in estimates:
        if _in_any_bin(est.position, bins):
            continue
        t = _find(est, targets)
        if t is not None and (t.done or t.attempts > retries):
            continue
        key = (-est.confidence, float(np.linalg.norm(est.position[:2])))
        if best is None or key < best[0]:
            best = (key, est)
    return None if best is None else best[1]


def _find(est: ObjectEstimate, targets: list[_Target]) -> _Target | None:
    for t in targets:
        if t.label == est.label and float(np.linalg.norm(t.position[:2] - est.position[:2])) < _SAME_OBJECT_M:
            return t
    return None


def _target_for(est: ObjectEstimate, targets: list[_Target]) -> _Target:
    t = _find(est, targets)
    if t is None:
        t = _Target(est.label, est.cls, est.color, est.position.copy(), first_estimate=est.position.copy())
        targets.append(t)
    t.position = est.position.copy()
    return t


def _true_match(world: "World", est: ObjectEstimate) -> set[int]:
    near = [(float(np.linalg.norm(o.position[:2] - est.position[:2])), o.id) for o in world.objects()]
    d, oid = min(near) if near else (math.inf, -1)
    return {oid} if d < 0.05 else set()


def _judge(cell: Cell, truth: dict, targets: list[_Target], bins: dict[str, np.ndarray]) -> list[ObjectOutcome]:
    settings = cell.settings
    out = []
    for oid, o0 in truth.items():
        now = cell.world.object_state(oid)
        bin_name = bin_for(o0.cls, o0.color, settings)
        c = bins.get(bin_name)
        placed = c is not None and abs(now.position[0] - c[0]) < _BIN_HALF_M and abs(now.position[1] - c[1]) < _BIN_HALF_M and now.position[2] < _BIN_WALL_M + 0.05
        mine = [t for t in targets if oid in t.true_ids]
        if placed:
            err = None
        elif not mine:
            err = "not perceived"
        else:
            err = mine[-1].error or "released, but it did not land in its bin"
        pose_err = float(np.linalg.norm(mine[0].first_estimate[:2] - o0.position[:2])) if mine and mine[0].first_estimate is not None else None
        out.append(
            ObjectOutcome(
                id=o0.name, cls=o0.cls, color=o0.color, target_bin=bin_name, placed=bool(placed), error=err,
                cycle_time_s=sum(t.cycle_time_s for t in mine), pose_error_m=pose_err,
            )
        )
    return out
