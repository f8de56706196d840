"""A conservative sphere model of the robot, and the compiled check that clears most configurations
before FCL sees them.

Why: a planner asks the scene about thousands of configurations per query, and one FCL check through
Python costs 10-20 us (moving a dozen objects, refitting the broadphase, callbacks). Most of those
configurations are nowhere near anything. Here every robot collision primitive (and a held box) is
enclosed in spheres, generated from the same URDF shapes the FCL scene uses, and one compiled loop
(numba, `twin.collision.sphere_kernel`, loaded on first use) computes the link frames, places the
spheres and measures their exact distances to the environment's primitives, and for each allowed self
pair the spheres of one shape against the exact primitive of the other (both ways). A configuration
whose spheres touch nothing is certainly free in FCL too (every sphere contains its part of a shape);
the rest go to FCL unchanged. So the scene's answers do not change at all, only their price: FCL stays
the judge of every configuration the spheres cannot clear. Along a dense sequence (a final check walks
thousands of configurations 2 mrad apart) the next configurations are cleared without evaluation while
no robot point can have moved as far as the last cleared configuration's clearance (conservative
advancement; `CompiledChain.joint_reach` bounds how far a joint motion moves any point).

The covers are the robot's (`twin.robot.sphere_cover`, made once per robot: `Robot.sphere_cover`).
A sphere is "touching" when its distance is below `TOUCH_M` (10 um), well above FCL's tolerances.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twin.errors import ConfigError
from twin.robot.sphere_cover import CELL_M, SLACK_M, cover

__all__ = ["CELL_M", "SLACK_M", "TOUCH_M", "EnvPrimitives", "cover", "env_primitives", "primitive"]

TOUCH_M = 1e-5  # spheres closer than this to anything are left to FCL, m

BOX, CYLINDER, SPHERE, CAPSULE = 0, 1, 2, 3
_KIND = {"box": BOX, "cylinder": CYLINDER, "sphere": SPHERE, "capsule": CAPSULE}


@dataclass(frozen=True, eq=False)
class EnvPrimitives:
    """The environment as arrays for the compiled check: per primitive its kind code, the world-to-local
    transform (3, 4), its half extents (box: x, y, z; cylinder/capsule: radius, half length, 0; sphere:
    radius, 0, 0) inflated by the padding as FCL inflates it, and its bounding sphere (x, y, z, r)."""

    kind: np.ndarray
    to_local: np.ndarray
    dims: np.ndarray
    bound: np.ndarray


def env_primitives(shapes: Sequence[tuple[str, Sequence[float], np.ndarray]], pad: float) -> EnvPrimitives:
    """Arrays for `shapes` [(kind, size, pose (4, 4) in the world)], each inflated by `pad` m per side
    exactly as `twin.collision.fcl_shapes.fcl_geometry` inflates it."""
    n = len(shapes)
    kind = np.zeros(n, dtype=np.int64)
    to_local = np.zeros((n, 3, 4))
    dims = np.zeros((n, 3))
    bound = np.zeros((n, 4))
    for i, (k, size, T) in enumerate(shapes):
        kind[i], dims[i], rad = primitive(k, size, pad)
        R, t = np.asarray(T, dtype=float)[:3, :3], np.asarray(T, dtype=float)[:3, 3]
        to_local[i, :, :3] = R.T
        to_local[i, :, 3] = -R.T @ t
        bound[i, :3] = t
        bound[i, 3] = rad
    return EnvPrimitives(kind, to_local, dims, bound)


def primitive(kind: str, size: Sequence[float] | np.ndarray, pad: float = 0.0) -> tuple[int, np.ndarray, float]:
    """(kind code, half dimensions (3,), bounding radius) of a primitive inflated by `pad` m per side as
    `twin.collision.fcl_shapes.fcl_geometry` inflates it: box half extents; cylinder and capsule (radius,
    half length, 0); sphere (radius, 0, 0)."""
    if kind not in _KIND:
        raise ConfigError(f"collision shape {kind!r} is not supported by the planning scene (use primitives)")
    dims = np.zeros(3)
    if kind == "box":
        dims[:] = 0.5 * np.asarray(size[:3], dtype=float) + pad
        rad = float(np.linalg.norm(dims))
    elif kind == "cylinder":
        dims[:2] = (float(size[0]) + pad, 0.5 * float(size[1]) + pad)
        rad = math.hypot(dims[0], dims[1])
    elif kind == "capsule":
        dims[:2] = (float(size[0]) + pad, 0.5 * float(size[1]))
        rad = dims[0] + dims[1]
    else:
        dims[0] = float(size[0]) + pad
        rad = dims[0]
    return _KIND[kind], dims, rad
