"""Judging and metrics of task runs: the one module of twin.tasks that reads the simulator's ground truth.

A real cell knows only what it senses (joint encoders, the gripper's finger position, camera frames), so
the tasks decide with those alone. What only the simulator knows lives here, in three roles:

- **Judging**: was an object placed? The rule is strict. In a bin: after settling, at rest and wholly
  inside the bin's inner volume (between the inner wall faces, above the floor, its bottom below the
  rim's top), from the object's true pose and exact geometry. In a warehouse drop zone: at rest on the
  table (its bottom within a few mm of the table top) with its centre inside the zone.
- **Metrics**: which true object an estimate was (pose error, per-object cycle time).
- **Simulator plumbing** that must not feed a task's decisions: the body between the fingers for the
  simulated contact monitor, and the ground truth handed to a detector labelled ORACLE.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from twin.perception.detection import needs_ground_truth, with_ground_truth
from twin.scene_layout import OBJECT_TEMPLATES
from twin.types import ObjectOutcome, quat_to_matrix

if TYPE_CHECKING:
    from twin.camera import RGBDFrame
    from twin.config import Settings
    from twin.perception.detection import Detector
    from twin.tasks.robocup import BinGeometry
    from twin.tasks.robocup.perception import RobocupResult
    from twin.world import ObjectState, World

__all__ = [
    "CONTACT_SLOP_M",
    "MATCH_RADIUS_M",
    "REST_ANGULAR_RAD_S",
    "REST_LINEAR_M_S",
    "SETTLE_MAX_S",
    "TABLE_REST_TOL_M",
    "RobocupReferee",
    "Verdict",
    "WarehouseReferee",
    "bin_verdict",
    "body_between_fingers",
    "judge_in_bin",
    "judge_in_zone",
    "object_bounds",
    "oracle_ground_truth",
    "perceive_robocup_scene",
    "settle_until_rest",
    "zone_verdict",
]

# At rest: a settled object in PyBullet moves at ~1e-4 m/s; anything still sliding, rolling or toppling
# after the run's settling pause is well above these.
REST_LINEAR_M_S = 0.01
REST_ANGULAR_RAD_S = 0.1
# Resting geometry sinks this far into what it touches (PyBullet's contact slop is ~1 mm), so an object
# pressed against an inner wall or lying on the floor is still inside.
CONTACT_SLOP_M = 0.002
# The judge lets objects come to rest for at most this long after a run (a rolling can stops at a wall).
SETTLE_MAX_S = 5.0
# Warehouse: "on the table" when the object's lowest point is within this of the table top; an object on
# another one is a cube height (50 mm) higher.
TABLE_REST_TOL_M = 0.005
# An estimate is of the true object whose centre is this close in xy (objects are >= 21 mm across and
# spawn >= 30 mm apart; perception errors are ~20 mm).
MATCH_RADIUS_M = 0.05


@dataclass(frozen=True)
class Verdict:
    """Is the object where it should be; `reason` says why not ("" when placed)."""

    placed: bool
    reason: str = ""


def object_bounds(state: ObjectState, T_frame_world: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(lo (3,), hi (3,)): exact axis-aligned bounds of an object's true geometry in a frame (default the
    world), `T_frame_world` (4, 4) mapping world points into it. Boxes from their oriented extents (the 8
    corners), cylinders exactly (axis half-length and radius projected on each axis)."""
    T = np.eye(4) if T_frame_world is None else np.asarray(T_frame_world, dtype=float)
    R_obj = quat_to_matrix(state.orientation_xyzw)
    R = T[:3, :3] @ R_obj  # object axes in the frame
    centre = T[:3, :3] @ np.asarray(state.position, dtype=float) + T[:3, 3]
    size = np.asarray(state.size, dtype=float)
    if OBJECT_TEMPLATES[state.cls].shape == "cylinder":
        r, h = size[0] / 2.0, size[2] / 2.0
        a = np.abs(R[:, 2])  # the axis, per frame axis
        half = a * h + r * np.sqrt(np.clip(1.0 - a * a, 0.0, 1.0))
    else:
        half = np.abs(R) @ (size / 2.0)
    return centre - half, centre + half


def _moving(velocity: tuple[np.ndarray, np.ndarray]) -> str:
    lin, ang = (float(np.linalg.norm(v)) for v in velocity)
    if lin > REST_LINEAR_M_S or ang > REST_ANGULAR_RAD_S:
        return f"it is still moving ({lin:.3f} m/s, {ang:.2f} rad/s)"
    return ""


