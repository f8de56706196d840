"""FCL geometry of the planning scene: URDF collision primitives as FCL shapes, their bounding spheres,
poses as FCL transforms, and the broadphase callbacks and requests every query reuses.

Why a module of its own: this is the one place that knows how a URDF primitive (`twin.robot.urdf_model.Shape`
kinds) maps onto an FCL shape and how padding inflates it, so the scene, the exclusion rules and any
other FCL user build identical geometry. Meshes are not supported: the scene needs primitives (planners
query it millions of times, and the robot URDF is written with primitives for that reason).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import fcl
import numpy as np

from twin.errors import ConfigError
from twin.robot.urdf_model import RobotModel, Shape

__all__ = [
    "COLLISION_REQUEST",
    "DISTANCE_REQUEST",
    "FAR",
    "BufferView",
    "CollideFlag",
    "DistanceAccumulator",
    "bounding_radius",
    "collide_callback",
    "distance_callback",
    "fcl_geometry",
    "fcl_transform",
    "primitive_shapes",
]

FAR = 1e9  # "no distance measured yet": larger than any distance in a robot cell, m

COLLISION_REQUEST = fcl.CollisionRequest()
DISTANCE_REQUEST = fcl.DistanceRequest(enable_signed_distance=True)


def fcl_geometry(kind: str, size: Sequence[float], pad: float = 0.0) -> Any:
    """FCL shape of a primitive (sizes as `twin.robot.urdf_model.Shape`), inflated by `pad` m on each side.

    A box grows by 2 pad per extent, a cylinder by pad in radius and 2 pad in length, a sphere by pad in
    radius, a capsule by pad in radius (its caps grow with it). Raises ConfigError for other kinds."""
    if kind == "box":
        return fcl.Box(*(float(s) + 2 * pad for s in size))
    if kind == "cylinder":
        return fcl.Cylinder(float(size[0]) + pad, float(size[1]) + 2 * pad)
    if kind == "sphere":
        return fcl.Sphere(float(size[0]) + pad)
    if kind == "capsule":
        return fcl.Capsule(float(size[0]) + pad, float(size[1]))
    raise ConfigError(f"collision shape {kind!r} is not supported by the planning scene (use primitives)")


def bounding_radius(kind: str, size: Sequence[float]) -> float:
    """Radius of the sphere about the shape's origin that encloses it (all primitives are centred)."""
    if kind == "box":
        return 0.5 * math.sqrt(sum(float(v) ** 2 for v in size))
    if kind == "cylinder":
        return math.hypot(float(size[0]), 0.5 * float(size[1]))
    if kind == "capsule":
        return float(size[0]) + 0.5 * float(size[1])
    return float(size[0])


def fcl_transform(T: np.ndarray) -> Any:
    """fcl.Transform of a (4, 4) homogeneous pose."""
    return fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


def primitive_shapes(model: RobotModel) -> list[Shape]:
    """Every collision shape of `model` (links in `link_names` order); ConfigError if one is a mesh."""
    shapes = model.shapes()
    for s in shapes:
        if s.kind == "mesh":
            raise ConfigError(f"{model.source}: link {s.link!r} uses a mesh; the planning scene needs primitives")
    return shapes


class BufferView:
    """Hands python-fcl a persistent buffer view: its setters call `arr.astype(float64)` and read the
    memory, so returning a ready memoryview skips a numpy copy per call (halves the transfer cost)."""

    __slots__ = ("mv",)

    def __init__(self, mv: memoryview):
        self.mv = mv

    def astype(self, *_: Any, **__: Any) -> memoryview:
        return self.mv


class CollideFlag:
    """Set by `collide_callback` when the broadphase finds a colliding pair."""

    __slots__ = ("hit",)

    def __init__(self) -> None:
        self.hit = False


def collide_callback(o1: Any, o2: Any, flag: CollideFlag) -> bool:
    """Broadphase collide callback: narrow-phase test, stop at the first hit."""
    if fcl.collide(o1, o2, COLLISION_REQUEST):
        flag.hit = True
        return True
    return False


class DistanceAccumulator:
    """Running minimum handed to the broadphase; starting it at a known bound prunes every farther pair."""

    __slots__ = ("request", "result")

    def __init__(self, bound: float = FAR) -> None:
        self.request = DISTANCE_REQUEST
        self.result = fcl.DistanceResult(bound)


def distance_callback(o1: Any, o2: Any, acc: DistanceAccumulator) -> tuple[bool, float]:
    """Broadphase distance callback: keep the smallest signed distance in `acc`."""
    fcl.distance(o1, o2, acc.request, acc.result)
    # keep exploring overlapping AABBs after a penetration so the deepest one is usually found
    return False, max(acc.result.min_distance, 1e-12)
