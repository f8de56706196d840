"""The robot's collision body: its shapes as persistent FCL objects, posed at q through the compiled chain,
with the gripper's opening and a held box, the self pairs the rules allow and the sphere model of the
sphere check.

Why a class of its own: this is what is set up (from a parsed robot model, at construction, attach, detach
and a new gripper opening) and what changes together; the planning scene (`twin.collision.scene`) asks
questions of it and of the environment. Posing is split in two steps so that batches stay vectorised:
`pack`/`pack_batch` write every object's pose into a transfer buffer (numpy), `push` moves the FCL objects
to it and refits the broadphase tree of the moving shapes.

Links rigidly fixed to the world (frame 0: base_link) are placed once and never moved; they are left out of
the moving broadphase, so they are never tested against the environment (base_link stands on the table).
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import fcl
import numpy as np

from twin.collision.chain import CompiledChain
from twin.collision.fcl_shapes import (
    COLLISION_REQUEST,
    DISTANCE_REQUEST,
    FAR,
    BufferView,
    bounding_radius,
    fcl_geometry,
    fcl_transform,
    primitive_shapes,
)
from twin.collision.rules import HELD, CollisionRules
from twin.collision.spheres import TOUCH_M, EnvPrimitives, cover, primitive
from twin.errors import ConfigError, InvalidRequestError
from twin.robot.gripper import gripper_stroke_m
from twin.robot.urdf_model import RobotModel, Shape, pose_from_xyz_rpy

__all__ = ["RobotBody", "check_robot_model"]

log = logging.getLogger("twin")

_ONES3 = np.ones(3)


@dataclass(frozen=True, eq=False)
class _HeldBox:
    """The held object: an FCL box that moves with the tcp at `T_tcp` (4, 4, in the tcp frame)."""

    name: str
    size: np.ndarray  # (3,) full extents, m
    T_tcp: np.ndarray
    geometry: Any
    obj: Any  # its fcl.CollisionObject
    radius: float  # bounding-sphere radius, m


def check_robot_model(model: RobotModel, tcp_link: str) -> None:
    """ConfigError unless `model` is an arm the scene supports: 6 arm joints, a `tcp_link`, no joint that
    mimics an arm joint."""
    src = model.source
    if len(model.arm_joints) != 6:
        raise ConfigError(f"{src}: expected 6 arm joints, found {list(model.arm_joints)}")
    if tcp_link not in model.link_index:
        raise ConfigError(f"{src}: no link named {tcp_link!r} for the tcp")
    arm = set(model.arm_joints)
    for j in model.joint_order:
        if j.mimic is not None and j.mimic[0] in arm:
            raise ConfigError(f"{src}: joint {j.name!r} mimics an arm joint; not supported")


def _check_opening(width_m: float, max_opening_m: float) -> None:
    if not (math.isfinite(width_m) and -1e-12 <= width_m <= max_opening_m + 1e-12):
        raise InvalidRequestError(f"gripper opening must be in [0, {max_opening_m}] m, got {width_m}")


class RobotBody:
    """The arm (and a held box) as FCL objects, posed at q (6,) joint angles, rad; poses in the world = robot
    base frame. Object i of `objects` is robot shape i (`shapes` order), then the held box when there is one.

    `owner`/`object_of`: id(FCL geometry) -> part name / its CollisionObject (FCL reports geometries back).
    `t`: (objects, 3) view of the objects' positions = bounding-sphere centres after `pack`.
    `pair_objects`, `sel`, `rsum`, `rsum2`: the allowed self pairs, their centre-difference selection and
    bounding-sphere radius sums. Not thread-safe: posing moves the shared FCL objects.
    """

    def __init__(
        self,
        model: RobotModel,
        rules: CollisionRules,
        *,
        tcp_link: str = "tcp",
        finger_opening_m: float | None = None,
        held: tuple[str, np.ndarray, np.ndarray] | None = None,
        covers: Sequence[np.ndarray] | None = None,
    ):
        """`held`: (name, size (3,), pose in the tcp frame (4, 4)) of a box the gripper holds, or None.
        `covers`: the sphere cover of each of the model's shapes, in `model.shapes()` order (the robot's,
        `Robot.sphere_cover`); None: covered here."""
        check_robot_model(model, tcp_link)
        self.model = m = model
        self.tcp_link = tcp_link
        self.max_opening_m = gripper_stroke_m(m)
        self._opening = self.max_opening_m if finger_opening_m is None else float(finger_opening_m)
        _check_opening(self._opening, self.max_opening_m)
        self.chain = CompiledChain(m, tcp_link=tcp_link, finger_opening_m=self._opening)
        self.rules = rules
        self.excluded_pairs: frozenset[tuple[str, str]] = rules.excluded_pairs

        # ---- robot shapes (built once; fcl reports the python geometry back in distance results) --
        self.shapes = primitive_shapes(m)
        self.owner: dict[int, str] = {}  # id(geometry) -> robot part name
        self.object_of: dict[int, Any] = {}  # id(geometry) -> its CollisionObject
        self._shape_objects = []
        for s in self.shapes:
            geom = fcl_geometry(s.kind, s.size)
            self.owner[id(geom)] = s.link
            self._shape_objects.append(fcl.CollisionObject(geom))
            self.object_of[id(geom)] = self._shape_objects[-1]
        self._shape_radius = [bounding_radius(s.kind, s.size) for s in self.shapes]
        # spheres in each shape's frame
        self._shape_covers = list(covers) if covers is not None else [cover(s.kind, s.size) for s in self.shapes]
        if len(self._shape_covers) != len(self.shapes):
            raise InvalidRequestError(f"{len(self._shape_covers)} sphere covers for {len(self.shapes)} shapes")
        self._shape_const = self._shape_constants()
        self.held: _HeldBox | None = None
        if held is not None:
            name, size, T = held
            sx, sy, sz = (float(v) for v in size)
            self._set_held(name, (sx, sy, sz), T)
        self.rebuild()

    @classmethod
    def from_model(
        cls,
        model: RobotModel,
        *,
        tcp_link: str = "tcp",
        finger_opening_m: float | None = None,
        reference_configs: Iterable[Sequence[float]] = (),
        extra_excluded_pairs: Iterable[tuple[str, str]] = (),
        covers: Sequence[np.ndarray] | None = None,
    ) -> RobotBody:
        """The body of a parsed model with its allowed-collision rules computed (`CollisionRules.from_model`:
        the reference postures are measured here, once; `copy` reuses them). The model and the opening are
        checked before the rules are measured."""
        check_robot_model(model, tcp_link)
        if finger_opening_m is not None:
            _check_opening(float(finger_opening_m), gripper_stroke_m(model))
        rules = CollisionRules.from_model(
            model, tcp_link=tcp_link, reference_configs=reference_configs, extra_excluded_pairs=extra_excluded_pairs
        )
        return cls(model, rules, tcp_link=tcp_link, finger_opening_m=finger_opening_m, covers=covers)

    def copy(self) -> RobotBody:
        """An equal body with its own FCL objects (the model, the rules, the opening and the held box reused)."""
        return RobotBody(
            self.model,
            self.rules,
            tcp_link=self.tcp_link,
            finger_opening_m=self._opening,
            held=self.held_box(),
            covers=self._shape_covers,
        )

    # =============================================================================================
    # set-up: gripper opening, held box, self pairs, sphere model
    # =============================================================================================
    @property
    def opening(self) -> float:
        """Current total finger opening, m."""
        return self._opening

    def set_opening(self, width_m: float) -> None:
        """Move the fingers to a total opening of `width_m` (0 .. max stroke)."""
        w = float(width_m)
        _check_opening(w, self.max_opening_m)
        self._opening = w
        self.chain.set_opening(w)
        self._shape_const = self._shape_constants()
        self._refresh_constants()

    def held_box(self) -> tuple[str, np.ndarray, np.ndarray] | None:
        """(name, size (3,), pose in the tcp frame (4, 4)) of the held box, or None."""
        if self.held is None:
            return None
        return self.held.name, self.held.size.copy(), self.held.T_tcp.copy()

    def attach(self, name: str, size: tuple[float, float, float], T_tcp_object: np.ndarray) -> None:
        """Hold a box (checked arguments) that moves with the tcp."""
        self._set_held(name, size, T_tcp_object)
        self.rebuild()

    def detach(self) -> str | None:
        """Drop the held box; its name, or None when nothing was held."""
        if self.held is None:
            return None
        name, geom = self.held.name, self.held.geometry
        self.owner.pop(id(geom), None)
        self.object_of.pop(id(geom), None)
        self.held = None
        self.rebuild()
        return name

    def _set_held(self, name: str, size: tuple[float, float, float], T: np.ndarray) -> None:
        geom = fcl_geometry("box", size)
        self.owner[id(geom)] = name
        obj = fcl.CollisionObject(geom)
        self.held = _HeldBox(name, np.array(size, dtype=float), T, geom, obj, bounding_radius("box", size))
        self.object_of[id(geom)] = obj

    def _shape_constants(self) -> np.ndarray:
        """(shapes, 4, 4) every shape's pose in its frame, at the current opening."""
        return np.array([self.chain.link_const[s.link] @ s.origin for s in self.shapes])

    def rebuild(self) -> None:
        """(Re)build the object list, self pairs, sphere model, transfer buffer and the broadphase trees of the
        moving shapes (at construction, attach and detach)."""
        held = self.held
        objects = list(self._shape_objects)
        nodes = [s.link for s in self.shapes]
        frames = [self.chain.frame_of[s.link] for s in self.shapes]
        radius = list(self._shape_radius)
        if held is not None:
            objects.append(held.obj)
            nodes.append(HELD)
            frames.append(self.chain.tcp_frame)
            radius.append(held.radius)
        self.objects = objects
        self.object_frame = np.array(frames, dtype=np.int64)  # int64: the sphere kernel's index type
        self._moving = [i for i, f in enumerate(frames) if f != 0]
        self._moving_objects = [objects[i] for i in self._moving]
        self._build_self_pairs(nodes, radius)
        self._build_sphere_model(radius)
        self._refresh_constants()
        # transfer buffer: per object a (4, 3) block = [R^T ; t], i.e. R column-major then t (see BufferView)
        self._buf = np.zeros((len(objects), 4, 3))
        self.t = self._buf[:, 3]  # translations = bounding-sphere centres
        # numpy's stubs declare ndarray.__buffer__ only for Python >= 3.12; the buffer protocol is there on 3.11
        self._sinks = [
            (BufferView(memoryview(self._buf[i, :3])), BufferView(memoryview(self._buf[i, 3])))  # type: ignore[arg-type]
            for i in self._moving
        ]
        self._fast = self._probe_fast_path()
        self.moving_manager = fcl.DynamicAABBTreeCollisionManager()
        self.moving_manager.registerObjects(self._moving_objects)
        self.moving_manager.setup()
        # clearance leaves out what only the base joint moves: the shoulder, and a shape of the next link that is
        # round about that link's own joint axis (the upper arm's cylinder around the shoulder-lift axis): they
        # only turn about the base axis, so their distance to the cell is the same in every configuration, and
        # it would cap every clearance at theirs (robocup: 0.1025 m, upper arm to table, whatever the path)
        m = self.model
        turning = {ln for ln in m.link_names if m.rigid_parent(ln) in (m.root, m.joints[m.arm_joints[0]].child)}
        in_place = {i for i, sh in enumerate(self.shapes) if _round_about_its_joint(m, sh, turning)}
        clear = [i for i in self._moving if nodes[i] not in turning and i not in in_place]
        self.clear_objects = [objects[i] for i in clear]
        self.clear_index = np.array(clear, dtype=np.int64)  # the same objects, as the sphere kernels number them
        self.clear_manager = fcl.DynamicAABBTreeCollisionManager()
        self.clear_manager.registerObjects(self.clear_objects)
        self.clear_manager.setup()
        # place every object once (static ones are never moved again) and refit the tree
        self.pack(self.chain.frames_one(np.zeros(6)))
        for i, o in enumerate(objects):
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = self._buf[i, :3].T, self._buf[i, 3]
            o.setTransform(fcl_transform(T))
        self.moving_manager.update()

    def _build_self_pairs(self, nodes: list[str], radius: list[float]) -> None:
        """Self pairs at object level that the rules allow, with their bounding-sphere radius sums."""
        objects = self.objects
        allows = self.rules.allows
        pairs = [(i, k) for i, k in itertools.combinations(range(len(objects)), 2) if allows(nodes[i], nodes[k])]
        self.pa = np.array([i for i, _ in pairs], dtype=int)
        self.pb = np.array([k for _, k in pairs], dtype=int)
        rsum = np.array([radius[i] + radius[k] for i, k in pairs]) + 1e-9
        self.rsum, self.rsum2 = rsum, rsum**2
        # centre differences of all pairs as one product: (pairs x objects) selection @ centres
        self.sel = np.zeros((len(pairs), len(objects)))
        self.sel[np.arange(len(pairs)), self.pa] = 1.0
        self.sel[np.arange(len(pairs)), self.pb] = -1.0
        self.pair_objects = [(objects[i], objects[k]) for i, k in pairs]

    def _build_sphere_model(self, radius: list[float]) -> None:
        """The objects' sphere covers and primitives for the sphere check (`twin.collision.spheres`)."""
        held = self.held
        covers = list(self._shape_covers)
        if held is not None:
            covers.append(cover("box", held.size))
        self._covers = covers
        self.sph_start = np.concatenate([[0], np.cumsum([c.shape[0] for c in covers])]).astype(np.int64)
        self._sph_frame = np.repeat(self.object_frame, [c.shape[0] for c in covers])
        self.obj_radius = np.array(radius, dtype=float)
        self._obj_env = self.object_frame != 0
        prims = [primitive(s.kind, s.size) for s in self.shapes]
        if held is not None:
            prims.append(primitive("box", held.size))
        self._obj_kind = np.array([k for k, _, _ in prims], dtype=np.int64)
        self.obj_dims = np.array([d for _, d, _ in prims])

    def _refresh_constants(self) -> None:
        """Per-object constants (object pose in its frame): transposed for the packing product, and the
        sphere model's poses, sphere centres and joint bounds."""
        S = list(self._shape_const)
        if self.held is not None:
            S.append(self.chain.tcp_const @ self.held.T_tcp)
        self._ST = np.ascontiguousarray(np.transpose(np.array(S), (0, 2, 1)))
        self.obj_const = np.ascontiguousarray(np.array(S))
        self.reach = self.chain.joint_reach(self.object_frame, self.obj_const, self.obj_radius)
        self.obj_reach = np.ascontiguousarray(
            self.chain.object_reach(self.object_frame, self.obj_const, self.obj_radius)
        )
        moves = self.chain.joints_moving(self.object_frame)
        # (pairs, 6) 1.0 where arm joint k moves exactly one part of self pair p (it changes their relative pose):
        # joints that move both (or neither) move the pair rigidly
        self.pair_moves = np.ascontiguousarray(np.abs(moves[self.pa] - moves[self.pb]).reshape(-1, 6))
        # (pairs, 6) how far joint k moves one part of pair p relative to the other per radian, at most
        self.pair_reach = np.ascontiguousarray(
            (self.pair_moves * np.maximum(self.obj_reach[self.pa], self.obj_reach[self.pb])).reshape(-1, 6)
        )
        self.sph = np.vstack(
            [np.hstack([c[:, :3] @ T[:3, :3].T + T[:3, 3], c[:, 3:]]) for c, T in zip(self._covers, S, strict=True)]
        )

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

    # =============================================================================================
    # posing the body at q
    # =============================================================================================
    def pack(self, F: np.ndarray) -> None:
        """Object poses for frames F (7, 4, 4) into the transfer buffer: [R^T; t] = S^T @ F^T[:, :3]."""
        np.matmul(self._ST, F.transpose(0, 2, 1)[self.object_frame, :, :3], out=self._buf)

    def pack_batch(self, F: np.ndarray) -> np.ndarray:
        """(n, m, 4, 3) transfer blocks for frames F (n, 7, 4, 4)."""
        return self._ST @ F.transpose(0, 1, 3, 2)[:, self.object_frame, :, :3]

    def push(self) -> None:
        """Move the moving FCL objects to the poses in the transfer buffer and refit their tree."""
        if self._fast:
            for o, (rv, tv) in zip(self._moving_objects, self._sinks, strict=True):
                o.setRotation(rv)
                o.setTranslation(tv)
        else:  # pragma: no cover
            for i, o in zip(self._moving, self._moving_objects, strict=True):
                o.setRotation(np.ascontiguousarray(self._buf[i, :3].T))
                o.setTranslation(self._buf[i, 3].copy())
        self.moving_manager.update()

    def prepare(self, q: np.ndarray) -> None:
        """Pose the body at q (6,)."""
        self.pack(self.chain.frames_one(q))
        self.push()

    def iter_prepared(self, qs: np.ndarray, chunk: int = 256) -> Iterator[int]:
        """Pose the body at each of (n, 6) qs in turn (link poses computed `chunk` at a time), yielding i."""
        for start in range(0, qs.shape[0], chunk):
            P = self.pack_batch(self.chain.frames(qs[start : start + chunk]))
            for i in range(P.shape[0]):
                self._buf[...] = P[i]
                self.push()
                yield start + i

    # =============================================================================================
    # self-collision of the posed body
    # =============================================================================================
    def self_collides(self) -> bool:
        """Whether an allowed self pair collides at the current pose: the pairs whose bounding spheres
        overlap (one numpy step) go to FCL's narrow phase, until the first hit."""
        d = self.sel.dot(self.t)
        d *= d
        for c in np.flatnonzero(d.dot(_ONES3) <= self.rsum2).tolist():
            oa, ob = self.pair_objects[c]
            if fcl.collide(oa, ob, COLLISION_REQUEST):
                return True
        return False

    def self_distance(self, res: Any) -> tuple[float, tuple[str, str] | None]:
        """(smallest signed distance, its pair of part names) over the allowed self pairs at the current pose,
        or (FAR, None) when there is none. Pairs are visited in order of their bounding-sphere lower bound
        and the walk stops once the bound exceeds the best distance found. `res`: a reused fcl.DistanceResult
        (a fresh one costs as much as the distance itself)."""
        best = FAR
        d = self.sel.dot(self.t)
        d *= d
        lower = np.sqrt(d.dot(_ONES3)) - self.rsum  # sphere bound <= true distance
        order = np.argsort(lower).tolist()
        lower_l = lower.tolist()
        res.min_distance = FAR
        bi = -1
        for c in order:
            if lower_l[c] >= best:
                break
            oa, ob = self.pair_objects[c]
            dc = fcl.distance(oa, ob, DISTANCE_REQUEST, res)
            if dc < best:
                best, bi = dc, c
        if bi < 0:
            return best, None
        return best, (self.owner[id(res.o1)], self.owner[id(res.o2)])

    def kernel_model(self, env: EnvPrimitives) -> tuple[Any, ...]:
        """The sphere model against `env` as the compiled kernels take it (`twin.collision.sphere_kernel`'s
        model tuple): this body as it is now (held object, finger opening), a snapshot."""
        ch = self.chain
        body = (self.object_frame, self.obj_const, self._obj_kind, self.obj_dims, self.obj_radius, self._obj_env)
        cover = (self.sph_start, self._sph_frame, self.sph, self.pa, self.pb)
        bounds = (self.reach, self.pair_moves, TOUCH_M, self.obj_reach, self.pair_reach)
        return (
            ch.revolute,
            ch.A,
            ch.B,
            ch.C,
            ch.chain_arr,
            *body,
            *cover,
            env.kind,
            env.to_local,
            env.dims,
            env.bound,
            *bounds,
        )

    def kernel_scratch(self) -> tuple[Any, ...]:
        """Work arrays for the kernels over this body (made again when the held object changes their sizes)."""
        from twin.collision.sphere_kernel import new_scratch  # lazy: numba (compiled on first use)

        size = (len(self.object_frame), self.sph.shape[0], len(self.pa))
        if getattr(self, "_scratch_size", None) != size:
            self._kernel_scratch, self._scratch_size = new_scratch(*size), size
        return self._kernel_scratch

    def sphere_flags(self, qs: np.ndarray, env: EnvPrimitives) -> np.ndarray:
        """(n,) bool: False where the sphere model proves qs[i] (n, 6) clear of `env` and of itself, True
        where FCL must decide."""
        from twin.collision.sphere_kernel import flag_configurations  # lazy: numba (compiled on first use)

        if not (qs.flags.c_contiguous and qs.flags.writeable and qs.dtype == np.float64):
            qs = np.array(qs, dtype=float, order="C")  # one compiled specialisation: writeable C float64
        out = np.empty(qs.shape[0], dtype=bool)
        flag_configurations(self.kernel_model(env), self.kernel_scratch(), qs, out)
        return out

    # ---- introspection ------------------------------------------------------------------------
    def allowed_self_pairs(self) -> list[tuple[str, str]]:
        """Robot link pairs checked against each other (the held object is not listed)."""
        return self.rules.allowed_self_pairs(self.model)

    def held_object_checked_against(self) -> list[str]:
        """Robot links the held object is checked against (all but the tcp's rigid body and fingers)."""
        m = self.model
        return [ln for ln in m.link_names if m.links[ln].shapes and ln not in self.rules.held_excluded]


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