def bin_verdict(state: ObjectState, velocity: tuple[np.ndarray, np.ndarray], bin_: BinGeometry) -> Verdict:
    """Placed in `bin_`: at rest (`velocity`: linear, angular) and its whole geometry inside the inner
    volume: between the inner wall faces, not below the floor's top, its bottom below the rim's top (a tall
    object standing on the floor may rise above the rim; one lying on the rim may not)."""
    moving = _moving(velocity)
    if moving:
        return Verdict(False, moving)
    lo, hi = object_bounds(state, np.linalg.inv(bin_.pose))
    ilo, ihi, olo, ohi = bin_.inner_lo, bin_.inner_hi, bin_.outer_lo, bin_.outer_hi
    overlaps = bool(np.all(hi[:2] > olo[:2]) and np.all(lo[:2] < ohi[:2]))
    if not overlaps:
        return Verdict(False, f"it is outside {bin_.name}")
    if lo[2] < ilo[2] - CONTACT_SLOP_M:  # lower than the floor's top: it stands outside, over the bin's edge
        return Verdict(False, f"it is outside {bin_.name}, leaning on or reaching over its wall")
    over = float(max(ilo[0] - lo[0], hi[0] - ihi[0], ilo[1] - lo[1], hi[1] - ihi[1]))
    if lo[2] >= ihi[2] - CONTACT_SLOP_M:
        where = "on the rim of" if over > CONTACT_SLOP_M else "above the rim of"
        d = float(lo[2] - ihi[2])
        level = "level with the rim's top" if abs(d) < CONTACT_SLOP_M else f"{1000 * d:.0f} mm above the rim's top"
        return Verdict(False, f"it rests {where} {bin_.name} (its bottom {level})")
    if over > CONTACT_SLOP_M:
        return Verdict(False, f"it sticks {1000 * over:.0f} mm out over the inner walls of {bin_.name}")
    return Verdict(True)


def zone_verdict(
    state: ObjectState, velocity: tuple[np.ndarray, np.ndarray], zone: Sequence[float], radius_m: float
) -> Verdict:
    """Placed in a drop zone (x, y, table-top z): at rest, its bottom within TABLE_REST_TOL_M of the table
    top (not on another object), its centre within `radius_m` of the zone's centre in xy."""
    moving = _moving(velocity)
    if moving:
        return Verdict(False, moving)
    lo, _ = object_bounds(state)
    above = float(lo[2] - zone[2])
    if above > TABLE_REST_TOL_M:
        return Verdict(
            False, f"it does not rest on the table (its bottom is {1000 * above:.0f} mm above it, on something)"
        )
    d = float(np.linalg.norm(np.asarray(state.position[:2]) - np.asarray(zone[:2], dtype=float)))
    if d > radius_m:
        return Verdict(False, f"it rests {100 * d:.1f} cm from its drop zone's centre (radius {100 * radius_m:.0f} cm)")
    return Verdict(True)


def judge_in_bin(world: World, body_id: int, bin_: BinGeometry) -> Verdict:
    """`bin_verdict` of one object of `world`, from its ground-truth pose and velocity now."""
    return bin_verdict(world.object_state(body_id), world.object_velocity(body_id), bin_)


def judge_in_zone(world: World, body_id: int, zone: Sequence[float], radius_m: float) -> Verdict:
    """`zone_verdict` of one object of `world`, from its ground-truth pose and velocity now."""
    return zone_verdict(world.object_state(body_id), world.object_velocity(body_id), zone, radius_m)


def settle_until_rest(world: World, *, max_s: float = SETTLE_MAX_S) -> None:
    """Step the physics until every object is at rest, at most `max_s`: objects are judged where they
    come to rest, not while a can still rolls across a bin's floor."""
    chunk = max(1, round(0.1 / world.dt))
    for _ in range(max(1, round(max_s / (chunk * world.dt)))):
        if not any(_moving(world.object_velocity(i)) for i in world.object_ids()):
            return
        world.step(chunk)


def _nearest(truth: Iterable[ObjectState], xy: np.ndarray) -> int | None:
    best = min(((float(np.linalg.norm(o.position[:2] - xy[:2])), o.id) for o in truth), default=(math.inf, -1))
    return best[1] if best[0] < MATCH_RADIUS_M else None


# ---- RoboCup --------------------------------------------------------------------------------------
class RobocupTarget(Protocol):
    """What the RoboCup task records about one object it worked on (twin.tasks.robocup._Target)."""

    error: str | None
    failure: str | None
    stage: str | None
    planner: str | None
    done: bool
    cycle_time_s: float
    first_estimate: np.ndarray | None
    true_ids: set[int]


@dataclass(frozen=True)
class Displacement:
    """A loose object the gripper did not hold moved `distance_m` during one motion (`stage`, `planner`);
    `after_release`: the gripper had held it before (it had been placed, or let go)."""

    object_id: int
    stage: str
    planner: str
    distance_m: float
    after_release: bool


