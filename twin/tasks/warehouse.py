"""The warehouse sorting task (seeds 000/001): fixed camera, ArUco calibration, DBSCAN perception, pick
each cube, carry it over the perceived obstacle with the transfer planner (NMPC by default), release it
at the drop location of its colour."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from twin.perception.aruco import MarkerNotFound, calibrate
from twin.perception.capture import capture_frame
from twin.perception.warehouse import LabeledCube, perceive_warehouse
from twin.tasks.cell import Cell, StageFailed, top_down
from twin.types import ObjectOutcome

__all__ = ["run_warehouse"]

log = logging.getLogger("twin")

_CUBE_M = 0.05
_APPROACH_M = 0.06  # the transfer ends this far above the drop point
_GRASP_YAW = np.pi / 2  # the seed perceives no cube yaw; an 85 mm stroke closes on a 50 mm cube at any yaw


@dataclass
class _Attempt:
    cube: LabeledCube
    true_id: int | None
    error: str | None = None
    cycle_time_s: float = 0.0


def _pick_and_place(cell: Cell, cube: LabeledCube, zone: tuple[float, float, float]) -> None:
    task = cell.settings.task.warehouse
    c = cube.centroid
    cell.open_gripper()
    cell.move_pose("hover", top_down((c[0], c[1], c[2] + task.hover_m), _GRASP_YAW))
    cell.move_pose("descent", top_down(c, _GRASP_YAW))
    if cell.close_gripper() is None:
        raise StageFailed("grasp", "nothing between the fingers after closing")
    cell.move_pose("ascent", top_down((c[0], c[1], c[2] + task.hover_m), _GRASP_YAW))
    if cell.world.grasped_object() is None:
        raise StageFailed("ascent", "the cube slipped out of the gripper")
    cell.attach("cube", np.full(3, _CUBE_M))
    drop = (zone[0], zone[1], zone[2] + task.release_height_m + _CUBE_M / 2)
    above = (drop[0], drop[1], drop[2] + _APPROACH_M)
    cell.move_pose("transfer", top_down(above, _GRASP_YAW))
    if cell.world.grasped_object() is None:
        raise StageFailed("transfer", "the cube was dropped while carrying it")
    # NMPC stops within 3 cm of its goal: finish with a short straight move to the exact drop point
    cell.move_pose("place", top_down(drop, _GRASP_YAW))
    cell.release()
    cell.move_pose("ascent", top_down((drop[0], drop[1], drop[2] + task.hover_m / 2), _GRASP_YAW))


def run_warehouse(cell: Cell) -> list[ObjectOutcome]:
    """Sort every cube the camera sees; one outcome per true cube, judged by physics at the end."""
    settings, world = cell.settings, cell.world
    task = settings.task.warehouse
    truth = {o.id: o for o in world.objects()}
    cubes: tuple[LabeledCube, ...] = ()
    global_error: str | None = None
    capture = capture_frame(world, settings)
    try:
        calib = calibrate(capture.frame, settings)
        seen = perceive_warehouse(capture.frame, calib.T_base_camera, settings.perception.warehouse, seed=world.seed)
        cubes = seen.cubes
        if seen.obstacle_extended is not None:
            b = seen.obstacle_extended
            cell.scene.add_box_bounds("obstacle", b.lo, b.hi)
        else:
            log.warning("warehouse: no obstacle seen; planning without one")
    except MarkerNotFound as e:
        global_error = f"calibration failed: {e}"
    attempts: list[_Attempt] = []
    for cube in cubes:
        near = min(truth.values(), key=lambda o: float(np.linalg.norm(o.position[:2] - cube.centroid[:2])), default=None)
        true_id = near.id if near is not None and np.linalg.norm(near.position[:2] - cube.centroid[:2]) < 0.05 else None
        attempts.append(_Attempt(cube, true_id))
    order = list(task.drop_zones)
    attempts.sort(key=lambda a: (order.index(a.cube.color_label) if a.cube.color_label in order else len(order), float(a.cube.centroid[1])))
    for att in attempts:
        zone = task.drop_zones.get(att.cube.color_label)
        cell.current = f"{att.cube.color_label} cube"
        t0 = world.sim_time
        if zone is None:
            att.error = f"no drop zone for colour {att.cube.color_label!r}; zones: {', '.join(task.drop_zones)}"
            continue
        if world.sim_time > settings.task.max_sim_time_s:
            att.error = "run time limit reached"
            continue
        for k in range(task.retries + 1):
            try:
                _pick_and_place(cell, att.cube, zone)
                att.error = None
                break
            except StageFailed as e:
                att.error = str(e)
                log.info("warehouse: %s cube, attempt %d failed: %s", att.cube.color_label, k + 1, e)
                cell.recover()
        att.cycle_time_s = world.sim_time - t0
    try:
        cell.move_joints("home", np.array(settings.robot.home))
    except StageFailed as e:
        log.info("warehouse: could not return home: %s", e)
    cell.settle(1.0)
    return _judge(cell, truth, attempts, global_error)


def _judge(cell: Cell, truth: dict, attempts: list[_Attempt], global_error: str | None) -> list[ObjectOutcome]:
    task = cell.settings.task.warehouse
    by_true = {a.true_id: a for a in attempts if a.true_id is not None}
    out = []
    for oid, o0 in truth.items():
        now = cell.world.object_state(oid)
        zone = task.drop_zones.get(o0.color or "")
        placed = zone is not None and float(np.linalg.norm(now.position[:2] - np.array(zone[:2]))) <= task.drop_radius_m and now.position[2] < zone[2] + _CUBE_M
        att = by_true.get(oid)
        if att is None:
            err = global_error or "not perceived"
        else:
            err = att.error
        if placed:
            err = None
        elif err is None:
            err = "released, but it did not come to rest in its drop zone"
        out.append(
            ObjectOutcome(
                id=o0.name,
                cls=o0.cls,
                color=o0.color,
                target_bin=f"drop_{o0.color}",
                placed=bool(placed),
                error=err,
                cycle_time_s=att.cycle_time_s if att else 0.0,
                pose_error_m=float(np.linalg.norm(att.cube.centroid[:2] - o0.position[:2])) if att else None,
            )
        )
    return out
