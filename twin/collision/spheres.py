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

Covers (built by partition, so they enclose their shape by construction):
* box: a grid of cells no longer than `CELL_M` per side, each inside its circumscribed sphere;
* cylinder and capsule: slabs along the axis, each inside the sphere through its rim, thin enough that
  the sphere is at most `SLACK_M` wider than the cylinder (a capsule's caps are spheres of their own);
* sphere: itself.
A sphere is "touching" when its distance is below `TOUCH_M` (10 um), well above FCL's tolerances.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twin.errors import ConfigError

__all__ = ["CELL_M", "SLACK_M", "TOUCH_M", "EnvPrimitives", "cover", "env_primitives", "primitive"]

CELL_M = 0.02  # largest cell side of a box cover, m
SLACK_M = 0.002  # a cylinder slab's sphere is at most this much wider than the cylinder, m
TOUCH_M = 1e-5  # spheres closer than this to anything are left to FCL, m

BOX, CYLINDER, SPHERE, CAPSULE = 0, 1, 2, 3
_KIND = {"box": BOX, "cylinder": CYLINDER, "sphere": SPHERE, "capsule": CAPSULE}


def cover(kind: str, size: Sequence[float] | np.ndarray) -> np.ndarray:
    """(k, 4) spheres (x, y, z, r) in the primitive's own frame whose union encloses it (sizes as
    `twin.robot.urdf_model.Shape`: box full extents, cylinder/capsule (radius, length), sphere (radius,))."""
    if kind == "sphere":
        return np.array([[0.0, 0.0, 0.0, float(size[0])]])
    if kind == "box":
        ext = np.array(size[:3], dtype=float)
        counts = [max(1, math.ceil(float(e) / CELL_M - 1e-9)) for e in ext]
        cell = ext / np.array(counts)
        r = 0.5 * float(np.linalg.norm(cell)) * (1 + 1e-12)
        axes = [(np.arange(counts[i]) + 0.5) * cell[i] - 0.5 * ext[i] for i in range(3)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        return np.hstack([grid, np.full((grid.shape[0], 1), r)])
    if kind in ("cylinder", "capsule"):
        rho, length = float(size[0]), float(size[1])
        slab = 2.0 * math.sqrt(2.0 * rho * SLACK_M + SLACK_M**2)
        n = max(1, math.ceil(length / slab - 1e-9))
        t = length / n
        r = math.sqrt(rho**2 + 0.25 * t**2) * (1 + 1e-12)
        z = (np.arange(n) + 0.5) * t - 0.5 * length
        out = np.column_stack([np.zeros(n), np.zeros(n), z, np.full(n, r)])
        if kind == "capsule":
            caps = np.array([[0.0, 0.0, -0.5 * length, rho], [0.0, 0.0, 0.5 * length, rho]])
            out = np.vstack([out, caps])
        return out
    raise ConfigError(f"collision shape {kind!r} has no sphere cover (use primitives)")


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