class DisplacementWatch:
    """Judging only (ground truth, never read by a task): which motion moved which loose object it did not
    hold. An object placed and then knocked out of its bin or zone by a later motion (a held object swinging
    into it, a path through where it stands) is lost to that motion, whichever stage carried it; the
    referees say so (`Referee.outcomes`). `Cell.move` calls `before` and `after` around every motion."""

    MIN_M = 0.01  # a move of less than this is settling, not a knock

    def __init__(self, world: World) -> None:
        self.world = world
        self.events: list[Displacement] = []
        self._before: dict[int, np.ndarray] = {}
        self._held_once: set[int] = set()

    def before(self) -> None:
        self._before = {o.id: o.position.copy() for o in self.world.objects()}

    def after(self, stage: str, planner: str, held: int | None) -> None:
        if held is not None:
            self._held_once.add(held)
        for o in self.world.objects():
            p0 = self._before.get(o.id)
            if o.id == held or p0 is None:
                continue
            d = float(np.linalg.norm(o.position - p0))
            if d > self.MIN_M:
                self.events.append(Displacement(o.id, stage, planner, d, o.id in self._held_once))

    def knocked(self, object_id: int) -> Displacement | None:
        """The last motion that moved the object after the gripper had let go of it, if any."""
        hits = [e for e in self.events if e.object_id == object_id and e.after_release]
        return hits[-1] if hits else None


def _knocked_error(knock: Displacement, verdict_reason: str) -> str:
    return (
        f"{knock.stage}: {knock.planner}: the motion moved it {100 * knock.distance_m:.0f} cm after it was "
        f"let go; {verdict_reason}"
    )


class RobocupReferee:
    """Ground truth of one RoboCup run: the true objects at the start, which of them each estimate was
    (metrics), and the verdict on each at the end. The task hands it its records; it never answers a
    question the task could act on."""

    def __init__(self, world: World, settings: Settings, watch: DisplacementWatch | None = None) -> None:
        from twin.tasks.robocup import bin_geometries  # the task's rules: which bin, what a bin looks like

        self.world = world
        self.settings = settings
        self.watch = watch
        self.truth = {o.id: o for o in world.objects()}
        self.bins = bin_geometries(settings)

    def match(self, position: np.ndarray) -> set[int]:
        """Metrics: the true object an estimate at `position` (3,) was, as a set of none or one id."""
        oid = _nearest(self.world.objects(), np.asarray(position, dtype=float))
        return set() if oid is None else {oid}

    def outcomes(self, targets: Sequence[RobocupTarget], *, stopped: str | None = None) -> list[ObjectOutcome]:
        """One outcome per true object; errors read "<stage>: <why>". `stopped`: why the run ended early."""
        from twin.tasks.robocup import bin_for

        settle_until_rest(self.world)
        out = []
        for oid, o0 in self.truth.items():
            bin_name = bin_for(o0.cls, o0.color, self.settings)
            mine = [t for t in targets if oid in t.true_ids]
            bin_ = self.bins.get(bin_name)
            verdict = (
                judge_in_bin(self.world, oid, bin_)
                if bin_ is not None
                else Verdict(False, f"there is no fixture {bin_name!r}")
            )
            failure = stage = planner = None
            if verdict.placed:
                err = None
            elif not mine:
                err = "perception: never seen on the table" + (f" (the run stopped: {stopped})" if stopped else "")
            elif mine[-1].error or (not mine[-1].done and any(t.error for t in mine)):
                # seen again elsewhere after a failure (dropped, knocked), the object is a new target to the
                # task; its first failure is still the object's, the later targets' are added to the text
                failed = [t for t in mine if t.error]
                origin = failed[0]
                err, failure, stage, planner = origin.error, origin.failure, origin.stage, origin.planner
                err = "; then: ".join([str(err), *(str(t.error) for t in failed[1:])])
            elif mine[-1].done and (knock := self.watch and self.watch.knocked(oid)):
                err = _knocked_error(knock, f"{verdict.reason}{self._elsewhere(oid, bin_name)}")
                failure, stage, planner = "execution_contact", knock.stage, knock.planner
            elif mine[-1].done:
                err = f"place: released, but {verdict.reason}{self._elsewhere(oid, bin_name)}"
            else:
                err = "task: attempted, but neither placed nor failed" + (
                    f" (the run stopped: {stopped})" if stopped else ""
                )
            first = mine[0].first_estimate if mine else None
            out.append(
                ObjectOutcome(
                    id=o0.name,
                    cls=o0.cls,
                    color=o0.color,
                    target_bin=bin_name,
                    placed=verdict.placed,
                    error=err,
                    failure=failure,
                    stage=stage or _stage_of(err),
                    planner=planner,
                    cycle_time_s=sum(t.cycle_time_s for t in mine),
                    pose_error_m=float(np.linalg.norm(first[:2] - o0.position[:2])) if first is not None else None,
                )
            )
        return out

    def _elsewhere(self, oid: int, target: str) -> str:
        for name, b in self.bins.items():
            if name != target and judge_in_bin(self.world, oid, b).placed:
                return f" (it is in {name})"
        return ""


