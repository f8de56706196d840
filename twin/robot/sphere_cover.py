"""The robot's conservative sphere cover: every collision primitive enclosed in spheres, by partition.

Why with the robot: the cover is a property of the robot's shapes (issue 41's planning model is built from
it), made once per robot (`Robot.sphere_cover`) and handed to every planning scene, like the rest of the robot.
The compiled check that uses it is `twin.collision.sphere_kernel`.

Covers (built by partition, so they enclose their shape by construction):
* box: a grid of cells no longer than `CELL_M` per side, each inside its circumscribed sphere;
* cylinder and capsule: slabs along the axis, each inside the sphere through its rim, thin enough that
  the sphere is at most `SLACK_M` wider than the cylinder (a capsule's caps are spheres of their own);
* sphere: itself.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from twin.errors import ConfigError

__all__ = ["CELL_M", "SLACK_M", "cover"]

CELL_M = 0.02  # largest cell side of a box cover, m
SLACK_M = 0.002  # a cylinder slab's sphere is at most this much wider than the cylinder, m


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
