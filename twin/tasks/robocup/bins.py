"""The RoboCup cell's bins: what a bin looks like (from its URDF's boxes) and which bin an object belongs in.

The task's rules, read by both the task (where to release) and its referee (was the object placed), so they
live below both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.config import Settings
from twin.errors import ConfigError
from twin.robot.urdf_model import read_fixture_shapes
from twin.transforms import pose_from_xyz_rpy

__all__ = ["BinGeometry", "bin_for", "bin_geometries", "read_bin_geometry"]


@dataclass(frozen=True, eq=False)
class BinGeometry:
    """A bin as its URDF's collision boxes describe it, in its own frame, and where it stands.

    `inner_lo`/`inner_hi` (3,): the open inner volume: x and y between the inner wall faces, z from the
    floor's top to the rims' top. `outer_lo`/`outer_hi` (3,): the whole bin. `pose` (4, 4): the bin frame
    in the base frame (the fixture's position and rpy).
    """

    name: str
    pose: np.ndarray
    inner_lo: np.ndarray
    inner_hi: np.ndarray
    outer_lo: np.ndarray
    outer_hi: np.ndarray

    def local(self, p: np.ndarray) -> np.ndarray:
        """(3,) base-frame point in the bin frame."""
        R, t = self.pose[:3, :3], self.pose[:3, 3]
        return R.T @ (np.asarray(p, dtype=float)[:3] - t)

    def world(self, p_local: np.ndarray) -> np.ndarray:
        """(3,) bin-frame point in the base frame."""
        return self.pose[:3, :3] @ np.asarray(p_local, dtype=float) + self.pose[:3, 3]

    def over(self, p: np.ndarray) -> bool:
        """True when base-frame point `p` is above or inside the bin's outer footprint."""
        q = self.local(p)
        return bool(np.all(q[:2] > self.outer_lo[:2]) and np.all(q[:2] < self.outer_hi[:2]))

    @property
    def yaw(self) -> float:
        return math.atan2(self.pose[1, 0], self.pose[0, 0])


def read_bin_geometry(name: str, urdf: str, pose: np.ndarray) -> BinGeometry:
    """A bin's geometry from its URDF: the box with the largest footprint is the floor, the others are
    walls, each on the side of the bin its thin direction points to. ConfigError if it is not such a bin."""
    boxes = []
    for s in read_fixture_shapes(urdf):
        if s.kind != "box":
            raise ConfigError(f"{urdf}: a bin is made of boxes, found a {s.kind}")
        half = np.abs(s.pose[:3, :3]) @ (np.asarray(s.size, dtype=float) / 2.0)
        boxes.append((s.pose[:3, 3], half))
    if len(boxes) < 5:
        raise ConfigError(f"{urdf}: a bin needs a floor and four walls, found {len(boxes)} boxes")
    outer_lo = np.min([c - h for c, h in boxes], axis=0)
    outer_hi = np.max([c + h for c, h in boxes], axis=0)
    mid = (outer_lo + outer_hi) / 2.0
    k_floor = max(range(len(boxes)), key=lambda k: (boxes[k][1][0] * boxes[k][1][1], -boxes[k][0][2]))
    floor_c, floor_h = boxes[k_floor]
    walls = [b for k, b in enumerate(boxes) if k != k_floor]
    inner_lo, inner_hi = outer_lo.copy(), outer_hi.copy()
    for axis in (0, 1):
        other = 1 - axis
        side = [(c, h) for c, h in walls if h[axis] < h[other]]  # thin along `axis`: a wall facing it
        hi_faces = [c[axis] - h[axis] for c, h in side if c[axis] > mid[axis]]
        lo_faces = [c[axis] + h[axis] for c, h in side if c[axis] < mid[axis]]
        if not hi_faces or not lo_faces:
            raise ConfigError(f"{urdf}: no wall on both sides of the bin along {'xy'[axis]}")
        inner_lo[axis], inner_hi[axis] = max(lo_faces), min(hi_faces)
    inner_lo[2] = floor_c[2] + floor_h[2]
    inner_hi[2] = max(c[2] + h[2] for c, h in walls)
    return BinGeometry(name, np.asarray(pose, dtype=float), inner_lo, inner_hi, outer_lo, outer_hi)


def bin_geometries(settings: Settings) -> dict[str, BinGeometry]:
    """The bins the class-to-bin map names, by fixture name (a bin named there but missing is a KeyError
    later, reported per object)."""
    task = settings.task.robocup
    named = set(task.bins.values()) | {task.default_bin}
    return {
        f.name: read_bin_geometry(f.name, str(settings.resolve(f.urdf)), pose_from_xyz_rpy(f.position, f.rpy))
        for f in settings.world.fixtures
        if f.name in named
    }


def bin_for(cls: str, color: str | None, settings: Settings) -> str:
    """The fixture name of the bin for a class (a `cube_red`-style key wins over `cube`)."""
    bins = settings.task.robocup.bins
    if color and f"{cls}_{color}" in bins:
        return bins[f"{cls}_{color}"]
    return bins.get(cls, settings.task.robocup.default_bin)
