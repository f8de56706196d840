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
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import fcl
import numpy as np
from numpy.typing import ArrayLike

from twin.collision.geometry import COLLISION_REQUEST as _CREQ
from twin.collision.geometry import DISTANCE_REQUEST as _DREQ
from twin.collision.geometry import FAR as _FAR
from twin.collision.geometry import BufferView as _Vec
from twin.collision.geometry import CollideFlag as _CollideFlag
from twin.collision.geometry import DistanceAccumulator as _DistAcc
from twin.collision.geometry import bounding_radius as _bounding_radius
from twin.collision.geometry import collide_callback as _collide_cb
from twin.collision.geometry import distance_callback as _distance_cb
from twin.collision.geometry import fcl_geometry as _geometry
from twin.collision.geometry import fcl_transform as _tf
from twin.collision.geometry import primitive_shapes
from twin.collision.rules import HELD as _HELD
from twin.collision.rules import CollisionRules, gripper_stroke_m
from twin.collision.spheres import TOUCH_M as _TOUCH_M
from twin.collision.spheres import EnvPrimitives, cover, env_primitives, primitive
from twin.errors import ConfigError, InvalidRequestError
from twin.timing import stage
from twin.types import BoxBounds
from twin.urdf_model import RobotModel, Shape, pose_from_xyz_rpy, read_fixture_shapes

if TYPE_CHECKING:
    from twin.config import Settings

__all__ = ["DistanceResult", "FixtureSpec", "PathCheck", "PlanningScene", "UnknownFixtures"]

# how a scene holds the fixtures marked `known: false`: as boxes at their true poses (what a perfect detector
# reports), or not at all (a task's cell, which perceives them)
UnknownFixtures = Literal["box", "ignore"]

log = logging.getLogger("twin")