# ---- warehouse ------------------------------------------------------------------------------------
class WarehouseAttempt(Protocol):
    """What the warehouse task records about one cube it worked on (twin.tasks.warehouse._Attempt)."""

    cube: Any  # twin.perception.warehouse.LabeledCube
    true_id: int | None
    error: str | None
    failure: str | None
    stage: str | None
    planner: str | None
    cycle_time_s: float


class WarehouseReferee:
    """Ground truth of one warehouse run: the true cubes at the start, which one each perceived cube was,
    and the verdict on each at the end."""

    def __init__(self, world: World, settings: Settings, watch: DisplacementWatch | None = None) -> None:
        self.world = world
        self.settings = settings
        self.watch = watch
        self.truth = {o.id: o for o in world.objects()}

    def match(self, centroid: np.ndarray) -> int | None:
        """Metrics: the true cube a perceived centroid (3,) was, or None."""
        return _nearest(self.truth.values(), np.asarray(centroid, dtype=float))

    def outcomes(self, attempts: Sequence[WarehouseAttempt]) -> list[ObjectOutcome]:
        """One outcome per true cube; errors read "<stage>: <why>"."""
        task = self.settings.task.warehouse
        settle_until_rest(self.world)
        by_true = {a.true_id: a for a in attempts if a.true_id is not None}
        out = []
        for oid, o0 in self.truth.items():
            zone = task.drop_zones.get(o0.color or "")
            verdict = (
                judge_in_zone(self.world, oid, zone, task.drop_radius_m)
                if zone is not None
                else Verdict(False, "no drop zone")
            )
            att = by_true.get(oid)
            failure = stage = planner = None
            if verdict.placed:
                err = None
            elif att is None:
                err = "perception: never seen on the table"
            elif att.error:
                err, failure, stage, planner = att.error, att.failure, att.stage, att.planner
            elif knock := self.watch and self.watch.knocked(oid):
                err = _knocked_error(knock, verdict.reason)
                failure, stage, planner = "execution_contact", knock.stage, knock.planner
            else:
                err = f"place: released, but {verdict.reason}"
            out.append(
                ObjectOutcome(
                    id=o0.name,
                    cls=o0.cls,
                    color=o0.color,
                    target_bin=f"drop_{o0.color}",
                    placed=verdict.placed,
                    error=err,
                    failure=failure,
                    stage=stage or _stage_of(err),
                    planner=planner,
                    cycle_time_s=att.cycle_time_s if att else 0.0,
                    pose_error_m=float(np.linalg.norm(att.cube.centroid[:2] - o0.position[:2])) if att else None,
                )
            )
        return out


def _stage_of(error: str | None) -> str | None:
    """The stage an outcome's error names ("<stage>: <why>"), for an error no failed stage gave."""
    if not error:
        return None
    head, sep, _ = error.partition(":")
    return head if sep and head and " " not in head else None


# ---- simulator plumbing (never a task's decision) -----------------------------------------------
def body_between_fingers(world: World) -> int | None:
    """The simulator body both fingers touch, or None. It feeds the simulated contact monitor (the executor
    ignores contacts with the held object); tasks decide "holding" from the finger position alone."""
    return world.grasped_object()


def oracle_ground_truth(world: World, detector: object) -> list[ObjectState] | None:
    """ORACLE: the simulator's true objects for a detector that declares `needs_ground_truth` (the labelled
    `oracle` detector); None for every real detector."""
    return world.objects() if needs_ground_truth(detector) else None


def perceive_robocup_scene(
    world: World,
    frame: RGBDFrame,
    T_base_camera: np.ndarray,
    settings: Settings,
    detector: Detector,
    *,
    known_boxes: list[tuple[np.ndarray, np.ndarray]] | None = None,
) -> RobocupResult:
    """The RoboCup perception of one frame (`twin.tasks.robocup.perception.perceive_robocup`), with the ORACLE
    hand-off: only a detector labelled as needing ground truth is given the simulator's objects."""
    from twin.tasks.robocup.perception import perceive_robocup

    fed = with_ground_truth(detector, oracle_ground_truth(world, detector))
    return perceive_robocup(frame, T_base_camera, settings, fed, seed=world.seed, known_boxes=known_boxes)
