"""The planning scene: the robot, the static cell, perceived obstacle boxes and an object held in the
gripper, and the collision, distance and clearance queries planners make against them.

Why this shape: planners call the collision check millions of times, so everything is built once and a
query only moves the robot's shapes. Link poses come from a compiled, vectorised URDF chain (numpy); the
shapes are moved with `setRotation/setTranslation` on persistent FCL objects; then
* robot vs environment: one manager-vs-manager call of FCL's DynamicAABBTree broadphase (moving robot
  shapes + held object vs fixtures + boxes);
* self-collision: the allowed shape pairs (`twin.collision.rules`) are prefiltered with bounding spheres
  in one numpy step and the few survivors (~3 per configuration) go to FCL's narrow phase directly. For
  distances the pairs are visited in order of their sphere lower bound and the walk stops once the bound
  exceeds the best distance found; that best distance then bounds the environment broadphase.
Links rigidly fixed to the world (base_link) are never tested against the environment: their pose
cannot change, and base_link stands on the table.

Padding: `padding_m` inflates every environment shape (fixtures and boxes) on each side; the robot, the
held object and self-collision are unpadded. Distances to the environment are therefore reduced by the
padding (exactly on faces, conservatively near box edges). Distances are signed: < 0 is a penetration.
`padded(extra_m)` copies a scene with more padding without reading any URDF again.

The parts: `twin.collision.robot_body.RobotBody` (the robot set up from its model: compiled chain, shapes,
gripper opening, held box, allowed self pairs, sphere model; posed at q) and
`twin.collision.obstacles.Obstacles` (fixtures and boxes); `PlanningScene` holds one of each and answers the
queries over both.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import fcl
import numpy as np
from numpy.typing import ArrayLike

from twin.collision.fcl_shapes import DISTANCE_REQUEST as _DREQ
from twin.collision.fcl_shapes import FAR as _FAR
from twin.collision.fcl_shapes import CollideFlag as _CollideFlag
from twin.collision.fcl_shapes import DistanceAccumulator as _DistAcc
from twin.collision.fcl_shapes import collide_callback as _collide_cb
from twin.collision.fcl_shapes import distance_callback as _distance_cb
from twin.collision.obstacles import Obstacles, box_from_bounds, check_pose, check_size
from twin.collision.planning_model import SphereModel
from twin.collision.robot_body import RobotBody
from twin.errors import InvalidRequestError
from twin.robot import Robot
from twin.robot.urdf_model import RobotModel, pose_from_xyz_rpy, read_fixture_shapes
from twin.timing import stage
from twin.types import BoxBounds

if TYPE_CHECKING:
    from twin.config import Settings

__all__ = ["DistanceResult", "FixtureSpec", "PathCheck", "PlanningScene", "UnknownFixtures"]

# how a scene holds the fixtures marked `known: false`: as boxes at their true poses (what a perfect detector
# reports), or not at all (a task's cell, which perceives them)
UnknownFixtures = Literal["box", "ignore"]
# `min_clearance` skips a configuration only when its sphere bound exceeds the smallest clearance measured by
# this much: FCL's distances are exact to far less, so a skipped one is never the minimum
_BOUND_SLACK_M = 1e-4


@dataclass(frozen=True)
class DistanceResult:
    """Smallest signed distance between the robot (incl. the held object) and anything it may hit.

    distance: metres, < 0 = penetration depth of a colliding pair (not necessarily the deepest).
    robot_part: robot link (or held object) name; other: environment object or robot link name.
    self_collision: the pair is robot-robot. Names are '' when nothing can be measured.
    """

    distance: float
    robot_part: str
    other: str
    self_collision: bool = False

    @property
    def in_collision(self) -> bool:
        return self.distance <= 0.0


@dataclass(frozen=True, eq=False)
class PathCheck:
    """Result of `check_path`: `segment` i means the collision lies between qs[i] and qs[i+1] (or at
    qs[0] for i = 0); `q` is the first colliding interpolated configuration."""

    free: bool
    segment: int | None = None
    q: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class FixtureSpec:
    """A static body: name, URDF path and (4, 4) pose in the world (= robot base) frame."""

    name: str
    urdf: str | Path
    pose: np.ndarray


class PlanningScene:
    """Collision and distance queries for the arm in its cell.

    `q`: (6,) joint angles, rad (shoulder_pan .. wrist_3); `qs`: (n, 6). Poses are (4, 4) in the
    world = robot base frame, sizes in metres. Build with `PlanningScene.from_settings(settings)`.
    Not thread-safe: a query moves the scene's shared FCL objects (use one scene per thread/process).
    """

    def __init__(
        self,
        robot_urdf: str | Path | RobotModel | Robot,
        *,
        fixtures: Sequence[FixtureSpec] = (),
        padding_m: float = 0.0,
        reference_configs: Iterable[Sequence[float]] = (),
        extra_excluded_pairs: Iterable[tuple[str, str]] = (),
        finger_opening_m: float | None = None,
        tcp_link: str = "tcp",
        sphere_filter: bool = True,
    ):
        padding = _check_padding(padding_m)
        if isinstance(robot_urdf, Robot):  # the run's robot: its model and sphere cover, made once
            model, covers = robot_urdf.model, robot_urdf.sphere_cover
        else:
            model = robot_urdf if isinstance(robot_urdf, RobotModel) else RobotModel.from_urdf(robot_urdf)
            covers = None
        body = RobotBody.from_model(
            model,
            covers=covers,
            tcp_link=tcp_link,
            finger_opening_m=finger_opening_m,
            reference_configs=reference_configs,
            extra_excluded_pairs=extra_excluded_pairs,
        )
        obstacles = Obstacles(padding)
        for fx in fixtures:
            obstacles.add_fixture(fx.name, fx.urdf, fx.pose)
        obstacles.manager.setup()
        self._assemble(body, obstacles, sphere_filter=sphere_filter)
        if self.sphere_filter:  # load (or, the first time on a machine, compile) the sphere kernel now, not
            with stage("imports"):  # inside a planner's time limit
                self._flags(np.zeros((1, 6)))

    def _assemble(self, body: RobotBody, obstacles: Obstacles, *, sphere_filter: bool) -> None:
        """The scene over a robot body and an environment (each with FCL objects of its own)."""
        self._body = body
        self._obstacles = obstacles
        self.sphere_filter = bool(sphere_filter)
        self._warm: tuple[object, object, tuple[str, str]] | None = None  # last closest robot/env objects
        self._scratch = fcl.DistanceResult()  # reused: a fresh one costs as much as the distance itself

    def padded(self, extra_m: float) -> PlanningScene:
        """A copy of this scene whose environment (fixtures and boxes) is inflated by `extra_m` more on
        each side (`padding_m` becomes `padding_m + extra_m`); robot, exclusions, held object and gripper
        opening are the same. The original is not changed; `padded(0.0)` is an equal copy.

        Much cheaper than building a scene again: the parsed robot model, the self-collision exclusions and
        the fixtures' shapes are reused, only the FCL objects are new (a query moves them, so two scenes
        cannot share them). A negative `extra_m` shrinks the padding, down to 0.
        """
        extra = float(extra_m)
        if not math.isfinite(extra):
            raise InvalidRequestError(f"extra_m must be finite, got {extra_m}")
        padding = _check_padding(self.padding_m + extra)
        new = type(self).__new__(type(self))
        new._assemble(self._body.copy(), self._obstacles.copy(padding), sphere_filter=self.sphere_filter)
        return new

    @classmethod
    def from_settings(
        cls, settings: Settings, *, robot: Robot | None = None, unknown_fixtures: UnknownFixtures = "box"
    ) -> PlanningScene:
        """The cell of a config: the robot (`robot`, the run's, built once; None builds it from
        settings.robot: its URDF model in the arm's base frame, with the arm's TCP where the URDF has no tcp
        link, checked against the arm; gripper fully open), fixtures from settings.world.fixtures, padding from
        settings.collision.padding_m, the sphere filter from settings.collision.sphere_filter; the home
        posture is an exclusion reference.

        Fixtures marked `known: false` (obstacles the robot has to perceive) are, with `unknown_fixtures="box"`
        (the default), in the scene as a perfect detector reports them: boxes at their true poses
        (`add_unknown_fixtures`). That is the cell `twin plan`, `twin compare`, problem-set export and the
        planner contract plan in, so one query gets one answer everywhere. A task perceives them instead:
        its cell asks for `unknown_fixtures="ignore"` and adds what perception found with `add_box_bounds`.
        """
        _check_unknown_fixtures(unknown_fixtures)
        robot = robot if robot is not None else Robot.from_settings(settings)
        fixtures = [
            FixtureSpec(f.name, settings.resolve(f.urdf), pose_from_xyz_rpy(f.position, f.rpy))
            for f in settings.world.fixtures
            if f.known
        ]
        scene = cls(
            robot,
            fixtures=fixtures,
            padding_m=settings.collision.padding_m,
            reference_configs=[settings.robot.home],
            sphere_filter=settings.collision.sphere_filter,
        )
        if unknown_fixtures == "box":
            scene.add_unknown_fixtures(settings)
        return scene

    # ---- the robot's set-up, read through ------------------------------------------------------
    @property
    def model(self) -> RobotModel:
        """The parsed robot model the collision body was built from."""
        return self._body.model

    @property
    def tcp_link(self) -> str:
        """Name of the tcp link (a held object moves with it)."""
        return self._body.tcp_link

    @property
    def max_opening_m(self) -> float:
        """Largest total finger opening of the collision model, m."""
        return self._body.max_opening_m

    @property
    def excluded_pairs(self) -> frozenset[tuple[str, str]]:
        """Robot link pairs never tested against each other (`twin.collision.rules`)."""
        return self._body.excluded_pairs

    @property
    def padding_m(self) -> float:
        """How much every environment shape is inflated on each side, m."""
        return self._obstacles.padding_m

    # =============================================================================================
    # queries
    # =============================================================================================
    def _collides_now(self) -> bool:
        body = self._body
        if self._obstacles.objects:
            flag = _CollideFlag()
            body.moving_manager.collide(self._obstacles.manager, flag, _collide_cb)
            if flag.hit:
                return True
        return body.self_collides()

    def _distance_now(self, include_self: bool = True) -> DistanceResult:
        body, env = self._body, self._obstacles
        best, pair, is_self = _FAR, ("", ""), False
        if include_self and len(body.pa):
            best, self_pair = body.self_distance(self._scratch)
            if self_pair is not None:
                pair, is_self = self_pair, True
        if env.objects:
            # warm start: the previous closest robot-environment pair bounds this query's broadphase
            # (consecutive queries along a path usually share it, which prunes most of the tree)
            warm = self._warm
            if warm is not None:
                scratch = self._scratch
                scratch.min_distance = _FAR
                dw = fcl.distance(warm[0], warm[1], _DREQ, scratch)
                if dw < best:
                    best, pair, is_self = dw, warm[2], False
            acc = _DistAcc(best)
            body.moving_manager.distance(env.manager, acc, _distance_cb)
            r = acc.result
            if r.o1 is not None and r.min_distance < best:
                g1, g2 = (r.o1, r.o2) if id(r.o1) in body.owner else (r.o2, r.o1)
                pair = (body.owner[id(g1)], env.owner[id(g2)])
                best, is_self = r.min_distance, False
                self._warm = (body.object_of[id(g1)], env.object_of[id(g2)], pair)
        if best >= _FAR:
            return DistanceResult(math.inf, "", "")
        return DistanceResult(float(best), pair[0], pair[1], self_collision=is_self)

    def _clearance_now(self) -> DistanceResult:
        body, env = self._body, self._obstacles
        if not env.objects or not body.clear_objects:
            return DistanceResult(math.inf, "", "")
        body.clear_manager.update()
        acc = _DistAcc(_FAR)
        body.clear_manager.distance(env.manager, acc, _distance_cb)
        r = acc.result
        if r.o1 is None or r.min_distance >= _FAR:
            return DistanceResult(math.inf, "", "")
        g1, g2 = (r.o1, r.o2) if id(r.o1) in body.owner else (r.o2, r.o1)
        return DistanceResult(float(r.min_distance), body.owner[id(g1)], env.owner[id(g2)])

    def _flags(self, qs: np.ndarray) -> np.ndarray:
        """(n,) bool: False where the sphere model proves qs[i] (n, 6) free, True where FCL must decide."""
        return self._body.sphere_flags(qs, self._obstacles.primitives())

    def sphere_clear(self, qs: np.ndarray) -> np.ndarray:
        """(n,) bool for (n, 6) configurations: True where the conservative sphere model alone proves the
        configuration collision-free (then FCL agrees); False means "ask FCL", not "in collision"."""
        return ~self._flags(_as_qs(qs))

    def sphere_model(self, clearance_m: float = 0.0) -> SphereModel:
        """The planning model of this scene as it is now (`twin.collision.planning_model`): the robot's sphere
        cover against the padded environment inflated by `clearance_m` more, touching = in collision, no FCL.
        A snapshot: edits to the scene after it was made (boxes, held object, opening) are not in it."""
        c = float(clearance_m)
        if not (math.isfinite(c) and c >= 0):
            raise InvalidRequestError(f"clearance_m must be >= 0, got {clearance_m}")
        return SphereModel(self._body.kernel_model(self._obstacles.primitives(c)), self._body.kernel_scratch())

    def in_collision(self, q: np.ndarray) -> bool:
        """True when the arm at q (6,) hits the environment or itself, or the held object hits either."""
        q = _as_q(q)
        if self.sphere_filter and not self._flags(q[None])[0]:
            return False
        self._body.prepare(q)
        return self._collides_now()

    def min_distance(self, q: np.ndarray, *, include_self: bool = True) -> DistanceResult:
        """Smallest signed distance at q (6,) over robot-environment and allowed robot-robot pairs.

        Some allowed self pairs never collide but stay close by construction (base_link/upper_arm_link
        9-12.5 mm, wrist_1/wrist_3 >= 17 mm), so they often hold the minimum; pass include_self=False
        for the clearance to the environment alone (obstacle-distance costs and constraints)."""
        self._body.prepare(_as_q(q))
        return self._distance_now(include_self)

    def clearance(self, q: np.ndarray) -> DistanceResult:
        """Signed distance at q (6,) from the arm beyond the shoulder (and a held object) to the environment:
        the clearance a trajectory keeps. Unlike min_distance it leaves out the base and shoulder links,
        whose distance to the cell does not depend on the configuration."""
        self._body.prepare(_as_q(q))
        return self._clearance_now()

    def clearance_batch(self, qs: np.ndarray) -> np.ndarray:
        """(n,) clearances, m, for (n, 6) configurations (see clearance)."""
        qs = _as_qs(qs)
        out = np.empty(qs.shape[0])
        for i in self._body.iter_prepared(qs):
            out[i] = self._clearance_now().distance
        return out

    def min_clearance(self, qs: np.ndarray) -> tuple[float, int]:
        """(the smallest clearance over the (n, 6) configurations qs, the index of one where it is), exactly as
        `clearance_batch(qs)`'s minimum and argmin, ties aside. FCL measures only where it can matter: the
        sphere model bounds every configuration's clearance from below, and the configurations are measured
        in the order of their bounds until the next bound exceeds the smallest clearance measured."""
        qs, body = _as_qs(qs), self._body
        if qs.shape[0] == 0:
            raise InvalidRequestError("min_clearance needs at least one configuration")
        bounds = self.sphere_model().distance_bounds(qs, body.clear_index)
        best, where = math.inf, 0
        for i in np.argsort(bounds, kind="stable").tolist():
            if bounds[i] - _BOUND_SLACK_M >= best:
                break
            body.prepare(qs[i])
            d = self._clearance_now().distance
            if d < best:
                best, where = d, i
        return best, where

    def in_collision_batch(self, qs: np.ndarray) -> np.ndarray:
        """(n,) bool for (n, 6) configurations (link poses computed vectorised)."""
        qs = _as_qs(qs)
        out = np.zeros(qs.shape[0], dtype=bool)
        if self.sphere_filter:
            ask = np.flatnonzero(self._flags(qs))
            for _, k in zip(self._body.iter_prepared(qs[ask]), ask.tolist(), strict=True):
                out[k] = self._collides_now()
            return out
        for i in self._body.iter_prepared(qs):
            out[i] = self._collides_now()
        return out

    def min_distance_batch(self, qs: np.ndarray, *, include_self: bool = True) -> np.ndarray:
        """(n,) signed minimum distances, m, for (n, 6) configurations (see min_distance)."""
        qs = _as_qs(qs)
        out = np.empty(qs.shape[0])
        for i in self._body.iter_prepared(qs):
            out[i] = self._distance_now(include_self).distance
        return out

    def first_collision(self, qs: np.ndarray) -> int | None:
        """Index of the first colliding configuration of (n, 6) qs, or None when all are free."""
        qs = _as_qs(qs)
        if not self.sphere_filter:
            for i in self._body.iter_prepared(qs, chunk=32):
                if self._collides_now():
                    return i
            return None
        # chunks growing from 32: a collision near the start (bisection order) is found after little work
        start, chunk = 0, 32
        while start < qs.shape[0]:
            part = qs[start : start + chunk]
            ask = np.flatnonzero(self._flags(part))
            if ask.size:
                for _, k in zip(self._body.iter_prepared(part[ask], chunk=8), ask.tolist(), strict=True):
                    if self._collides_now():
                        return start + k
            start += part.shape[0]
            chunk *= 2
        return None

    def check_path(self, qs: np.ndarray, *, resolution_rad: float = 0.01) -> PathCheck:
        """Check the piecewise-linear joint path through (n, 6) waypoints, densified so that no joint
        moves more than `resolution_rad` between two checked configurations; reports the first hit."""
        qs = _as_qs(qs)
        if not (math.isfinite(resolution_rad) and resolution_rad > 0):
            raise InvalidRequestError(f"resolution_rad must be > 0, got {resolution_rad}")
        if qs.shape[0] == 0:
            return PathCheck(True)
        dense, seg = _densify(qs, resolution_rad)
        k = self.first_collision(dense)
        return PathCheck(True) if k is None else PathCheck(False, seg[k], dense[k].copy())

    def link_poses(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """{link: (4, 4)} world poses of every robot link at q (6,), at the current gripper opening."""
        return self._body.chain.link_poses(_as_q(q))

    # =============================================================================================
    # scene edits
    # =============================================================================================
    @property
    def gripper_opening(self) -> float:
        """Current total finger opening of the collision model, m."""
        return self._body.opening

    def set_gripper_opening(self, width_m: float) -> None:
        """Move the collision model's fingers to a total opening of `width_m` (0 .. max stroke)."""
        self._body.set_opening(width_m)

    def names(self) -> list[str]:
        """Names of the environment objects (fixtures and boxes), in insertion order."""
        return list(self._obstacles.objects)

    def add_box(self, name: str, size: ArrayLike, pose: np.ndarray) -> None:
        """Add (or replace) an obstacle box of full extents `size` (3,) at `pose` (4, 4) in the world
        frame; fixtures cannot be replaced this way (remove them first)."""
        if self._obstacles.add_box(name, size, pose):
            self._warm = None  # the box it replaced may be the warm start's

    def add_box_bounds(self, name: str, lo: ArrayLike, hi: ArrayLike) -> None:
        """Add (or replace) an axis-aligned obstacle box between corners lo (3,) < hi (3,), world frame."""
        size, T = box_from_bounds(lo, hi)
        self.add_box(name, size, T)

    def add_unknown_fixtures(self, settings: Settings) -> None:
        """Add the fixtures marked `known: false` as a perfect detector would report them: their box
        shapes at their true poses (for planner tests and benchmarks that leave perception out)."""
        for name, size, pose in _unknown_fixture_boxes(settings):
            self.add_box(name, size, pose)

    def remove(self, name: str) -> None:
        """Remove an environment object (box or fixture) by name."""
        self._obstacles.remove(name)
        self._warm = None

    def environment_shapes(self) -> dict[str, list[tuple[str, tuple[float, ...], np.ndarray]]]:
        """Every environment object (fixtures and boxes) as its primitives, unpadded: name -> [(kind, size,
        pose (4, 4) in the world frame)], kinds and sizes as twin.robot.urdf_model.Shape. What a problem-set
        export writes, so another tool plans against exactly this world."""
        return {n: [(k, tuple(sz), T.copy()) for k, sz, T in shapes] for n, shapes in self._obstacles.shapes.items()}

    def boxes(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The boxes added at run time (perceived obstacles): name -> (size (3,), pose (4, 4)), world frame."""
        return {n: (sz.copy(), T.copy()) for n, (sz, T) in self._obstacles.boxes.items()}

    def box_bounds(self) -> dict[str, BoxBounds]:
        """The run-time boxes as axis-aligned bounds (the AABB of a rotated box), world frame."""
        return self._obstacles.box_bounds()

    def attached_box(self) -> tuple[str, np.ndarray, np.ndarray] | None:
        """(name, size (3,), pose in the tcp frame (4, 4)) of the held box, or None."""
        return self._body.held_box()

    @property
    def attached(self) -> str | None:
        """Name of the held object, or None."""
        held = self._body.held
        return None if held is None else held.name

    def attach_box(self, name: str, size: ArrayLike, T_tcp_object: np.ndarray) -> None:
        """Hold a box of full extents `size` (3,) at `T_tcp_object` (4, 4, object in the tcp frame): it moves
        with the tcp and is checked against the environment and the arm, not the gripper holding it."""
        if self.attached is not None:
            raise InvalidRequestError(f"already holding {self.attached!r}; detach() first")
        if not isinstance(name, str) or not name:
            raise InvalidRequestError("attached object name must be a non-empty string")
        self._body.attach(name, check_size(size), check_pose(T_tcp_object))
        self._warm = None  # the robot's objects are rebuilt

    def detach(self) -> str | None:
        """Drop the held object from the model; returns its name (None when nothing was held)."""
        name = self._body.detach()
        if name is not None:
            self._warm = None  # the robot's objects are rebuilt
        return name

    # ---- introspection ------------------------------------------------------------------------
    def allowed_self_pairs(self) -> list[tuple[str, str]]:
        """Robot link pairs checked against each other (the held object is not listed)."""
        return self._body.allowed_self_pairs()

    def held_object_checked_against(self) -> list[str]:
        """Robot links the held object is checked against (all but the tcp's rigid body and fingers)."""
        return self._body.held_object_checked_against()


def _unknown_fixture_boxes(settings: Settings) -> Iterator[tuple[str, tuple[float, ...], np.ndarray]]:
    """(fixture name, size, pose (4, 4)) of each box shape of the fixtures marked `known: false`, one by one;
    InvalidRequestError at a shape that is not a box."""
    for f in settings.world.fixtures:
        if f.known:
            continue
        for shape in read_fixture_shapes(settings.resolve(f.urdf), pose_from_xyz_rpy(f.position, f.rpy)):
            if shape.kind != "box":
                raise InvalidRequestError(f"fixture {f.name!r}: only box shapes can stand in for a perceived obstacle")
            yield f.name, shape.size, shape.pose


def _densify(qs: np.ndarray, resolution_rad: float) -> tuple[np.ndarray, list[int]]:
    """The piecewise-linear path through (n >= 1, 6) waypoints qs as (m, 6) configurations no more than
    `resolution_rad` apart in any joint, and for each the segment it lies on (0 for qs[0])."""
    pts, seg = [qs[:1]], [0]
    for i in range(qs.shape[0] - 1):
        steps = max(1, int(math.ceil(float(np.abs(qs[i + 1] - qs[i]).max()) / resolution_rad)))
        t = np.arange(1, steps + 1)[:, None] / steps
        pts.append(qs[i] + t * (qs[i + 1] - qs[i]))
        seg.extend([i] * steps)
    return np.concatenate(pts), seg


def _check_unknown_fixtures(unknown_fixtures: str) -> None:
    if unknown_fixtures not in ("box", "ignore"):
        raise InvalidRequestError(f"unknown_fixtures must be 'box' or 'ignore', got {unknown_fixtures!r}")


def _check_padding(padding_m: float) -> float:
    p = float(padding_m)
    if not (math.isfinite(p) and 0.0 <= p < 1.0):
        raise InvalidRequestError(f"padding_m must be in [0, 1) m, got {padding_m}")
    return p


def _as_q(q: np.ndarray) -> np.ndarray:
    a = np.asarray(q, dtype=float)
    if a.shape != (6,):
        raise InvalidRequestError(f"q must have shape (6,), got {a.shape}")
    if not math.isfinite(a.sum()):
        raise InvalidRequestError(f"q must be finite, got {a.tolist()}")
    return a


def _as_qs(qs: np.ndarray) -> np.ndarray:
    a = np.asarray(qs, dtype=float)
    if a.ndim != 2 or a.shape[1] != 6:
        raise InvalidRequestError(f"qs must have shape (n, 6), got {a.shape}")
    if not np.isfinite(a).all():
        raise InvalidRequestError("qs must be finite")
    return a