_ONES3 = np.ones(3)


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
        robot_urdf: str | Path | RobotModel,
        *,
        fixtures: Sequence[FixtureSpec] = (),
        padding_m: float = 0.0,
        reference_configs: Iterable[Sequence[float]] = (),
        extra_excluded_pairs: Iterable[tuple[str, str]] = (),
        finger_opening_m: float | None = None,
        tcp_link: str = "tcp",
        sphere_filter: bool = True,
    ):
        self.padding_m = _check_padding(padding_m)
        self.sphere_filter = bool(sphere_filter)
        model = robot_urdf if isinstance(robot_urdf, RobotModel) else RobotModel.from_urdf(robot_urdf)
        self._init_robot(model, tcp_link=tcp_link, finger_opening_m=finger_opening_m)
        self._set_rules(
            CollisionRules.from_model(
                model, tcp_link=tcp_link, reference_configs=reference_configs, extra_excluded_pairs=extra_excluded_pairs
            )
        )

        # ---- environment ---------------------------------------------------------------------------
        self._init_env()
        for fx in fixtures:
            self._add_fixture(fx)
        self._env.setup()
        self._rebuild_robot()
        if self.sphere_filter:  # load (or, the first time on a machine, compile) the sphere kernel now, not
            with stage("imports"):  # inside a planner's time limit
                self._flags(np.zeros((1, 6)))

    def _init_robot(self, model: RobotModel, *, tcp_link: str, finger_opening_m: float | None) -> None:
        """Robot part of the scene from a parsed model: compiled chain and persistent FCL shapes (the
        allowed-collision rules are set by the caller with `_set_rules`)."""
        self.model = m = model
        src = m.source
        if len(m.arm_joints) != 6:
            raise ConfigError(f"{src}: expected 6 arm joints, found {list(m.arm_joints)}")
        if tcp_link not in m.link_index:
            raise ConfigError(f"{src}: no link named {tcp_link!r} for the tcp")
        arm = set(m.arm_joints)
        for j in m.joint_order:
            if j.mimic is not None and j.mimic[0] in arm:
                raise ConfigError(f"{src}: joint {j.name!r} mimics an arm joint; not supported")
        self.tcp_link = tcp_link
        self.max_opening_m = gripper_stroke_m(m)
        self._opening = self.max_opening_m if finger_opening_m is None else float(finger_opening_m)
        self._check_opening(self._opening)

        # ---- compiled chain: frame 0 = root, frame k+1 = child link of arm joint k ---------------
        self._frame_links = [m.root] + [m.joints[n].child for n in m.arm_joints]
        self._frame_of = {ln: self._frame_links.index(m.rigid_parent(ln, movable=m.arm_joints)) for ln in m.link_names}
        order = sorted(range(6), key=lambda k: m.joint_order.index(m.joints[m.arm_joints[k]]))
        self._chain = [(k, self._frame_of[m.joints[m.arm_joints[k]].parent]) for k in order]
        self._revolute = np.array([m.joints[n].type != "prismatic" for n in m.arm_joints])
        self._chain_arr = np.array(self._chain, dtype=np.int64)
        self._frame_parent = {k + 1: f for k, f in self._chain}  # frame -> its parent frame (0: the root)
        self._all_revolute = bool(self._revolute.all())
        self._F_list: list[np.ndarray] = [np.eye(4)] * 7
        self._gen = np.zeros((6, 4, 4))  # generator of each joint's motion (rotation K or translation)
        for k, n in enumerate(m.arm_joints):
            a = m.joints[n].axis
            if self._revolute[k]:
                self._gen[k, :3, :3] = [[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]]
            else:
                self._gen[k, :3, 3] = a

        # ---- robot shapes (built once; fcl reports the python geometry back in distance results) --
        self._shapes = primitive_shapes(m)
        self._owner: dict[int, tuple[str, bool]] = {}  # id(geometry) -> (name, is_robot)
        self._geom_object: dict[int, Any] = {}  # id(geometry) -> its CollisionObject
        self._warm: tuple[Any, Any, tuple[str, str]] | None = None  # last closest robot/env objects
        self._scratch = fcl.DistanceResult()  # reused: a fresh one costs as much as the distance itself
        self._shape_objects = []
        for s in self._shapes:
            geom = _geometry(s.kind, s.size)
            self._owner[id(geom)] = (s.link, True)
            self._shape_objects.append(fcl.CollisionObject(geom))
            self._geom_object[id(geom)] = self._shape_objects[-1]
        self._shape_radius = [_bounding_radius(s.kind, s.size) for s in self._shapes]
        self._shape_covers = [cover(s.kind, s.size) for s in self._shapes]  # spheres in each shape's frame
        self._static_links = {ln for ln in m.link_names if self._frame_of[ln] == 0}
        self._attached: tuple[str, Any, np.ndarray, Any, float] | None = None  # name, obj, T_tcp_obj, geom, radius
        self._update_constants()

    def _init_env(self) -> None:
        self._env = fcl.DynamicAABBTreeCollisionManager()
        self._env_objects: dict[str, list[tuple[Any, Any]]] = {}
        self._env_shapes: dict[str, list[tuple[str, tuple[float, ...], np.ndarray]]] = {}  # unpadded, for padded()
        self._boxes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._fixture_names: set[str] = set()
        self._env_prims: EnvPrimitives | None = None  # the environment for the sphere check, built on use

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
        new = type(self).__new__(type(self))
        new.padding_m = _check_padding(self.padding_m + extra)
        new.sphere_filter = self.sphere_filter
        new._init_robot(self.model, tcp_link=self.tcp_link, finger_opening_m=self._opening)
        new._set_rules(self._rules)
        new._init_env()
        for name in self._env_objects:
            if name in self._fixture_names:
                new._fixture_names.add(name)
            new._add_env(name, self._env_shapes[name])
            if name in self._boxes:
                sz, T = self._boxes[name]
                new._boxes[name] = (sz.copy(), T.copy())
        new._env.setup()
        if self._attached is not None:
            name, _, T, _, _ = self._attached
            ax, ay, az = (float(v) for v in self._attached_size)
            new._set_attached(name, (ax, ay, az), T.copy())
        new._rebuild_robot()
        return new

    @classmethod
    def from_settings(cls, settings: Settings, *, unknown_fixtures: UnknownFixtures = "box") -> PlanningScene:
        """The cell of a config: robot from settings.robot.urdf (gripper fully open; in the arm's base frame,
        with the arm's TCP where the URDF has no tcp link: `URArm.fit_urdf`), fixtures from
        settings.world.fixtures, padding from settings.collision.padding_m, the sphere filter from
        settings.collision.sphere_filter; the home posture is an exclusion reference.

        Fixtures marked `known: false` (obstacles the robot has to perceive) are, with `unknown_fixtures="box"`
        (the default), in the scene as a perfect detector reports them: boxes at their true poses
        (`add_unknown_fixtures`). That is the cell `twin plan`, `twin compare`, problem-set export and the
        planner contract plan in, so one query gets one answer everywhere. A task perceives them instead:
        its cell asks for `unknown_fixtures="ignore"` and adds what perception found with `add_box_bounds`.
        """
        if unknown_fixtures not in ("box", "ignore"):
            raise InvalidRequestError(f"unknown_fixtures must be 'box' or 'ignore', got {unknown_fixtures!r}")
        fixtures = [
            FixtureSpec(f.name, settings.resolve(f.urdf), pose_from_xyz_rpy(f.position, f.rpy))
            for f in settings.world.fixtures
            if f.known
        ]
        from twin.kinematics import URArm

        arm = URArm.from_settings(settings)
        model = arm.fit_urdf(RobotModel.from_urdf(settings.resolve(settings.robot.urdf)))
        scene = cls(
            model,
            fixtures=fixtures,
            padding_m=settings.collision.padding_m,
            reference_configs=[settings.robot.home],
            sphere_filter=settings.collision.sphere_filter,
        )
        wrong = arm.urdf_mismatch(scene.model)
        if wrong is not None:  # the planners plan with the DH kinematics: the collision model must be that arm
            raise ConfigError(
                f"robot.urdf {settings.robot.urdf} is not the arm of robot.model {settings.robot.model}: {wrong}"
            )
        if unknown_fixtures == "box":
            scene.add_unknown_fixtures(settings)
        return scene

    # =============================================================================================
    # construction helpers
    # =============================================================================================
    def _check_opening(self, w: float) -> None:
        if not (math.isfinite(w) and -1e-12 <= w <= self.max_opening_m + 1e-12):
            raise InvalidRequestError(f"gripper opening must be in [0, {self.max_opening_m}] m, got {w}")

    def _update_constants(self) -> None:
        """Constants of the compiled chain at the current finger opening: local joint transforms are
        A + u*B + v*C with u = sin q, v = 1 - cos q (revolute, Rodrigues) or u = q, v = 0 (prismatic)."""
        m = self.model
        L0 = m.link_pose_array(np.zeros((1, 6)), finger_opening=self._opening)[0]
        # frame 0 is the base frame itself (the root link sits at the model's root_pose in it)
        F0inv = [np.eye(4)] + [np.linalg.inv(L0[m.link_index[ln]]) for ln in self._frame_links[1:]]
        J = np.empty((6, 4, 4))
        for k, name in enumerate(m.arm_joints):
            j = m.joints[name]
            J[k] = F0inv[self._frame_of[j.parent]] @ L0[m.link_index[j.parent]] @ j.origin
        self._A = J
        self._B = J @ self._gen
        self._C = J @ self._gen @ self._gen
        self._C[~self._revolute] = 0.0
        self._ABC = np.ascontiguousarray(np.stack([self._A, self._B, self._C], axis=1).reshape(6, 3, 16))
        self._W = np.ones((6, 3))
        # every link relative to its frame, and every shape relative to its frame
        self._link_const = {ln: F0inv[self._frame_of[ln]] @ L0[m.link_index[ln]] for ln in m.link_names}
        self._shape_const = np.array([self._link_const[s.link] @ s.origin for s in self._shapes])
        self._tcp_frame = self._frame_of[self.tcp_link]
        self._tcp_const = self._link_const[self.tcp_link]
        if hasattr(self, "_objects"):
            self._refresh_constants()

    def _set_rules(self, rules: CollisionRules) -> None:
        self._rules = rules
        self.excluded_pairs: frozenset[tuple[str, str]] = rules.excluded_pairs
        self._held_excluded = rules.held_excluded

    def _rebuild_robot(self) -> None:
        """(Re)build the robot object list, self pairs, transfer buffer and the moving-shape broadphase
        (at construction, attach and detach)."""
        objects = list(self._shape_objects)
        nodes = [s.link for s in self._shapes]
        frames = [self._frame_of[s.link] for s in self._shapes]
        radius = list(self._shape_radius)
        if self._attached is not None:
            objects.append(self._attached[1])
            nodes.append(_HELD)
            frames.append(self._tcp_frame)
            radius.append(self._attached[4])
        self._objects = objects
        self._warm = None
        self._object_frame = np.array(frames, dtype=np.int64)  # int64: the sphere kernel's index type
        self._moving = [i for i, f in enumerate(frames) if f != 0]
        self._moving_objects = [objects[i] for i in self._moving]
        # self pairs at shape level, with their bounding-sphere radius sums
        allows = self._rules.allows
        pairs = [(i, k) for i, k in itertools.combinations(range(len(objects)), 2) if allows(nodes[i], nodes[k])]
        self._pa = np.array([i for i, _ in pairs], dtype=int)
        self._pb = np.array([k for _, k in pairs], dtype=int)
        rsum = np.array([radius[i] + radius[k] for i, k in pairs]) + 1e-9
        self._rsum, self._rsum2 = rsum, rsum**2
        # centre differences of all pairs as one product: (pairs x objects) selection @ centres
        self._sel = np.zeros((len(pairs), len(objects)))
        self._sel[np.arange(len(pairs)), self._pa] = 1.0
        self._sel[np.arange(len(pairs)), self._pb] = -1.0
        self._pair_objects = [(objects[i], objects[k]) for i, k in pairs]
        covers = list(self._shape_covers)
        if self._attached is not None:
            covers.append(cover("box", self._attached_size))
        self._covers = covers
        self._sph_start = np.concatenate([[0], np.cumsum([c.shape[0] for c in covers])]).astype(np.int64)
        self._sph_frame = np.repeat(self._object_frame, [c.shape[0] for c in covers])
        self._obj_radius = np.array(radius, dtype=float)
        self._obj_env = self._object_frame != 0
        prims = [primitive(s.kind, s.size) for s in self._shapes]
        if self._attached is not None:
            prims.append(primitive("box", self._attached_size))
        self._obj_kind = np.array([k for k, _, _ in prims], dtype=np.int64)
        self._obj_dims = np.array([d for _, d, _ in prims])
        self._refresh_constants()
        # transfer buffer: per object a (4, 3) block = [R^T ; t], i.e. R column-major then t (see _Vec)
        self._buf = np.zeros((len(objects), 4, 3))
        self._t = self._buf[:, 3]  # translations = bounding-sphere centres
        # numpy's stubs declare ndarray.__buffer__ only for Python >= 3.12; the buffer protocol is there on 3.11
        self._sinks = [
            (_Vec(memoryview(self._buf[i, :3])), _Vec(memoryview(self._buf[i, 3])))  # type: ignore[arg-type]
            for i in self._moving
        ]
        self._fast = self._probe_fast_path()
        self._moving_manager = fcl.DynamicAABBTreeCollisionManager()
        self._moving_manager.registerObjects(self._moving_objects)
        self._moving_manager.setup()
        # clearance leaves out what only the base joint moves: the shoulder, and a shape of the next link that is
        # round about that link's own joint axis (the upper arm's cylinder around the shoulder-lift axis): they
        # only turn about the base axis, so their distance to the cell is the same in every configuration, and
        # it would cap every clearance at theirs (robocup: 0.1025 m, upper arm to table, whatever the path)
        m = self.model
        turning = {ln for ln in m.link_names if m.rigid_parent(ln) in (m.root, m.joints[m.arm_joints[0]].child)}
        in_place = {i for i, sh in enumerate(self._shapes) if _round_about_its_joint(m, sh, turning)}
        self._clear_objects = [objects[i] for i in self._moving if nodes[i] not in turning and i not in in_place]
        self._clear_manager = fcl.DynamicAABBTreeCollisionManager()
        self._clear_manager.registerObjects(self._clear_objects)
        self._clear_manager.setup()
        # place every object once (static ones are never moved again) and refit the tree
        self._pack(self._frames_one(np.zeros(6)))
        for i, o in enumerate(objects):
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = self._buf[i, :3].T, self._buf[i, 3]
            o.setTransform(_tf(T))
        self._moving_manager.update()

    def _refresh_constants(self) -> None:
        """Per-object constant (object pose in its frame), transposed for the packing product."""
        S = list(self._shape_const)
        if self._attached is not None:
            S.append(self._tcp_const @ self._attached[2])
        self._ST = np.ascontiguousarray(np.transpose(np.array(S), (0, 2, 1)))
        if hasattr(self, "_covers"):  # sphere model: poses and sphere centres in the objects' frames
            self._obj_const = np.ascontiguousarray(np.array(S))
            self._reach = self._joint_reach()
            self._pair_moves = self._joints_between_pairs()
            self._sph = np.vstack(
                [np.hstack([c[:, :3] @ T[:3, :3].T + T[:3, 3], c[:, 3:]]) for c, T in zip(self._covers, S, strict=True)]
            )

    def _joint_reach(self) -> np.ndarray:
        """(6,) for each arm joint, how far any point of a part it moves can be from its axis, m: a joint
        motion dq moves no point farther than sum_k |dq_k| reach_k. Bounded by the chain's link offsets from
        the joint's child frame (on its axis) to the part's frame, plus the part's centre offset and bounding
        radius. A chain with a prismatic joint gets no bound (inf: nothing is cleared by advancement), as its
        link offsets change with the joint."""
        if not self._all_revolute:
            return np.full(6, np.inf)
        parent = self._frame_parent
        offset = {k + 1: float(np.linalg.norm(self._A[k][:3, 3])) for k in range(6)}  # frame origin from parent's
        reach = np.zeros(6)
        for o, f in enumerate(self._object_frame.tolist()):
            extent = float(np.linalg.norm(self._obj_const[o][:3, 3])) + float(self._obj_radius[o])
            g, path = f, 0.0
            while g != 0:  # every joint whose child frame is g or an ancestor of g moves part o
                k = g - 1
                reach[k] = max(reach[k], path + extent)
                path += offset[g]
                g = parent[g]
        return reach

    def _joints_between_pairs(self) -> np.ndarray:
        """(pairs, 6) 1.0 where arm joint k moves exactly one part of self pair p (it changes their relative
        pose), else 0.0: joints that move both (or neither) move the pair rigidly."""
        parent = self._frame_parent

        def moved_by(frame: int) -> np.ndarray:
            out = np.zeros(6)
            while frame != 0:
                out[frame - 1] = 1.0
                frame = parent[frame]
            return out

        moves = np.array([moved_by(f) for f in self._object_frame.tolist()]).reshape(-1, 6)
        return np.ascontiguousarray(np.abs(moves[self._pa] - moves[self._pb]).reshape(-1, 6))

    def _probe_fast_path(self) -> bool:
        """Check once that python-fcl reads the buffer views as intended (else use plain arrays)."""
        if not self._sinks:
            return False
        T = pose_from_xyz_rpy((0.1, -0.2, 0.3), (0.3, -0.5, 1.1))
        i = self._moving[0]
        saved = self._buf[i].copy()
        self._buf[i, :3] = T[:3, :3].T
        self._buf[i, 3] = T[:3, 3]
        o = fcl.CollisionObject(fcl.Sphere(0.1))
        try:
            o.setRotation(self._sinks[0][0])
            o.setTranslation(self._sinks[0][1])
            ok = bool(np.allclose(o.getRotation(), T[:3, :3]) and np.allclose(o.getTranslation(), T[:3, 3]))
        except Exception:  # noqa: BLE001  # pragma: no cover - depends on the python-fcl version
            ok = False
        self._buf[i] = saved
        if not ok:  # pragma: no cover
            log.warning("python-fcl setter shortcut unavailable; collision checks will be slower")
        return ok

    def _add_fixture(self, fx: FixtureSpec) -> None:
        if fx.name in self._env_objects:
            raise ConfigError(f"fixture name {fx.name!r} is used twice")
        shapes = read_fixture_shapes(fx.urdf, np.asarray(fx.pose, dtype=float))
        self._fixture_names.add(fx.name)
        self._add_env(fx.name, [(s.kind, s.size, s.pose) for s in shapes])

    def _add_env(self, name: str, shapes: list[tuple[str, tuple[float, ...], np.ndarray]]) -> None:
        objs = []
        for kind, size, pose in shapes:
            geom = _geometry(kind, size, self.padding_m)
            self._owner[id(geom)] = (name, False)
            objs.append((fcl.CollisionObject(geom, _tf(pose)), geom))
            self._geom_object[id(geom)] = objs[-1][0]
        self._env_objects[name] = objs
        self._env_prims = None
        self._env_shapes[name] = [(kind, tuple(size), np.array(pose, dtype=float)) for kind, size, pose in shapes]
        if objs:
            self._env.registerObjects([o for o, _ in objs])
            self._env.update()

    # =============================================================================================
    # kinematics of the collision model
    # =============================================================================================
    def _frames(self, qs: np.ndarray) -> np.ndarray:
        """(n, 7, 4, 4) frame poses (root + the 6 arm-joint child links) for (n, 6) qs."""
        if self._all_revolute:
            u, v = np.sin(qs), 1.0 - np.cos(qs)
        else:
            u = np.where(self._revolute, np.sin(qs), qs)
            v = np.where(self._revolute, 1.0 - np.cos(qs), 0.0)
        local = self._A + u[:, :, None, None] * self._B + v[:, :, None, None] * self._C
        F = np.empty((qs.shape[0], 7, 4, 4))
        F[:, 0] = np.eye(4)
        for k, f in self._chain:
            np.matmul(F[:, f], local[:, k], out=F[:, k + 1])
        return F

    def _frames_one(self, q: np.ndarray) -> np.ndarray:
        """(7, 4, 4) frames for one configuration (2-D products: fewer numpy calls than _frames)."""
        if self._all_revolute:
            u, v = np.sin(q), 1.0 - np.cos(q)
        else:
            u = np.where(self._revolute, np.sin(q), q)
            v = np.where(self._revolute, 1.0 - np.cos(q), 0.0)
        W = self._W  # local_k = [1, u_k, v_k] @ [A_k; B_k; C_k]: one small matmul instead of five ops
        W[:, 1] = u
        W[:, 2] = v
        local = np.matmul(W[:, None, :], self._ABC).reshape(6, 4, 4)
        F = self._F_list  # ndarray.dot on 2-D arrays is ~2x cheaper than matmul for 4x4
        for k, f in self._chain:
            F[k + 1] = F[f].dot(local[k])
        return np.array(F)

    def _pack(self, F: np.ndarray) -> None:
        """Object poses for frames F (7, 4, 4) into the transfer buffer: [R^T; t] = S^T @ F^T[:, :3]."""
        np.matmul(self._ST, F.transpose(0, 2, 1)[self._object_frame, :, :3], out=self._buf)

    def _pack_batch(self, F: np.ndarray) -> np.ndarray:
        """(n, m, 4, 3) transfer blocks for frames F (n, 7, 4, 4)."""
        return self._ST @ F.transpose(0, 1, 3, 2)[:, self._object_frame, :, :3]

    def _push(self) -> None:
        """Move the moving FCL objects to the poses in the transfer buffer and refit their tree."""
        if self._fast:
            for o, (rv, tv) in zip(self._moving_objects, self._sinks, strict=True):
                o.setRotation(rv)
                o.setTranslation(tv)
        else:  # pragma: no cover
            for i, o in zip(self._moving, self._moving_objects, strict=True):
                o.setRotation(np.ascontiguousarray(self._buf[i, :3].T))
                o.setTranslation(self._buf[i, 3].copy())
        self._moving_manager.update()

    def _prepare(self, q: np.ndarray) -> None:
        self._pack(self._frames_one(q))
        self._push()

    def _iter_prepared(self, qs: np.ndarray, chunk: int = 256) -> Iterator[int]:
        for start in range(0, qs.shape[0], chunk):
            P = self._pack_batch(self._frames(qs[start : start + chunk]))
            for i in range(P.shape[0]):
                self._buf[...] = P[i]
                self._push()
                yield start + i

    @staticmethod
    def _as_q(q: np.ndarray) -> np.ndarray:
        a = np.asarray(q, dtype=float)
        if a.shape != (6,):
            raise InvalidRequestError(f"q must have shape (6,), got {a.shape}")
        if not math.isfinite(a.sum()):
            raise InvalidRequestError(f"q must be finite, got {a.tolist()}")
        return a

    @staticmethod
    def _as_qs(qs: np.ndarray) -> np.ndarray:
        a = np.asarray(qs, dtype=float)
        if a.ndim != 2 or a.shape[1] != 6:
            raise InvalidRequestError(f"qs must have shape (n, 6), got {a.shape}")
        if not np.isfinite(a).all():
            raise InvalidRequestError("qs must be finite")
        return a

    # =============================================================================================
    # queries
    # =============================================================================================
    def _collides_now(self) -> bool:
        if self._env_objects:
            flag = _CollideFlag()
            self._moving_manager.collide(self._env, flag, _collide_cb)
            if flag.hit:
                return True
        d = self._sel.dot(self._t)
        d *= d
        for c in np.flatnonzero(d.dot(_ONES3) <= self._rsum2).tolist():
            oa, ob = self._pair_objects[c]
            if fcl.collide(oa, ob, _CREQ):
                return True
        return False

    def _distance_now(self, include_self: bool = True) -> DistanceResult:
        best, pair, is_self = _FAR, ("", ""), False
        if include_self and len(self._pa):
            d = self._sel.dot(self._t)
            d *= d
            lower = np.sqrt(d.dot(_ONES3)) - self._rsum  # sphere bound <= true distance
            order = np.argsort(lower).tolist()
            lower_l = lower.tolist()
            res = self._scratch
            res.min_distance = _FAR
            bi = -1
            for c in order:
                if lower_l[c] >= best:
                    break
                oa, ob = self._pair_objects[c]
                dc = fcl.distance(oa, ob, _DREQ, res)
                if dc < best:
                    best, bi = dc, c
            if bi >= 0:
                r = res
                pair = (self._owner[id(r.o1)][0], self._owner[id(r.o2)][0])
                is_self = True
        if self._env_objects:
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
            self._moving_manager.distance(self._env, acc, _distance_cb)
            r = acc.result
            if r.o1 is not None and r.min_distance < best:
                g1, g2 = (r.o1, r.o2) if self._owner[id(r.o1)][1] else (r.o2, r.o1)
                pair = (self._owner[id(g1)][0], self._owner[id(g2)][0])
                best, is_self = r.min_distance, False
                self._warm = (self._geom_object[id(g1)], self._geom_object[id(g2)], pair)
        if best >= _FAR:
            return DistanceResult(math.inf, "", "")
        return DistanceResult(float(best), pair[0], pair[1], self_collision=is_self)

    # ---- the sphere check (twin.collision.spheres): clears configurations before FCL sees them -----------
    def _flags(self, qs: np.ndarray) -> np.ndarray:
        """(n,) bool: False where the sphere model proves qs[i] (n, 6) free, True where FCL must decide."""
        from twin.collision.sphere_kernel import flag_configurations  # numba: loaded on first use

        if not (qs.flags.c_contiguous and qs.flags.writeable and qs.dtype == np.float64):
            qs = np.array(qs, dtype=float, order="C")  # one compiled specialisation: writeable C float64
        out = np.empty(qs.shape[0], dtype=bool)
        if self._env_prims is None:
            self._env_prims = env_primitives(
                [sh for shapes in self._env_shapes.values() for sh in shapes], self.padding_m
            )
        env = self._env_prims
        flag_configurations(
            qs,
            self._revolute,
            self._A,
            self._B,
            self._C,
            self._chain_arr,
            self._object_frame,
            self._obj_const,
            self._obj_kind,
            self._obj_dims,
            self._obj_radius,
            self._obj_env,
            self._sph_start,
            self._sph_frame,
            self._sph,
            self._pa,
            self._pb,
            env.kind,
            env.to_local,
            env.dims,
            env.bound,
            _TOUCH_M,
            self._reach,
            self._pair_moves,
            out,
        )
        return out

    def sphere_clear(self, qs: np.ndarray) -> np.ndarray:
        """(n,) bool for (n, 6) configurations: True where the conservative sphere model alone proves the
        configuration collision-free (then FCL agrees); False means "ask FCL", not "in collision"."""
        return ~self._flags(self._as_qs(qs))

    def in_collision(self, q: np.ndarray) -> bool:
        """True when the arm at q (6,) hits the environment or itself, or the held object hits either."""
        q = self._as_q(q)
        if self.sphere_filter and not self._flags(q[None])[0]:
            return False
        self._prepare(q)
        return self._collides_now()

    def min_distance(self, q: np.ndarray, *, include_self: bool = True) -> DistanceResult:
        """Smallest signed distance at q (6,) over robot-environment and allowed robot-robot pairs.

        Some allowed self pairs never collide but stay close by construction (base_link/upper_arm_link
        9-12.5 mm, wrist_1/wrist_3 >= 17 mm), so they often hold the minimum; pass include_self=False
        for the clearance to the environment alone (obstacle-distance costs and constraints)."""
        self._prepare(self._as_q(q))
        return self._distance_now(include_self)

    def _clearance_now(self) -> DistanceResult:
        if not self._env_objects or not self._clear_objects:
            return DistanceResult(math.inf, "", "")
        self._clear_manager.update()
        acc = _DistAcc(_FAR)
        self._clear_manager.distance(self._env, acc, _distance_cb)
        r = acc.result
        if r.o1 is None or r.min_distance >= _FAR:
            return DistanceResult(math.inf, "", "")
        g1, g2 = (r.o1, r.o2) if self._owner[id(r.o1)][1] else (r.o2, r.o1)
        return DistanceResult(float(r.min_distance), self._owner[id(g1)][0], self._owner[id(g2)][0])

    def clearance(self, q: np.ndarray) -> DistanceResult:
        """Signed distance at q (6,) from the arm beyond the shoulder (and a held object) to the environment:
        the clearance a trajectory keeps. Unlike min_distance it leaves out the base and shoulder links,
        whose distance to the cell does not depend on the configuration."""
        self._prepare(self._as_q(q))
        return self._clearance_now()

    def clearance_batch(self, qs: np.ndarray) -> np.ndarray:
        """(n,) clearances, m, for (n, 6) configurations (see clearance)."""
        qs = self._as_qs(qs)
        out = np.empty(qs.shape[0])
        for i in self._iter_prepared(qs):
            out[i] = self._clearance_now().distance
        return out

    def in_collision_batch(self, qs: np.ndarray) -> np.ndarray:
        """(n,) bool for (n, 6) configurations (link poses computed vectorised)."""
        qs = self._as_qs(qs)
        out = np.zeros(qs.shape[0], dtype=bool)
        if self.sphere_filter:
            ask = np.flatnonzero(self._flags(qs))
            for _, k in zip(self._iter_prepared(qs[ask]), ask.tolist(), strict=True):
                out[k] = self._collides_now()
            return out
        for i in self._iter_prepared(qs):
            out[i] = self._collides_now()
        return out

    def min_distance_batch(self, qs: np.ndarray, *, include_self: bool = True) -> np.ndarray:
        """(n,) signed minimum distances, m, for (n, 6) configurations (see min_distance)."""
        qs = self._as_qs(qs)
        out = np.empty(qs.shape[0])
        for i in self._iter_prepared(qs):
            out[i] = self._distance_now(include_self).distance
        return out

    def first_collision(self, qs: np.ndarray) -> int | None:
        """Index of the first colliding configuration of (n, 6) qs, or None when all are free."""
        qs = self._as_qs(qs)
        if not self.sphere_filter:
            for i in self._iter_prepared(qs, chunk=32):
                if self._collides_now():
                    return i
            return None
        # chunks growing from 32: a collision near the start (bisection order) is found after little work
        start, chunk = 0, 32
        while start < qs.shape[0]:
            part = qs[start : start + chunk]
            ask = np.flatnonzero(self._flags(part))
            if ask.size:
                for _, k in zip(self._iter_prepared(part[ask], chunk=8), ask.tolist(), strict=True):
                    if self._collides_now():
                        return start + k
            start += part.shape[0]
            chunk *= 2
        return None

    def check_path(self, qs: np.ndarray, *, resolution_rad: float = 0.01) -> PathCheck:
        """Check the piecewise-linear joint path through (n, 6) waypoints, densified so that no joint
        moves more than `resolution_rad` between two checked configurations; reports the first hit."""
        qs = self._as_qs(qs)
        if not (math.isfinite(resolution_rad) and resolution_rad > 0):
            raise InvalidRequestError(f"resolution_rad must be > 0, got {resolution_rad}")
        if qs.shape[0] == 0:
            return PathCheck(True)
        pts, seg = [qs[:1]], [0]
        for i in range(qs.shape[0] - 1):
            steps = max(1, int(math.ceil(float(np.abs(qs[i + 1] - qs[i]).max()) / resolution_rad)))
            t = np.arange(1, steps + 1)[:, None] / steps
            pts.append(qs[i] + t * (qs[i + 1] - qs[i]))
            seg.extend([i] * steps)
        dense = np.concatenate(pts)
        k = self.first_collision(dense)
        return PathCheck(True) if k is None else PathCheck(False, seg[k], dense[k].copy())

    def link_poses(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """{link: (4, 4)} world poses of every robot link at q (6,), at the current gripper opening."""
        F = self._frames_one(self._as_q(q))
        return {ln: F[self._frame_of[ln]] @ C for ln, C in self._link_const.items()}

    # =============================================================================================
    # scene edits
    # =============================================================================================
    @property
    def gripper_opening(self) -> float:
        """Current total finger opening of the collision model, m."""
        return self._opening

    def set_gripper_opening(self, width_m: float) -> None:
        """Move the collision model's fingers to a total opening of `width_m` (0 .. max stroke)."""
        w = float(width_m)
        self._check_opening(w)
        self._opening = w
        self._update_constants()

    def names(self) -> list[str]:
        """Names of the environment objects (fixtures and boxes), in insertion order."""
        return list(self._env_objects)

    def add_box(self, name: str, size: ArrayLike, pose: np.ndarray) -> None:
        """Add (or replace) an obstacle box of full extents `size` (3,) at `pose` (4, 4) in the world
        frame; fixtures cannot be replaced this way (remove them first)."""
        if not isinstance(name, str) or not name:
            raise InvalidRequestError("box name must be a non-empty string")
        if name in self._fixture_names:
            raise InvalidRequestError(f"{name!r} is a fixture; remove it first or choose another name")
        sz = _check_size(size)
        T = _check_pose(pose)
        if name in self._env_objects:
            self.remove(name)
        self._add_env(name, [("box", sz, T)])
        self._boxes[name] = (np.array(sz, dtype=float), T.copy())

    def add_box_bounds(self, name: str, lo: ArrayLike, hi: ArrayLike) -> None:
        """Add (or replace) an axis-aligned obstacle box between corners lo (3,) < hi (3,), world frame."""
        a, b = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        if a.shape != (3,) or b.shape != (3,) or not (np.isfinite(a).all() and np.isfinite(b).all()):
            raise InvalidRequestError(f"lo and hi must be 3 finite numbers each, got {lo!r}, {hi!r}")
        if np.any(b <= a):
            raise InvalidRequestError(f"need lo < hi on every axis, got lo={a.tolist()} hi={b.tolist()}")
        T = np.eye(4)
        T[:3, 3] = 0.5 * (a + b)
        self.add_box(name, b - a, T)

    def add_unknown_fixtures(self, settings: Settings) -> None:
        """Add the fixtures marked `known: false` as a perfect detector would report them: their box
        shapes at their true poses (for planner tests and benchmarks that leave perception out)."""
        for f in settings.world.fixtures:
            if f.known:
                continue
            for shape in read_fixture_shapes(settings.resolve(f.urdf), pose_from_xyz_rpy(f.position, f.rpy)):
                if shape.kind != "box":
                    raise InvalidRequestError(
                        f"fixture {f.name!r}: only box shapes can stand in for a perceived obstacle"
                    )
                self.add_box(f.name, shape.size, shape.pose)

    def remove(self, name: str) -> None:
        """Remove an environment object (box or fixture) by name."""
        objs = self._env_objects.pop(name, None)
        self._boxes.pop(name, None)
        self._env_shapes.pop(name, None)
        self._env_prims = None
        if objs is None:
            raise InvalidRequestError(f"no object named {name!r} in the scene; present: {self.names()}")
        for o, geom in objs:
            self._env.unregisterObject(o)
            self._owner.pop(id(geom), None)
            self._geom_object.pop(id(geom), None)
        self._warm = None
        self._fixture_names.discard(name)
        self._env.update()

    def environment_shapes(self) -> dict[str, list[tuple[str, tuple[float, ...], np.ndarray]]]:
        """Every environment object (fixtures and boxes) as its primitives, unpadded: name -> [(kind, size,
        pose (4, 4) in the world frame)], kinds and sizes as twin.urdf_model.Shape. What a problem-set
        export writes, so another tool plans against exactly this world."""
        return {n: [(k, tuple(sz), T.copy()) for k, sz, T in shapes] for n, shapes in self._env_shapes.items()}

    def boxes(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The boxes added at run time (perceived obstacles): name -> (size (3,), pose (4, 4)), world frame."""
        return {n: (sz.copy(), T.copy()) for n, (sz, T) in self._boxes.items()}

    def box_bounds(self) -> dict[str, BoxBounds]:
        """The run-time boxes as axis-aligned bounds (the AABB of a rotated box), world frame."""
        out = {}
        for n, (sz, T) in self._boxes.items():
            half = np.abs(T[:3, :3]) @ (0.5 * sz)
            lo, hi = T[:3, 3] - half, T[:3, 3] + half
            out[n] = BoxBounds(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])
        return out

    def attached_box(self) -> tuple[str, np.ndarray, np.ndarray] | None:
        """(name, size (3,), pose in the tcp frame (4, 4)) of the held box, or None."""
        if self._attached is None:
            return None
        return self._attached[0], self._attached_size.copy(), self._attached[2].copy()

    @property
    def attached(self) -> str | None:
        """Name of the held object, or None."""
        return None if self._attached is None else self._attached[0]

    def attach_box(self, name: str, size: ArrayLike, T_tcp_object: np.ndarray) -> None:
        """Hold a box of full extents `size` (3,) at `T_tcp_object` (4, 4, object in the tcp frame): it moves
        with the tcp and is checked against the environment and the arm, not the gripper holding it."""
        if self._attached is not None:
            raise InvalidRequestError(f"already holding {self._attached[0]!r}; detach() first")
        if not isinstance(name, str) or not name:
            raise InvalidRequestError("attached object name must be a non-empty string")
        self._set_attached(name, _check_size(size), _check_pose(T_tcp_object))
        self._rebuild_robot()

    def _set_attached(self, name: str, sz: tuple[float, float, float], T: np.ndarray) -> None:
        geom = _geometry("box", sz)
        self._attached_size = np.array(sz, dtype=float)
        self._owner[id(geom)] = (name, True)
        self._attached = (name, fcl.CollisionObject(geom), T, geom, _bounding_radius("box", sz))
        self._geom_object[id(geom)] = self._attached[1]

    def detach(self) -> str | None:
        """Drop the held object from the model; returns its name (None when nothing was held)."""
        if self._attached is None:
            return None
        name, geom = self._attached[0], self._attached[3]
        self._owner.pop(id(geom), None)
        self._geom_object.pop(id(geom), None)
        self._attached = None
        self._rebuild_robot()
        return name

    # ---- introspection ------------------------------------------------------------------------
    def allowed_self_pairs(self) -> list[tuple[str, str]]:
        """Robot link pairs checked against each other (the held object is not listed)."""
        return self._rules.allowed_self_pairs(self.model)

    def held_object_checked_against(self) -> list[str]:
        """Robot links the held object is checked against (all but the tcp's rigid body and fingers)."""
        m = self.model
        return [ln for ln in m.link_names if m.links[ln].shapes and ln not in self._held_excluded]


def _round_about_its_joint(model: RobotModel, shape: Shape, turning: set[str]) -> bool:
    """Whether `shape` is round about the axis of its link's own revolute joint (a sphere centred on it, a
    cylinder or capsule along it) and that joint hangs from a link in `turning`: then the joint turns the
    shape in place, and only what moves `turning` moves it."""
    joint = model.parent_joint.get(shape.link)
    if joint is None or joint.type not in ("revolute", "continuous") or model.rigid_parent(joint.parent) not in turning:
        return False
    axis, centre = joint.axis, shape.origin[:3, 3]
    on_axis = float(np.linalg.norm(centre - (centre @ axis) * axis)) < 1e-9
    if shape.kind == "sphere":
        return on_axis
    along = float(np.linalg.norm(np.cross(shape.origin[:3, 2], axis))) < 1e-9
    return shape.kind in ("cylinder", "capsule") and on_axis and along


def _check_padding(padding_m: float) -> float:
    p = float(padding_m)
    if not (math.isfinite(p) and 0.0 <= p < 1.0):
        raise InvalidRequestError(f"padding_m must be in [0, 1) m, got {padding_m}")
    return p


def _check_size(size: ArrayLike) -> tuple[float, float, float]:
    sz = np.asarray(size, dtype=float)
    if sz.shape != (3,) or not np.isfinite(sz).all() or np.any(sz <= 0):
        raise InvalidRequestError(f"box size must be 3 positive numbers, got {size!r}")
    return (float(sz[0]), float(sz[1]), float(sz[2]))


def _check_pose(pose: np.ndarray) -> np.ndarray:
    T = np.asarray(pose, dtype=float)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise InvalidRequestError(f"pose must be a finite (4, 4) transform, got shape {T.shape}")
    R = T[:3, :3]
    if (
        not np.allclose(R.T @ R, np.eye(3), atol=1e-6)
        or abs(np.linalg.det(R) - 1.0) > 1e-6
        or not np.allclose(T[3], [0, 0, 0, 1])
    ):
        raise InvalidRequestError("pose must be rigid: orthonormal rotation with det +1 and last row 0 0 0 1")
    return T
