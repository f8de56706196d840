"""What the robot may hit: the cell's fixtures and the boxes added at run time, as padded FCL objects in one
broadphase tree, with their unpadded shapes kept for copies, exports and the sphere check.

Why a class of its own: the environment is edited (fixtures at construction, perceived boxes at run time)
independently of the robot, and a padded copy of a scene rebuilds it from the kept shapes without reading
any URDF again. Padding: `padding_m` inflates every shape on each side.
"""

from __future__ import annotations

from typing import Any

import fcl
import numpy as np
from numpy.typing import ArrayLike

from twin.collision.fcl_shapes import fcl_geometry, fcl_transform
from twin.collision.spheres import EnvPrimitives, env_primitives
from twin.errors import ConfigError, InvalidRequestError
from twin.robot.urdf_model import read_fixture_shapes
from twin.types import BoxBounds

__all__ = ["Obstacles", "ShapeList", "box_from_bounds", "check_pose", "check_size"]

ShapeList = list[
    tuple[str, tuple[float, ...], np.ndarray]
]  # [(kind, size, pose (4, 4))], as twin.robot.urdf_model.Shape


class Obstacles:
    """Environment objects by name (insertion order), each a list of padded FCL objects in `manager`.

    `owner`/`object_of`: id(FCL geometry) -> object name / its CollisionObject (FCL reports geometries back).
    Call `manager.setup()` once after the first batch of additions.
    """

    def __init__(self, padding_m: float):
        self.padding_m = padding_m
        self.manager = fcl.DynamicAABBTreeCollisionManager()
        self.objects: dict[str, list[tuple[Any, Any]]] = {}  # name -> [(CollisionObject, geometry)]
        self.shapes: dict[str, ShapeList] = {}  # unpadded, for copies
        self.boxes: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # run-time boxes: name -> (size (3,), pose)
        self.fixture_names: set[str] = set()
        self.owner: dict[int, str] = {}  # id(geometry) -> object name
        self.object_of: dict[int, Any] = {}  # id(geometry) -> its CollisionObject
        self._prims: EnvPrimitives | None = None  # the environment for the sphere check, built on use
        self._inflated: dict[float, EnvPrimitives] = {}  # ... inflated by a clearance more (planning models)

    def copy(self, padding_m: float) -> Obstacles:
        """The same objects (fixtures stay fixtures, boxes stay boxes) with `padding_m` and new FCL objects."""
        new = Obstacles(padding_m)
        for name in self.objects:
            if name in self.fixture_names:
                new.fixture_names.add(name)
            new.add(name, self.shapes[name])
            if name in self.boxes:
                sz, T = self.boxes[name]
                new.boxes[name] = (sz.copy(), T.copy())
        new.manager.setup()
        return new

    def add_fixture(self, name: str, urdf: Any, pose: np.ndarray) -> None:
        """Add the collision shapes of the fixture URDF `urdf` placed at `pose` (4, 4)."""
        if name in self.objects:
            raise ConfigError(f"fixture name {name!r} is used twice")
        shapes = read_fixture_shapes(urdf, np.asarray(pose, dtype=float))
        self.fixture_names.add(name)
        self.add(name, [(s.kind, s.size, s.pose) for s in shapes])

    def add(self, name: str, shapes: ShapeList) -> None:
        """Add object `name` made of `shapes` (unpadded; padded here)."""
        objs = []
        for kind, size, pose in shapes:
            geom = fcl_geometry(kind, size, self.padding_m)
            self.owner[id(geom)] = name
            objs.append((fcl.CollisionObject(geom, fcl_transform(pose)), geom))
            self.object_of[id(geom)] = objs[-1][0]
        self.objects[name] = objs
        self._prims = None
        self._inflated = {}
        self.shapes[name] = [(kind, tuple(size), np.array(pose, dtype=float)) for kind, size, pose in shapes]
        if objs:
            self.manager.registerObjects([o for o, _ in objs])
            self.manager.update()

    def add_box(self, name: str, size: ArrayLike, pose: np.ndarray) -> bool:
        """Add (or replace) a run-time box of full extents `size` (3,) at `pose` (4, 4); fixtures cannot be
        replaced this way. True when a box of that name was replaced (removed first)."""
        if not isinstance(name, str) or not name:
            raise InvalidRequestError("box name must be a non-empty string")
        if name in self.fixture_names:
            raise InvalidRequestError(f"{name!r} is a fixture; remove it first or choose another name")
        sz = check_size(size)
        T = check_pose(pose)
        replaced = name in self.objects
        if replaced:
            self.remove(name)
        self.add(name, [("box", sz, T)])
        self.boxes[name] = (np.array(sz, dtype=float), T.copy())
        return replaced

    def remove(self, name: str) -> None:
        """Remove an object (box or fixture) by name."""
        objs = self.objects.pop(name, None)
        self.boxes.pop(name, None)
        self.shapes.pop(name, None)
        self._prims = None
        self._inflated = {}
        if objs is None:
            raise InvalidRequestError(f"no object named {name!r} in the scene; present: {list(self.objects)}")
        for o, geom in objs:
            self.manager.unregisterObject(o)
            self.owner.pop(id(geom), None)
            self.object_of.pop(id(geom), None)
        self.fixture_names.discard(name)
        self.manager.update()

    def primitives(self, clearance_m: float = 0.0) -> EnvPrimitives:
        """Every shape, padded (and inflated by `clearance_m` more), for the sphere check (built on first use
        after a change)."""
        if clearance_m:
            prims = self._inflated.get(clearance_m)
            if prims is None:
                prims = self._inflated[clearance_m] = self._primitives(self.padding_m + clearance_m)
            return prims
        if self._prims is None:
            self._prims = self._primitives(self.padding_m)
        return self._prims

    def _primitives(self, pad: float) -> EnvPrimitives:
        return env_primitives([sh for shapes in self.shapes.values() for sh in shapes], pad)

    def box_bounds(self) -> dict[str, BoxBounds]:
        """The run-time boxes as axis-aligned bounds (the AABB of a rotated box), world frame."""
        out = {}
        for n, (sz, T) in self.boxes.items():
            half = np.abs(T[:3, :3]) @ (0.5 * sz)
            lo, hi = T[:3, 3] - half, T[:3, 3] + half
            out[n] = BoxBounds(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])
        return out


def box_from_bounds(lo: ArrayLike, hi: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(size (3,), pose (4, 4)) of the axis-aligned box between corners lo (3,) < hi (3,); InvalidRequestError
    otherwise."""
    a, b = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    if a.shape != (3,) or b.shape != (3,) or not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise InvalidRequestError(f"lo and hi must be 3 finite numbers each, got {lo!r}, {hi!r}")
    if np.any(b <= a):
        raise InvalidRequestError(f"need lo < hi on every axis, got lo={a.tolist()} hi={b.tolist()}")
    T = np.eye(4)
    T[:3, 3] = 0.5 * (a + b)
    return b - a, T


def check_size(size: ArrayLike) -> tuple[float, float, float]:
    """Box full extents (3,) as 3 positive floats, m; InvalidRequestError otherwise."""
    sz = np.asarray(size, dtype=float)
    if sz.shape != (3,) or not np.isfinite(sz).all() or np.any(sz <= 0):
        raise InvalidRequestError(f"box size must be 3 positive numbers, got {size!r}")
    return (float(sz[0]), float(sz[1]), float(sz[2]))


def check_pose(pose: np.ndarray) -> np.ndarray:
    """`pose` as a float (4, 4) rigid transform (not copied when it already is one); InvalidRequestError
    otherwise."""
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
