"""Judging and metrics of task runs: what reads the simulator's ground truth, here and in each task's referee.

A real cell knows only what it senses (joint encoders, the gripper's finger position, camera frames), so
the tasks decide with those alone. What only the simulator knows lives here (and, per task, in its
referee), in four roles:

- **Judging**: was an object placed? The rule is strict. In a bin: after settling, at rest and wholly
  inside the bin's inner volume (between the inner wall faces, above the floor, its bottom below the
  rim's top), from the object's true pose and exact geometry. In a warehouse drop zone: at rest on the
  table (its bottom within a few mm of the table top) with its centre inside the zone.
- **Metrics**: which true object an estimate was (pose error, per-object cycle time).
- **Referees**: what every task's referee shares (`Referee`, the displacements each motion caused); each
  task's own referee lives in its package (`twin.tasks.robocup.judge`, `twin.tasks.warehouse.judge`).
- **Simulator plumbing** that must not feed a task's decisions: the body between the fingers for the
  simulated contact monitor, and the ground truth handed to a detector labelled ORACLE.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from twin.perception.detection import needs_ground_truth
from twin.scene_layout import OBJECT_TEMPLATES
from twin.types import quat_to_matrix

if TYPE_CHECKING:
    from twin.config import Settings
    from twin.tasks.robocup.bins import BinGeometry
    from twin.world import ObjectState, World

__all__ = [
    "CONTACT_SLOP_M",
    "MATCH_RADIUS_M",
    "REST_ANGULAR_RAD_S",
    "REST_LINEAR_M_S",
    "SETTLE_MAX_S",
    "TABLE_REST_TOL_M",
    "Displacement",
    "DisplacementWatch",
    "Referee",
    "Verdict",
    "bin_verdict",
    "body_between_fingers",
    "judge_in_bin",
    "judge_in_zone",
    "knocked_error",
    "nearest_object",
    "object_bounds",
    "oracle_ground_truth",
    "settle_until_rest",
    "stage_of",
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


def nearest_object(truth: Iterable[ObjectState], xy: np.ndarray) -> int | None:
    best = min(((float(np.linalg.norm(o.position[:2] - xy[:2])), o.id) for o in truth), default=(math.inf, -1))
    return best[1] if best[0] < MATCH_RADIUS_M else None


# ---- what every referee shares ------------------------------------------------------------------
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


def knocked_error(knock: Displacement, verdict_reason: str) -> str:
    return (
        f"{knock.stage}: {knock.planner}: the motion moved it {100 * knock.distance_m:.0f} cm after it was "
        f"let go; {verdict_reason}"
    )


def stage_of(error: str | None) -> str | None:
    """The stage an outcome's error names ("<stage>: <why>"), for an error no failed stage gave."""
    if not error:
        return None
    head, sep, _ = error.partition(":")
    return head if sep and head and " " not in head else None


class Referee:
    """Ground truth of one run, the part every task's referee shares: the world, the settings, the true
    objects at the start (`truth`, by body id) and the motions' displacements (`watch`, `Cell.watch`). A task's
    referee (`twin.tasks.robocup.judge`, `twin.tasks.warehouse.judge`) adds its matching and verdicts; the
    task hands it its records, and it never answers a question the task could act on."""

    def __init__(self, world: World, settings: Settings, watch: DisplacementWatch | None = None) -> None:
        self.world = world
        self.settings = settings
        self.watch = watch
        self.truth = {o.id: o for o in world.objects()}


# ---- simulator plumbing (never a task's decision) -----------------------------------------------
def body_between_fingers(world: World) -> int | None:
    """The simulator body both fingers touch, or None. It feeds the simulated contact monitor (the executor
    ignores contacts with the held object); tasks decide "holding" from the finger position alone."""
    return world.grasped_object()


def oracle_ground_truth(world: World, detector: object) -> list[ObjectState] | None:
    """ORACLE: the simulator's true objects for a detector that declares `needs_ground_truth` (the labelled
    `oracle` detector); None for every real detector."""
    return world.objects() if needs_ground_truth(detector) else None
