"""The warehouse sorting task (seeds 000/001): fixed camera, ArUco calibration, DBSCAN perception, pick
each cube, carry it over the perceived obstacle with the transfer planner (NMPC by default), release it
at the drop location of its colour.

The task decides with what a real cell senses: the camera frame, joint encoders and the gripper's finger
position (grasped, slipped, dropped). Which true cube a perceived one was and whether it ended in its drop
zone is for the judge (twin.tasks.warehouse.judge) alone.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from twin.perception.aruco import MarkerNotFound, calibrate
from twin.perception.capture import capture_frame, prefetch_next_capture
from twin.perception.mount import error_bound_m, level_on_table, table_plane
from twin.tasks.cell import Cell, GraspCheck, StageFailed, clear_failure, note_failure, top_down
from twin.tasks.jam import clear_after_release
from twin.tasks.warehouse.judge import WarehouseReferee
from twin.tasks.warehouse.perception import LabeledCube, WarehouseResult, perceive_warehouse
from twin.types import CalibrationOutcome, Landmark, ObjectOutcome

if TYPE_CHECKING:
    from twin.registry import PluginContext

__all__ = ["WarehouseTask", "run_warehouse"]

log = logging.getLogger("twin")

_CUBE_M = 0.05
_APPROACH_M = 0.06  # the transfer ends this far above the drop point
_GRASP_YAW = np.pi / 2  # the seed perceives no cube yaw; an 85 mm stroke closes on a 50 mm cube at any yaw
# With the cube's yaw unknown the fingers may stop across a face (50 mm) or, if it does not turn square
# in the grip, anywhere up to its diagonal (71 mm).
_GRIP_WIDTH_M = (_CUBE_M, _CUBE_M * np.sqrt(2.0))
# A grip within this of the face width is square (under 6 deg off). Wider, the fingers hold the cube by two
# edges, which turns and slips out under the transfer's accelerations: open, turn and grasp again.
_SQUARE_TOL_M = 0.005
# Narrower than the face by more than this (the pads sink 0.2-2 mm into a cube), the fingers hold a corner
# of a cube that stands off the grasp point: such a grip slipped out on the ascent in 3 of 100 stress seeds
_CORNER_TOL_M = 0.005
_YAW_STEP = np.pi / 12  # the grasp and drop yaws tried, 15 deg apart


@dataclass
class _Attempt:
    cube: LabeledCube
    true_id: int | None  # metrics only (the referee's), never decided on
    error: str | None = None
    failure: str | None = None  # the failure's name, when the failed stage knew it (StageFailed.failure)
    stage: str | None = None  # the stage that failed and the planner that planned it (StageFailed's)
    planner: str | None = None
    cycle_time_s: float = 0.0


def _yaws_from(yaw: float, step: float = _YAW_STEP) -> list[float]:
    """Every top-down yaw of a half turn (a parallel gripper repeats after it) in `step`s from `yaw`,
    nearest first: the yaws at which the fingers grip a cube whose yaw is unknown, or set one down."""
    n = round(np.pi / step)
    turns = sorted(range(n), key=lambda k: min(k, n - k) + 0.5 * (k > n / 2))  # 0, +1, -1, +2, -2, ...
    return [yaw + (k if k <= n / 2 else k - n) * step for k in turns]


def _pick_and_place(cell: Cell, cube: LabeledCube, zone: tuple[float, float, float]) -> None:
    task = cell.settings.task.warehouse
    c = cube.centroid
    cell.open_gripper()
    hover = (float(c[0]), float(c[1]), float(c[2] + task.hover_m))
    # the seed grips at one yaw; beside the obstacle that yaw can put a finger into it, and far behind it the
    # upper arm reaches low over it, in some IK branches into it: the opened gripper descends at the yaw
    # nearest the seed's, in the branch, whose way down is clear for the whole arm (chosen before moving)
    way = cell.choose_way_down(c, hover, _yaws_from(_GRASP_YAW))
    cell.reach_hover(way)
    cell.move_pose("descent", way.target)
    grasp, yaw = _square_grasp(cell, c, way.yaw)
    if not grasp.holding:
        raise StageFailed("grasp", grasp.reason)
    if grasp.opening_m < _CUBE_M - _CORNER_TOL_M:  # slips out on the ascent: let go and look again
        raise StageFailed(
            "grasp",
            f"the fingers stopped at {1000 * grasp.opening_m:.1f} mm, narrower than the cube's "
            f"{1000 * _CUBE_M:.0f} mm face: they hold it by a corner (it is not where it was seen)",
        )
    cell.move_pose("ascent", top_down(hover, yaw))
    held = cell.check_holding()
    if not held.holding:
        raise StageFailed("ascent", f"the cube slipped out of the gripper: {held.reason}")
    cell.attach("cube", np.full(3, _CUBE_M))
    drop = (zone[0], zone[1], zone[2] + task.release_height_m + _CUBE_M / 2)
    above = (drop[0], drop[1], drop[2] + _APPROACH_M)
    # the cube is set down at any yaw: the one nearest the grasp's at which the drop is clear
    place_yaw, _ = cell.choose_top_down_yaw([drop, above], _yaws_from(yaw))
    cell.move_pose("transfer", top_down(above, place_yaw))
    held = cell.check_holding()
    if not held.holding:
        raise StageFailed(  # physics during the transfer's motion: its planner's
            "transfer", f"the cube was dropped while carrying it: {held.reason}", planner=cell.block("transfer").name
        )
    # NMPC stops within 3 cm of its goal: finish with a short straight move to the exact drop point
    release_pose = top_down(drop, place_yaw)
    cell.move_pose_turned("place", release_pose)
    cell.release()
    # rise and make sure the cube stayed: fingers that did not open fully hold it apart; then it is set down
    # on the table in its zone again and let go (twin.tasks.jam)
    jam = clear_after_release(
        cell,
        release_pose,
        top_down((drop[0], drop[1], drop[2] + task.hover_m / 2), place_yaw),
        surface_z=zone[2],
        hang_m=_CUBE_M / 2,
    )
    if jam.jammed:
        raise StageFailed("place", f"the cube is stuck between the opened fingers: {jam.reason}", failure="grasp_lost")
    # the cell knows where it put the cube: later motions plan around it (a transfer that swept through the
    # zone would knock it out). Its yaw in the fingers is not known exactly: a square as wide as its diagonal
    lo = np.array([drop[0], drop[1], zone[2]]) - [_CUBE_M / np.sqrt(2.0), _CUBE_M / np.sqrt(2.0), 0.0]
    hi = lo + [_CUBE_M * np.sqrt(2.0), _CUBE_M * np.sqrt(2.0), _CUBE_M]
    cell.scene.add_box_bounds(f"placed_{sum(n.startswith('placed_') for n in cell.scene.boxes())}", lo, hi)


def _square_grasp(cell: Cell, c: np.ndarray, yaw0: float) -> tuple[GraspCheck, float]:
    """Close on the cube at `c` (the tcp there at `yaw0`); if the opening says the fingers hold it by
    two edges (the seed perceives no cube yaw), turn the open gripper by the angle that opening implies and
    close again, the other way round if that was no better. Decided from the finger opening alone; returns
    the grasp and the yaw it was made at."""
    grasp, yaw = cell.close_gripper(_GRIP_WIDTH_M), yaw0
    if not grasp.holding or grasp.opening_m <= _CUBE_M + _SQUARE_TOL_M:
        return grasp, yaw
    # across two edges, d off the faces: opening = side * (cos d + sin d) = side * sqrt(2) * sin(d + 45 deg)
    d = float(np.arcsin(min(1.0, grasp.opening_m / (_CUBE_M * np.sqrt(2.0)))) - np.pi / 4)
    for turn in (d, -d):
        log.info(
            "warehouse: the fingers hold the cube by two edges (%.1f mm); turning %+.0f deg to grasp again",
            1000 * grasp.opening_m,
            np.degrees(turn),
        )
        cell.open_gripper()
        try:
            cell.move_pose("descent", top_down(c, yaw0 + turn))
            yaw = yaw0 + turn
        except StageFailed as e:  # planned, not moved: e.g. the turned gripper would touch the obstacle
            log.info("warehouse: cannot turn there (%s)", e)
        grasp = cell.close_gripper(_GRIP_WIDTH_M)
        if not grasp.holding or grasp.opening_m <= _CUBE_M + _SQUARE_TOL_M:
            break
    return grasp, yaw


def _perceive(cell: Cell) -> WarehouseResult:
    """Capture a frame from the fixed camera, calibrate it on the base marker, perceive the table."""
    settings, world = cell.settings, cell.world
    capture = capture_frame(world, settings)
    views = 0 if cell.calibration is None else cell.calibration.views
    try:
        calib = calibrate(capture.frame, settings)
        T_base_camera = calib.T_base_camera
        if cell.calibration is not None and cell.calibration.status == "fallback":  # an earlier look's stays said
            cell.calibration = replace(cell.calibration, views=views + 1)
        else:
            px = calib.marker.reprojection_px
            cell.calibration = CalibrationOutcome("measured", views=views + 1, reprojection_px=px)
    except MarkerNotFound as e:
        # a fixed camera has no other view: the configured pose, levelled on the table plane it sees (its tilt and
        # height measured), trusted to `camera.mount_tolerance` for the rest, and the run says so
        T_base_camera = level_on_table(capture, settings)
        bound = error_bound_m(settings, cell.kin, levelled=table_plane(capture) is not None)
        reason = f"the ArUco marker was not found ({e}); the configured camera pose, levelled on the table"
        if cell.calibration is None or cell.calibration.status != "fallback":
            log.warning("warehouse: %s: objects may be misplaced by up to %.0f mm", reason, 1e3 * bound)
        cell.calibration = CalibrationOutcome("fallback", views=views + 1, error_bound_m=bound, reason=reason)
    seen = perceive_warehouse(capture.frame, T_base_camera, settings.perception.warehouse, seed=world.seed)
    boxes = [] if seen.obstacle is None else [("obstacle", seen.obstacle.lo, seen.obstacle.hi)]
    boxes += [(f"unknown_{i}", b.lo, b.hi) for i, b in enumerate(seen.unknown)]
    cell.perceived(capture.frame, T_base_camera, [(f"{c.color_label} cube", c.centroid) for c in seen.cubes], boxes)
    prefetch_next_capture(world, settings)
    return seen


def _perceive_again(cell: Cell, cube: LabeledCube) -> LabeledCube | None:
    """After a failed attempt: go home (out of the camera's view), look again and return the cube of the
    same colour nearest to where it was (a slipped or dropped cube has moved); None when none is seen."""
    try:
        cell.reach_posture("home", np.array(cell.settings.robot.home))
        seen = _perceive(cell)
    except StageFailed as e:
        log.info("warehouse: could not look again: %s", e)
        return None
    same = [c for c in seen.cubes if c.color_label == cube.color_label]
    if not same:
        return None
    return min(same, key=lambda c: float(np.linalg.norm(c.centroid[:2] - cube.centroid[:2])))


def run_warehouse(cell: Cell) -> list[ObjectOutcome]:
    """Sort every cube the camera sees; one outcome per true cube, judged by physics at the end."""
    settings, world = cell.settings, cell.world
    task = settings.task.warehouse
    referee = WarehouseReferee(world, settings, cell.watch)  # ground truth: metrics, verdicts at the end
    seen = _perceive(cell)
    cubes = seen.cubes
    if seen.obstacle_extended is not None:
        b = seen.obstacle_extended
        cell.scene.add_box_bounds("obstacle", b.lo, b.hi)
    else:
        log.warning("warehouse: no obstacle seen; planning without one")
    for i, b in enumerate(seen.unknown):  # what stands on the table unexplained is planned around
        cell.scene.add_box_bounds(f"unknown_{i}", b.lo, b.hi)
    attempts = [_Attempt(cube, referee.match(cube.centroid)) for cube in cubes]
    order = list(task.drop_zones)
    attempts.sort(
        key=lambda a: (
            order.index(a.cube.color_label) if a.cube.color_label in order else len(order),
            float(a.cube.centroid[1]),
        )
    )
    for i, att in enumerate(attempts):
        cell.objects_done(i, len(attempts))
        zone = task.drop_zones.get(att.cube.color_label)
        cell.current = f"{att.cube.color_label} cube"
        t0 = world.sim_time
        if zone is None:
            att.error = (
                f"sorting: no drop zone for colour {att.cube.color_label!r}; zones: {', '.join(task.drop_zones)}"
            )
            continue
        if world.sim_time > settings.task.max_sim_time_s:
            att.error = "time: the run time limit was reached before this cube"
            continue
        for k in range(task.retries + 1):
            try:
                _pick_and_place(cell, att.cube, zone)
                clear_failure(att)
                break
            except StageFailed as e:
                note_failure(att, e, k + 1)
                log.info("warehouse: %s cube, attempt %d failed: %s", att.cube.color_label, k + 1, e)
                cell.recover()
                if k < task.retries:
                    again = _perceive_again(cell, att.cube)
                    if again is None:
                        att.error = f"{att.error}; then not seen again on the table"
                        break
                    att.cube = again
        att.cycle_time_s = world.sim_time - t0
    cell.objects_done(len(attempts), len(attempts))
    try:
        cell.reach_posture("home", np.array(settings.robot.home))
    except StageFailed as e:
        log.info("warehouse: could not return home: %s", e)
    cell.settle(1.0)
    return referee.outcomes(attempts)


class WarehouseTask:
    """The warehouse sorting task as a task plugin (name `warehouse`). Its settings are the config's
    `task.warehouse` and `perception.warehouse` sections (models in `twin.config.warehouse`)."""

    def __init__(self, params: None, context: PluginContext) -> None:
        self.context = context

    def run(self, cell: Cell) -> list[ObjectOutcome]:
        return run_warehouse(cell)

    def landmarks(self) -> list[Landmark]:
        """The drop zone of each colour, as large as a placed cube may be off it."""
        task = self.context.settings.task.warehouse
        return [Landmark(f"{c} drop", (p[0], p[1], p[2]), task.drop_radius_m) for c, p in task.drop_zones.items()]
