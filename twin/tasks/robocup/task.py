"""The RoboCup ARM sorting task (seed 002): the 7-stage state machine with perception in the loop.

Per object: capture pose -> perceive -> choose a target -> (1) base-first alignment -> (2) pre-grasp
hover `hover_m` above (MoveJ) -> (3) descent (MoveL) -> (4) close and settle -> (5) ascent (MoveL) ->
(6) transfer to the bin of its class (MoveJ) -> (7) lower it into the bin, release; then home. A failed
object is retried from a fresh perception (`retries` times), then skipped with its reason; the run goes on.

The task decides with what a real cell senses: camera frames, joint encoders and the gripper's finger
position (grasped, slipped, dropped: `Cell.close_gripper`, `Cell.check_holding`). Which true object an
estimate was and whether it ended in its bin is for the judge (twin.tasks.robocup.judge) alone.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Final

import numpy as np

from twin.config import Settings
from twin.perception.capture import Capture, capture_frame, prefetch_next_capture
from twin.perception.pipeline import make_detector
from twin.robot.kinematics import wrap_to_pi
from twin.scene_layout import OBJECT_TEMPLATES
from twin.tasks.cell import Cell, StageFailed, clear_failure, note_failure, top_down
from twin.tasks.jam import clear_after_release
from twin.tasks.robocup.bins import BinGeometry, bin_for, bin_geometries, read_bin_geometry
from twin.tasks.robocup.calibration import calibrate_hand_eye, relook_target
from twin.tasks.robocup.judge import RobocupReferee, perceive_robocup_scene
from twin.tasks.robocup.perception import ObjectEstimate, wrap_half_turn
from twin.types import ObjectOutcome

if TYPE_CHECKING:
    from twin.registry import PluginContext
    from twin.robot import Robot

__all__ = [
    "STROKE_MARGIN_M",
    "BinGeometry",
    "GraspChoice",
    "GraspSlipped",
    "RobocupTask",
    "bin_for",
    "bin_geometries",
    "choose_grasp",
    "feasible_cube_yaw",
    "grasp_sides",
    "grasp_yaw_symmetry",
    "grip_width",
    "read_bin_geometry",
    "run_robocup",
]

log = logging.getLogger("twin")

# the object's bottom above the bin floor when the gripper opens: set down, not dropped (a dropped object
# bounces and may topple against a wall; one hanging from the pads can also wedge them in PyBullet)
_RELEASE_GAP_M = 0.005
_RELEASE_OPEN_M = 0.01  # in the bin the fingers open only this much wider than the grasp: clear of the walls
_WALL_MARGIN_M = 0.005  # a placed object's footprint keeps this from the inner walls and from the others
_SPOT_STEP_M = 0.005  # the grid of candidate release points in a bin
_SAME_OBJECT_M = 0.04  # a later estimate this close to a failed one (same label) is the same object
_UNKNOWN_PAD_M = 0.01  # an unnamed thing on the table is planned around this much wider than it was seen

# The stroke a top-down grasp leaves around the object (both sides together) before it counts as needing the
# stroke's last millimetres: what the opened fingers must straddle grows with the error of the grasp centre
# along the closing direction (~2 mm a side on a calibrated camera, tracking included: 4 mm) and of its yaw
# (1 deg across a box's ~100 mm long side: 1.8 mm). With less, a finger comes down on the object's top edge,
# tilts it, and it is held across its edges and slips out on the ascent (a lying spam: 83 mm in the 85 mm
# stroke, 2 mm). Such a side is gripped only when no other side of the object fits (`choose_grasp`).
STROKE_MARGIN_M: Final = 0.006
# A grasp tried again after a slip goes as deep as the gripper allows: its fingertips this far above the table
# (the fitted table plane and the arm's tracking are good to a few mm) and its palm this far above the object's
# top, so the pads hold more of the object, nearer its centre of mass.
_TIP_CLEARANCE_M = 0.008
_PALM_CLEARANCE_M = 0.005
# ... squeezes with the 2F-85's most (its 20..235 N), unless its class has a force of its own (the marker's
# gentle 20 N: harder, the pads sink through it, task.grip_force_n) ...
_GRIPPER_MAX_FORCE_N = 235.0
# ... and lifts at this fraction of the arm's speed (the same path, the time stretched: the inertial load on
# the grip falls with its square).
_SLOW_LIFT = 0.5
# a grasp yaw this close (modulo a half turn) to one that slipped grips the same faces: half the 45 deg between
# a cube's face and its diagonal
_SAME_YAW_RAD = math.pi / 8


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
    failure: str | None = None  # the failure's name, when the failed stage knew it (StageFailed.failure)
    stage: str | None = None  # the stage that failed and the planner that planned it (StageFailed's)
    planner: str | None = None
    cycle_time_s: float = 0.0
    first_estimate: np.ndarray | None = None
    slipped: list[tuple[GraspChoice, float]] = field(default_factory=list)  # grasps (and base yaws) that slipped
    true_ids: set[int] = field(default_factory=set)  # metrics only (the referee's), never decided on


def _in_any_bin(p: np.ndarray, bins: dict[str, BinGeometry]) -> bool:
    return any(b.over(p) for b in bins.values())


@dataclass(frozen=True)
class GraspChoice:
    """One top-down grasp of an object: across which of its sides, and how.

    `side`: "short"/"long" (a box's or a lying cylinder's footprint sides), "diagonal"/"face" (a cube's),
    "round" (a standing cylinder's). `yaw_offset_rad`: the closing direction's turn from the perceived grasp
    yaw (which closes across the footprint's short side; a cube's across its diagonal). `width_m`: what should
    lie between the fingers. `margin_m`: the stroke left around it (max opening - width; < 0: it does not
    fit). `lower_m`: how far below the grasp lookup's height the tcp goes; `force_n`: the squeeze (None: the
    class's or the gripper's); `lift_speed`: the ascent's share of the arm's speed."""

    side: str
    yaw_offset_rad: float
    width_m: float
    margin_m: float
    lower_m: float = 0.0
    force_n: float | None = None
    lift_speed: float = 1.0

    @property
    def tight(self) -> bool:
        """The grasp needs the stroke's last millimetres (`STROKE_MARGIN_M`)."""
        return self.margin_m < STROKE_MARGIN_M

    def same_side(self, other: GraspChoice) -> bool:
        return self.side == other.side


class GraspSlipped(StageFailed):
    """The object left the fingers after a grasp that held (the ascent, the transfer): `grasp` and the base-frame
    `yaw` were what slipped, so the next attempt grips it otherwise."""

    def __init__(self, stage: str, reason: str, *, grasp: GraspChoice, yaw: float, planner: str | None = None):
        super().__init__(stage, reason, planner=planner)
        self.grasp = grasp
        self.yaw = yaw


def grasp_sides(est: ObjectEstimate, max_opening_m: float) -> list[GraspChoice]:
    """Every top-down grasp of the perceived class and orientation, in the order the task prefers them, with
    the stroke each leaves (negative: wider than the stroke). A parallel gripper from above closes across a
    side of the object's footprint, never across its height: a lying spam (102 x 83 footprint, 60 high) has
    its 83 mm side only (102 mm is wider than the 85 mm stroke), a standing one (102 x 60) its 60 mm side; a
    cube its 106 mm diagonal (the seed's self-locking grip) or a 75 mm face; a lying cylinder its diameter (its
    length is far wider), a standing one its diameter at any yaw."""
    t = OBJECT_TEMPLATES[est.cls]
    lying = est.orientation == "horizontal"
    ex, ey, _ = t.extents(lying)
    short, long_ = sorted((float(ex), float(ey)))
    if est.cls == "cube":  # perception's cube yaw closes across the diagonal
        sides = [("diagonal", 0.0, short * math.sqrt(2.0)), ("face", -math.pi / 4, short)]
    elif t.shape == "cylinder" and not lying:
        sides = [("round", 0.0, short)]
    else:
        sides = [("short", 0.0, short), ("long", math.pi / 2, long_)]
    return [GraspChoice(name, off, w, max_opening_m - w) for name, off, w in sides]


def choose_grasp(
    est: ObjectEstimate,
    max_opening_m: float,
    *,
    slipped: tuple[GraspChoice, ...] = (),
    lower_max_m: float = 0.0,
    force_max_n: float | None = None,
) -> GraspChoice:
    """The grasp to use on a perceived object. The first of its sides (`grasp_sides`, in order) that leaves
    `STROKE_MARGIN_M` of the stroke; when none does, the one that leaves the most (a lying spam: its 83 mm
    side, 2 mm; it is gripped at its footprint's centre, twin.tasks.robocup.perception, and the fingers must
    then close on its faces, `_pick_and_place`). When grasps of the object slipped (`slipped`: the earlier
    attempts', which the task keeps), a side that fits and has not slipped is taken instead; with none left
    the same side is gripped otherwise: `lower_max_m` deeper (the most the gripper allows, `_lowest_tcp`),
    with `force_max_n` (None: the usual force) and lifted at `_SLOW_LIFT` of the arm's speed."""
    sides = grasp_sides(est, max_opening_m)
    fits = [g for g in sides if g.margin_m >= 0.0]
    comfortable = [g for g in fits if not g.tight]
    best = comfortable[0] if comfortable else max(sides, key=lambda g: g.margin_m)
    if not slipped:
        return best
    fresh = [g for g in (comfortable or fits) if not any(g.same_side(s) for s in slipped)]
    if fresh:
        return fresh[0]
    return replace(best, lower_m=max(0.0, lower_max_m), force_n=force_max_n, lift_speed=_SLOW_LIFT)


def feasible_cube_yaw(est: ObjectEstimate, yaw: float, max_opening_m: float) -> float:
    """The grasp yaw of `choose_grasp`'s side: the seed grips cubes diagonally (+45 deg, edge-to-edge
    self-locking), but across a 75 mm cube's diagonal that spans 106 mm, more than the 85 mm stroke: a face
    grip there."""
    return yaw + choose_grasp(est, max_opening_m).yaw_offset_rad


def grasp_yaw_symmetry(est: ObjectEstimate) -> float | None:
    """The turn (rad) about the vertical that maps this object's grasp onto an equal one: 0 for any turn
    (a standing cylinder), a quarter turn for a cube; None when only the perceived yaw (or its half turn,
    the same for a parallel gripper) grips it."""
    t = OBJECT_TEMPLATES.get(est.cls)
    if t is None:
        return None
    if t.shape == "cylinder":
        return 0.0 if est.orientation == "vertical" else None
    ex, ey, _ = t.extents(est.orientation == "horizontal")
    return math.pi / 2 if abs(ex - ey) < 1e-6 else None  # a square footprint: the cube


def _clear_grasp_yaw(
    cell: Cell, est: ObjectEstimate, xyz: tuple[float, float, float], yaw: float, *, avoid: tuple[float, ...] = ()
) -> float:
    """The grasp yaw to use. An object that can be gripped at other yaws too (`grasp_yaw_symmetry`) is
    gripped at the one of them the wrist reaches with the least turn after the base-first alignment (a
    standing cylinder's perceived yaw says nothing: any yaw grips it), unless the gripper there or on its
    way down from the hover comes closer than `CHOOSE_CLEARANCE_M` to something in the planning scene;
    then at the next one that does not, or the one with the most clearance (a standing can beside a
    standing marker is gripped with the fingers turned away from it; `Cell.choose_top_down_yaw`). Yaws within
    `_SAME_YAW_RAD` of one in `avoid` (grasps of this object that slipped) come after all the others: a cube
    that slipped from one pair of faces is gripped across the other pair."""
    turn = grasp_yaw_symmetry(est)
    if turn is None:
        return yaw
    q_ref = _aligned(cell.world.joint_positions(), xyz[0], xyz[1])
    R = cell.kin.fk(q_ref)[:3, :3]
    yaw_ref = math.atan2(float(R[1, 0]), float(R[0, 0]))  # the fingers' closing direction if the wrist stays
    if turn == 0.0:
        step, n = math.pi / 12, 12  # every 15 deg of the half turn (a parallel gripper repeats after it)
        base = yaw_ref
    else:
        step, n = turn, max(1, round(math.pi / turn))
        base = yaw + round((yaw_ref - yaw) / turn) * turn
    candidates = sorted(
        (yaw_ref + wrap_half_turn(base + k * step - yaw_ref) for k in range(n)),
        key=lambda a: (any(abs(wrap_half_turn(a - b)) < _SAME_YAW_RAD for b in avoid), abs(a - yaw_ref)),
    )
    x, y, z = xyz
    hover_m = cell.settings.task.robocup.hover_m
    way_down = [(x, y, z), (x, y, z + hover_m / 2), (x, y, z + hover_m)]  # the descent from the hover
    best, best_c = cell.choose_top_down_yaw(way_down, candidates)
    if best != candidates[0]:
        log.info(
            "robocup: %s gripped at yaw %.0f deg, %.0f mm clear of the planning scene",
            est.label,
            math.degrees(best),
            1e3 * best_c,
        )
    return best


def grip_width(est: ObjectEstimate, max_opening_m: float) -> float:
    """The width the fingers should stop at on this object, from its perceived class and orientation: across
    the side `choose_grasp` grips (the short side of its footprint; cubes: a face, or the diagonal where it
    fits with `STROKE_MARGIN_M` to spare)."""
    return choose_grasp(est, max_opening_m).width_m


def _lowest_tcp(settings: Settings, robot: Robot, est: ObjectEstimate, z_grasp: float, opening_m: float) -> float:
    """The lowest tcp height (base z) for a top-down grasp of `est`: the fingertips `_TIP_CLEARANCE_M` above
    the table and the gripper's palm `_PALM_CLEARANCE_M` above the object's top, from the gripper's URDF
    shapes; the table's height is where the grasp lookup put `z_grasp` from."""
    entry = settings.perception.robocup.grasp.get(f"{est.cls}_{est.orientation}")
    table_z = z_grasp - (entry.z_grasp_m if entry is not None else est.top_m / 2.0)
    top = table_z + OBJECT_TEMPLATES[est.cls].height(est.orientation == "horizontal")
    boxes = robot.gripper_boxes(opening_m)
    tip = max(hi[2] for lo, hi in boxes)  # tcp z points down: larger is lower
    # the palm: the shapes across the axis between the fingers, where the object's top would meet the gripper
    palm = max(hi[2] for lo, hi in boxes if lo[0] < 0.0 < hi[0])
    return max(table_z + _TIP_CLEARANCE_M + tip, top + _PALM_CLEARANCE_M + palm)


@contextlib.contextmanager
def _lift_speed(cell: Cell, share: float) -> Iterator[None]:
    """Moves inside run at `share` of the arm's speed: the same paths, time stretched (velocity x share,
    acceleration x share^2, jerk x share^3)."""
    if share >= 1.0:
        yield
        return
    limits = cell.limits
    cell.limits = replace(
        limits,
        max_joint_vel=limits.max_joint_vel * share,
        max_joint_acc=limits.max_joint_acc * share**2,
        max_joint_jerk=limits.max_joint_jerk * share**3,
    )
    try:
        yield
    finally:
        cell.limits = limits


def _aligned(q: np.ndarray, x: float, y: float) -> np.ndarray:
    """`q` with the shoulder pan turned (the short way) to face (x, y): the base-first alignment."""
    out = np.array(q, dtype=float)
    pan = _pan_towards(x, y)
    out[0] = out[0] + (pan - out[0] + math.pi) % (2 * math.pi) - math.pi
    return out


def _pan_towards(x: float, y: float) -> float:
    """Shoulder pan that faces the point (x, y): with pan 0 the arm reaches towards -x."""
    return float(wrap_to_pi(math.atan2(y, x) + math.pi))


@dataclass(frozen=True)
class _Footprint:
    """Where the task released an object in a bin: centre (2,) and half extents (2,), bin frame."""

    centre: np.ndarray
    half: np.ndarray


def _turned(half_tcp: np.ndarray, rel_yaw: float) -> np.ndarray:
    """Half extents (2,) along the bin's axes of a box with half extents `half_tcp` along the tcp's x, y."""
    c, s = abs(math.cos(rel_yaw)), abs(math.sin(rel_yaw))
    return np.array([c * half_tcp[0] + s * half_tcp[1], s * half_tcp[0] + c * half_tcp[1]])


def _release_spot(
    bin_: BinGeometry, placed: list[_Footprint], obj_half_tcp: np.ndarray, reach_half_tcp: np.ndarray, grasp_yaw: float
) -> tuple[np.ndarray, float, _Footprint]:
    """Where (bin frame xy) and at which tcp yaw to release an object: inside the inner walls with what
    reaches below the rims (`reach_half_tcp`: the object and the opened fingers, tcp axes), clear of what
    the task placed in this bin before, as far out towards a corner as it goes (room for the next ones).
    On the way the object is turned square to the bin's walls (the least turn; a quarter more only if that
    packs better). If nothing is clear, the spot that overlaps the others least.

    Over a grid of candidates, the first (turn, then x, then y) with the least key (overlap, turn, -distance
    from the centre). The overlaps of the whole grid are taken at once, element by element the same sums
    as one candidate at a time; the distances by `_farthest` (see there)."""
    centre = (bin_.inner_lo[:2] + bin_.inner_hi[:2]) / 2.0
    square = grasp_yaw - float(wrap_to_pi(4.0 * (grasp_yaw - bin_.yaw))) / 4.0  # the nearest yaw square to the walls
    grids: list[tuple[float, np.ndarray, np.ndarray]] = []  # per turn: (yaw, candidates (n, 2), overlaps (n,))
    for turn in (0.0, math.pi / 2):
        yaw = square + turn
        reach = _turned(reach_half_tcp, yaw - bin_.yaw)
        lo = bin_.inner_lo[:2] + reach + _WALL_MARGIN_M
        hi = bin_.inner_hi[:2] - reach - _WALL_MARGIN_M
        lo, hi = np.minimum(lo, centre), np.maximum(hi, centre)  # too big for the bin: its centre at least
        xs = np.arange(lo[0], hi[0] + 1e-9, _SPOT_STEP_M) if hi[0] > lo[0] else np.array([centre[0]])
        ys = np.arange(lo[1], hi[1] + 1e-9, _SPOT_STEP_M) if hi[1] > lo[1] else np.array([centre[1]])
        P = np.column_stack([np.repeat(xs, len(ys)), np.tile(ys, len(xs))])  # x outer, y inner
        overlap = np.zeros(len(P))
        for f in placed:
            d = f.half + reach + _WALL_MARGIN_M - np.abs(P - f.centre)
            overlap += np.maximum(d[:, 0], 0.0) * np.maximum(d[:, 1], 0.0)
        grids.append((yaw, P, overlap))
    least = min(float(o.min()) for _, _, o in grids)
    # the quarter turn only when it packs better: the first turn that reaches the least overlap
    yaw, P, overlap = next(g for g in grids if float(g[2].min()) == least)
    p = _farthest(P[overlap == least], centre)
    return p, yaw, _Footprint(p, _turned(obj_half_tcp, yaw - bin_.yaw))


def _farthest(candidates: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """The first of `candidates` (n, 2) farthest from `centre` (2,) by `np.linalg.norm` of each, as the
    candidate-by-candidate search compared them. Distances taken for all at once may differ from those in
    the last bit, so they only pick the few within a hair of the farthest; those are compared as before."""
    dist = np.sqrt(np.sum((candidates - centre) ** 2, axis=1))
    near = np.flatnonzero(dist >= dist.max() * (1.0 - 1e-9) - 1e-15)
    best, best_key = candidates[near[0]], -float(np.linalg.norm(candidates[near[0]] - centre))
    for i in near[1:]:
        key = -float(np.linalg.norm(candidates[i] - centre))
        if key < best_key:
            best, best_key = candidates[i], key
    return np.array(best)


def _at_pose(cell: Cell, T: np.ndarray, tol_m: float = 1e-3, tol_rad: float = 1e-3) -> bool:
    """Whether the measured tcp is at `T` (4, 4) within `tol_m` and `tol_rad` (joint encoders + FK)."""
    M = cell.kin.fk(cell.world.joint_positions())
    turn = math.acos(float(np.clip((np.trace(M[:3, :3].T @ T[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)))
    return float(np.linalg.norm(M[:3, 3] - T[:3, 3])) <= tol_m and turn <= tol_rad


def _grasp_for(cell: Cell, est: ObjectEstimate, slipped: list[tuple[GraspChoice, float]]) -> GraspChoice:
    """`choose_grasp` for `est`, knowing which of the object's grasps slipped before, with this gripper's
    deepest grasp and most force for a grasp tried again."""
    settings = cell.settings
    max_opening = settings.gripper.max_opening_m
    if not slipped:
        return choose_grasp(est, max_opening)
    z_grasp, w_grip = float(est.grasp[2]), float(est.grasp[6])
    lower = z_grasp - _lowest_tcp(settings, cell.robot, est, z_grasp, min(w_grip, max_opening))
    own = settings.task.robocup.grip_force_n.get(est.cls)  # a class's own force is its most
    return choose_grasp(
        est,
        max_opening,
        slipped=tuple(g for g, _ in slipped),
        lower_max_m=lower,
        force_max_n=own if own is not None else _GRIPPER_MAX_FORCE_N,
    )


def _pick_and_place(
    cell: Cell,
    est: ObjectEstimate,
    bin_: BinGeometry,
    placed: list[_Footprint],
    grasp: GraspChoice | None = None,
    avoid_yaws: tuple[float, ...] = (),
) -> None:
    """Pick `est` with `grasp` (default: `choose_grasp`'s) and place it in `bin_`; StageFailed (GraspSlipped
    when it slipped out of a grasp that held) when a stage fails. `avoid_yaws`: base-frame yaws whose grasps
    slipped, taken last where the object's symmetry offers another."""
    task = cell.settings.task.robocup
    max_opening = cell.settings.gripper.max_opening_m
    if grasp is None:
        grasp = choose_grasp(est, max_opening)
    x, y, z_grasp, yaw, _, _, w_grip = (float(v) for v in est.grasp)
    yaw = yaw + grasp.yaw_offset_rad
    z_grasp -= grasp.lower_m
    yaw = _clear_grasp_yaw(cell, est, (x, y, z_grasp), yaw, avoid=avoid_yaws)
    if grasp.lower_m > 0 or grasp.force_n is not None or grasp.lift_speed < 1.0:
        log.info(
            "robocup: %s gripped again across its %s side (%.0f mm), %.0f mm deeper, at %s, lifted at %.0f %%",
            est.label,
            grasp.side,
            1e3 * grasp.width_m,
            1e3 * grasp.lower_m,
            "the usual force" if grasp.force_n is None else f"{grasp.force_n:.0f} N",
            100 * grasp.lift_speed,
        )
    # (1) base-first alignment
    cell.move_joints("align", _aligned(cell.world.joint_positions(), x, y))
    # (2) pre-grasp hover, gripper opened to the lookup width, in the IK branch whose way down (3) is clear for
    # the whole arm, checked before moving (`Cell.choose_way_down`; none clear: refused here, not in the descent)
    cell.open_gripper(min(w_grip, max_opening))
    way = cell.choose_way_down((x, y, z_grasp), (x, y, z_grasp + task.hover_m), [yaw])
    hover = way.hover
    cell.reach_hover(way)
    # (3) descent
    cell.move_pose("descent", way.target)
    # (4) close and settle: the finger position says whether the object is between the fingers
    w = grasp.width_m
    opened = cell.read_gripper(wait_s=0.0).opening_m
    force = grasp.force_n if grasp.force_n is not None else task.grip_force_n.get(est.cls)
    check = cell.close_gripper((w, w), force_n=force, speed_m_s=task.grip_speed_m_s.get(est.cls))
    if not check.holding:
        raise StageFailed("grasp", f"{check.reason} ({est.label}, {est.orientation})")
    if grasp.tight and check.opening_m > (opened + w) / 2.0:
        # a side in the stroke's last millimetres: fingers that closed less than half the way to its faces
        # (or were pushed wider) stand on its top edge or hold it tilted across its edges; it would slip out
        raise StageFailed(
            "grasp",
            f"the fingers stopped at {1e3 * check.opening_m:.1f} mm from {1e3 * opened:.1f} mm, not on the "
            f"{1e3 * w:.0f} mm faces: a finger came down on its top ({est.label}, {est.orientation})",
        )
    # (5) ascent
    with _lift_speed(cell, grasp.lift_speed):
        cell.move_pose("ascent", hover)
    held = cell.check_holding()
    if not held.holding:
        raise GraspSlipped("ascent", f"the object slipped out of the gripper: {held.reason}", grasp=grasp, yaw=yaw)
    ext = np.array(OBJECT_TEMPLATES[est.cls].extents(est.orientation == "horizontal"))
    short, long_ = sorted((float(ext[0]), float(ext[1])))
    # the fingers close along the tcp's x axis, across the object's short side
    cell.attach(est.cls, np.array([short, long_, ext[2]]), below_tcp_m=z_grasp - ext[2] / 2)
    # what goes below the rims at the release: the object and the parts of the opened gripper that reach
    # that low, as half extents along the tcp's x (the closing direction) and y. The fingers open a little
    # wider than the object (not the sensed opening: pads can sink into a light object), not fully.
    release_w = min(max(check.opening_m, w) + _RELEASE_OPEN_M, max_opening)
    rim_z = bin_.world(bin_.inner_hi)[2]
    floor_z = bin_.world(bin_.inner_lo)[2]
    tcp_z = floor_z + _RELEASE_GAP_M + z_grasp
    obj_half = np.array([short / 2.0, long_ / 2.0])
    reach_half = obj_half.copy()
    for lo, hi in cell.robot.gripper_boxes(release_w):
        if tcp_z - hi[2] < rim_z + _WALL_MARGIN_M:
            reach_half = np.maximum(reach_half, np.maximum(np.abs(lo[:2]), np.abs(hi[:2])))
    yaw_grasp = yaw
    spot, yaw, footprint = _release_spot(bin_, placed, obj_half, reach_half, yaw)
    xy = bin_.world(np.array([spot[0], spot[1], 0.0]))[:2]
    # (6) transfer above the release point, the object's bottom `place_clearance_m` above the rims
    above = top_down((xy[0], xy[1], rim_z + task.place_clearance_m + z_grasp), yaw)
    cell.move_pose("transfer", above)
    held = cell.check_holding()
    if not held.holding:
        raise GraspSlipped(  # physics during the transfer's motion: its planner's
            "transfer",
            f"the object was dropped while carrying it: {held.reason}",
            grasp=grasp,
            yaw=yaw_grasp,
            planner=cell.block("transfer").name,
        )
    # a transfer asks for a position within `transfer_tolerance_m`, orientation free: a planner that stops
    # there (nmpc) leaves the object up to 3 cm off and turned. Lowering it straight from there would cut
    # diagonally past the walls while turning it; the place move first finishes the pose above the rims
    if not _at_pose(cell, above):
        cell.move_pose("place", above)
    # (7) place: lower it into the bin (a tall object dropped from above the walls topples out), release
    release_pose = top_down((xy[0], xy[1], tcp_z), yaw)
    cell.move_pose_turned("place", release_pose)
    cell.release(release_w)
    placed.append(footprint)
    # rise above the rims and make sure the object stayed in the bin: fingers that did not open, or an object
    # the wrist camera sees still between them, is set down on the bin floor again and let go (twin.tasks.jam)
    jam = clear_after_release(
        cell,
        release_pose,
        top_down((xy[0], xy[1], rim_z + task.place_clearance_m + z_grasp), yaw),
        commanded_m=release_w,
        surface_z=floor_z,
        hang_m=z_grasp,
    )
    if jam.jammed:
        raise StageFailed(
            "place", f"the object is stuck between the opened fingers: {jam.reason}", failure="grasp_lost"
        )


def run_robocup(cell: Cell) -> list[ObjectOutcome]:
    """Sort every object on the table into its bin; one outcome per true object, judged at the end."""
    settings, world = cell.settings, cell.world
    task = settings.task.robocup
    referee = RobocupReferee(world, settings, cell.watch)  # ground truth: metrics, verdicts at the end
    bins = bin_geometries(settings)
    detector = make_detector(settings, context=cell.run_context)
    targets: list[_Target] = []
    placed_in: dict[str, list[_Footprint]] = {}  # where the task released what, per bin
    home = np.array(settings.robot.home)
    capture_q = np.array(settings.camera.capture_pose)
    most_seen = 0  # the most objects perception saw on the table in one capture: sizes the budget
    captures = 0
    stopped: str | None = None
    hand_eye = calibrate_hand_eye(cell, _reach_capture_pose)
    cell.calibration = hand_eye.outcome
    fixture_boxes = _fixture_boxes(cell)
    relook_at: np.ndarray | None = None  # where an object whose grasp found the wrong width was seen

    def perceive_from(cap: Capture, T_bc: np.ndarray) -> tuple[ObjectEstimate, ...]:
        return perceive_robocup_scene(world, cap.frame, T_bc, settings, detector, known_boxes=fixture_boxes).objects

    while True:
        budget = min(task.max_captures, (task.retries + 2) * most_seen + 3)
        if captures >= budget:
            stopped = f"the perception budget of {budget} captures was used up"
            log.info("robocup: %s", stopped)
            break
        if world.sim_time > settings.task.max_sim_time_s:
            stopped = "run time limit reached"
            log.info("robocup: %s", stopped)
            break
        cell.current = "scene"
        try:
            _reach_capture_pose(cell, capture_q)
        except StageFailed as e:
            stopped = f"cannot reach the capture pose: {e}"
            log.warning("robocup: %s", stopped)
            break
        cap = capture_frame(world, settings, move=False)
        captures += 1
        T_bc = hand_eye.camera_pose(settings, cap, cell.kin)
        # an oracle detector gets the truth; what stands on the table unexplained becomes an obstacle
        seen = perceive_robocup_scene(world, cap.frame, T_bc, settings, detector, known_boxes=fixture_boxes)
        unknown = [(f"unknown_{i}", lo, hi) for i, (lo, hi) in enumerate(seen.unknown)]
        cell.perceived(cap.frame, T_bc, [(e.label, e.position) for e in seen.objects], unknown)
        most_seen = max(most_seen, sum(not _in_any_bin(e.position, bins) for e in seen.objects))
        est = _choose(seen.objects, targets, bins, task.retries)
        cell.objects_done(*_counts(seen.objects, targets, bins, task.retries))
        if est is None:
            break
        prefetch_next_capture(world, settings)  # there will be another look
        objects = seen.objects
        if relook_at is not None:  # a grasp found the wrong width with an uncalibrated camera: look from above
            est, objects = relook_target(
                cell, hand_eye, est, objects, relook_at, capture_q, _reach_capture_pose, perceive_from
            )
            relook_at = None
        _update_obstacles(cell, objects, est, bins, seen.unknown)
        tgt = _target_for(est, targets)
        tgt.attempts += 1
        tgt.true_ids |= referee.match(est.position)  # metrics only: which true object this was
        cell.current = est.label
        t0 = world.sim_time
        bin_name = bin_for(est.cls, est.color, settings)
        if bin_name not in bins:
            tgt.done, tgt.error, tgt.failure = True, f"bin: no bin named {bin_name!r} among the fixtures", "error"
            continue
        try:
            grasp = _grasp_for(cell, est, tgt.slipped)
            avoid = tuple(yaw for _, yaw in tgt.slipped)
            _pick_and_place(cell, est, bins[bin_name], placed_in.setdefault(bin_name, []), grasp, avoid)
            tgt.done = True
            clear_failure(tgt)
        except StageFailed as e:
            if isinstance(e, GraspSlipped):  # the next attempt grips it otherwise (`choose_grasp`)
                tgt.slipped.append((e.grasp, e.yaw))
            note_failure(tgt, e, tgt.attempts)
            log.info("robocup: %s attempt %d failed: %s", est.label, tgt.attempts, e)
            _clear_seen(cell)  # the failure may have moved them: the next capture says where they are
            cell.recover()
            if hand_eye.uncalibrated and e.stage == "grasp":
                relook_at = est.position[:2].copy()
        tgt.cycle_time_s += world.sim_time - t0
        cell.objects_done(*_counts(seen.objects, targets, bins, task.retries))
        try:
            cell.move_joints_over("home", home)
        except StageFailed as e:
            log.info("robocup: could not return home: %s", e)
    cell.settle(1.0)
    return referee.outcomes(targets, stopped=stopped)


def _reach_capture_pose(cell: Cell, q: np.ndarray) -> None:
    """Move to the capture pose; when the move is stopped on the way (an object still stuck to a finger
    touches something), let go, rise and try once more before the run gives up."""
    try:
        cell.move_joints_over("capture", q)
    except StageFailed as e:
        log.info("robocup: capture move failed (%s); recovering and trying again", e)
        _clear_seen(cell)
        cell.recover()
        cell.move_joints_over("capture", q)


def _fixture_boxes(cell: Cell) -> list[tuple[np.ndarray, np.ndarray]]:
    """(lo, hi) around each fixture of the planning scene (the bins with their insides): what perception
    need not explain."""
    out = []
    for shapes in cell.scene.environment_shapes().values():
        boxes = [(T, np.asarray(dims, dtype=float)) for kind, dims, T in shapes if kind == "box"]
        if not boxes:
            continue
        corners = [T[:3, 3] + s * (np.abs(T[:3, :3]) @ (dims / 2.0)) for T, dims in boxes for s in (-1.0, 1.0)]
        out.append((np.min(corners, axis=0), np.max(corners, axis=0)))
    return out


def _update_obstacles(
    cell: Cell,
    estimates: tuple[ObjectEstimate, ...],
    target: ObjectEstimate,
    bins: dict[str, BinGeometry],
    unknown: tuple[tuple[np.ndarray, np.ndarray], ...] = (),
) -> None:
    """Every other perceived object on the table becomes a box in the planning scene (the target is left
    out: the fingers close around it), and so does everything perception saw there but could not name
    (grown by `_UNKNOWN_PAD_M`)."""
    _clear_seen(cell)
    for i, (lo, hi) in enumerate(unknown):
        cell.scene.add_box_bounds(f"seen_unknown_{i}", lo - _UNKNOWN_PAD_M, hi + _UNKNOWN_PAD_M)
    for i, est in enumerate(estimates):
        if est is target or _in_any_bin(est.position, bins):
            continue
        ext = np.array(OBJECT_TEMPLATES[est.cls].extents(est.orientation == "horizontal"))
        short, long_ = sorted((float(ext[0]), float(ext[1])))
        # the grasp yaw closes across the short side (cubes: across a face, 45 deg off the seed's yaw)
        yaw = est.yaw - math.pi / 4 if est.cls == "cube" else est.yaw
        T = np.eye(4)
        T[:3, :3] = np.array(
            [[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]]
        )
        T[:3, 3] = [est.position[0], est.position[1], ext[2] / 2 + 0.002]
        cell.scene.add_box(f"seen_{i}_{est.label}", np.array([short, long_, ext[2]]), T)


def _clear_seen(cell: Cell) -> None:
    """Remove the perceived objects' boxes from the planning scene."""
    for name in [n for n in cell.scene.boxes() if n.startswith("seen_")]:
        cell.scene.remove(name)


def _choose(
    estimates: tuple[ObjectEstimate, ...], targets: list[_Target], bins: dict[str, BinGeometry], retries: int
) -> ObjectEstimate | None:
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


def _counts(
    estimates: tuple[ObjectEstimate, ...], targets: list[_Target], bins: dict[str, BinGeometry], retries: int
) -> tuple[int, int]:
    """(objects done with: placed or given up on, those and the ones on the table still to do), for the
    progress display: what the task knows after a capture, not the truth."""
    finished = sum(t.done or t.attempts > retries for t in targets)
    to_do = 0
    for est in estimates:
        t = _find(est, targets)
        to_do += not _in_any_bin(est.position, bins) and (t is None or not (t.done or t.attempts > retries))
    return finished, finished + to_do


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


class RobocupTask:
    """The RoboCup ARM sorting task as a task plugin (name `robocup`). Its settings are the config's
    `task.robocup` and `perception.robocup` sections (models in `twin.config.robocup`)."""

    def __init__(self, params: None, context: PluginContext) -> None:
        self.context = context

    def run(self, cell: Cell) -> list[ObjectOutcome]:
        return run_robocup(cell)
