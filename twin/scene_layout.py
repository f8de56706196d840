"""Nominal scene geometry, without PyBullet: object templates, colours, the ArUco marker pose, and where
the objects of a seed are placed.

Perception, planning and tests need to know what the world builds (object dimensions, where the base
marker is) without importing the simulator; `twin.world` builds the scene from these same numbers, so
the two cannot drift apart. The layout (`sample_layout`) is pure too: given the config, the seed and the
boxes the objects must keep clear of (the world measures those in the simulator), it returns the same
placements every time.

Frames: the world frame is the robot base frame (z up, table top at z = 0). Every object's frame has
its origin at the object's geometric centre; cylinders have their axis along the object's z axis.

The ArUco base plate is a fixture whose URDF is `urdf/aruco_plate.urdf` (`ARUCO_PLATE_URDF`). Its
frame is the centre of the plate's underside; the marker lies flat on its top face. The marker frame is
OpenCV's (`SOLVEPNP_IPPE_SQUARE` object points): origin at the marker centre, x towards the marker
image's right edge, y towards its top edge, z out of the plate. With the plate's rpy = 0 these axes are
the world's x, y, z, i.e. the image's top edge faces +y and its right edge faces +x.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import PurePosixPath
from typing import Literal

import numpy as np

from twin.config import FixtureSettings, ObjectSettings, Settings, WorldSettings
from twin.errors import ConfigError, WorldError
from twin.transforms import pose_from_xyz_rpy

__all__ = [
    "ARUCO_PLATE_URDF",
    "COLORS",
    "MARKER_LIFT_M",
    "MARKER_MARGIN_FRACTION",
    "OBJECT_TEMPLATES",
    "PLATE_SIZE_M",
    "PLATE_THICKNESS_M",
    "ObjectTemplate",
    "Placement",
    "color_rgba",
    "find_marker_plate",
    "is_marker_plate",
    "keepout_rects",
    "marker_corners_in_base",
    "marker_pose_in_base",
    "marker_quad_size_m",
    "place_unmodelled_obstacle",
    "sample_layout",
]


@dataclass(frozen=True)
class ObjectTemplate:
    """One object class: primitive shape, size in its own frame (m), URDF, mass (kg).

    `size` is (x, y, z) extents standing upright; for cylinders (diameter, diameter, height).
    `lying_rpy` turns the upright object onto the face/side it lies on ("lying" in the SPEC's sense).
    """

    cls: str
    shape: Literal["box", "cylinder"]
    size: tuple[float, float, float]
    urdf: str
    mass_kg: float
    lying_rpy: tuple[float, float, float] = (math.pi / 2, 0.0, 0.0)

    def extents(self, lying: bool) -> tuple[float, float, float]:
        """(x, y, z) extents of the axis-aligned box around the object in its yawed placement frame."""
        sx, sy, sz = self.size
        return (sx, sz, sy) if lying else (sx, sy, sz)  # lying = +90 deg about x: y and z swap

    def height(self, lying: bool) -> float:
        """Height of the object's top above the table when resting (m)."""
        return self.extents(lying)[2]

    def footprint_radius(self, lying: bool) -> float:
        """Radius of a circle around the object's footprint on the table (m), any yaw."""
        ex, ey, _ = self.extents(lying)
        if self.shape == "cylinder" and not lying:
            return ex / 2.0
        return math.hypot(ex, ey) / 2.0


# SPEC dimensions (mm): bottle d68 x 197, can d66 x 117, spam 102 x 60 x 83, cube 75, marker d21 x 121;
# warehouse cubes 50 mm; the warehouse obstacle is a blue box.
OBJECT_TEMPLATES: dict[str, ObjectTemplate] = {
    "bottle": ObjectTemplate("bottle", "cylinder", (0.068, 0.068, 0.197), "urdf/objects/bottle.urdf", 0.30),
    "can": ObjectTemplate("can", "cylinder", (0.066, 0.066, 0.117), "urdf/objects/can.urdf", 0.35),
    "spam": ObjectTemplate("spam", "box", (0.102, 0.060, 0.083), "urdf/objects/spam.urdf", 0.34),
    "cube": ObjectTemplate("cube", "box", (0.075, 0.075, 0.075), "urdf/objects/cube75.urdf", 0.20),
    "marker": ObjectTemplate("marker", "cylinder", (0.021, 0.021, 0.121), "urdf/objects/marker.urdf", 0.015),
    "warehouse_cube": ObjectTemplate(
        "warehouse_cube", "box", (0.05, 0.05, 0.05), "urdf/objects/warehouse_cube.urdf", 0.06
    ),
    "obstacle": ObjectTemplate("obstacle", "box", (0.12, 0.30, 0.20), "urdf/objects/obstacle.urdf", 3.0),
}

# Saturated colours, easy to tell apart by average RGB (the warehouse perception labels by colour).
COLORS: dict[str, tuple[float, float, float, float]] = {
    "red": (0.85, 0.08, 0.08, 1.0),
    "green": (0.08, 0.65, 0.15, 1.0),
    "blue": (0.08, 0.20, 0.85, 1.0),
    "yellow": (0.95, 0.85, 0.08, 1.0),
    "black": (0.04, 0.04, 0.04, 1.0),
    "white": (0.95, 0.95, 0.95, 1.0),
    "orange": (0.95, 0.50, 0.05, 1.0),
    "purple": (0.50, 0.12, 0.65, 1.0),
    "grey": (0.50, 0.50, 0.50, 1.0),
}

ARUCO_PLATE_URDF = "urdf/aruco_plate.urdf"
PLATE_SIZE_M = 0.16  # square plate side, must match urdf/aruco_plate.urdf
PLATE_THICKNESS_M = 0.004  # must match urdf/aruco_plate.urdf
MARKER_LIFT_M = 0.0005  # the textured quad floats this far above the plate top (no z-fighting)
MARKER_MARGIN_FRACTION = 0.2  # white quiet zone on each side, as a fraction of the marker side


def color_rgba(name: str) -> tuple[float, float, float, float]:
    """RGBA of a colour name from the config; ConfigError listing the known names otherwise."""
    try:
        return COLORS[name.lower()]
    except KeyError:
        raise ConfigError(f"unknown colour {name!r}; known colours: {', '.join(sorted(COLORS))}") from None


def is_marker_plate(fixture: FixtureSettings) -> bool:
    """True for the fixture that carries the ArUco marker (its URDF is the plate's)."""
    return PurePosixPath(fixture.urdf.replace("\\", "/")).name == PurePosixPath(ARUCO_PLATE_URDF).name


def find_marker_plate(settings: Settings) -> FixtureSettings | None:
    """The marker plate fixture of the config, or None when the scene has no marker."""
    plates = [f for f in settings.world.fixtures if is_marker_plate(f)]
    if len(plates) > 1:
        raise ConfigError(f"only one ArUco plate fixture is supported, found {[f.name for f in plates]}")
    return plates[0] if plates else None


def marker_pose_in_base(settings: Settings) -> np.ndarray:
    """(4, 4) nominal pose of the ArUco marker frame (OpenCV convention) in the base frame.

    Raises ConfigError when the config has no fixture with `urdf: urdf/aruco_plate.urdf`.
    """
    plate = find_marker_plate(settings)
    if plate is None:
        raise ConfigError(f"the config has no ArUco plate fixture (a fixture with urdf: {ARUCO_PLATE_URDF})")
    lift = np.eye(4)
    lift[2, 3] = PLATE_THICKNESS_M + MARKER_LIFT_M
    return pose_from_xyz_rpy(plate.position, plate.rpy) @ lift


def marker_corners_in_base(settings: Settings) -> np.ndarray:
    """(4, 3) nominal marker corners (black square) in the base frame, OpenCV order TL, TR, BR, BL."""
    s = settings.aruco.size_m / 2.0
    local = np.array([[-s, s, 0.0, 1.0], [s, s, 0.0, 1.0], [s, -s, 0.0, 1.0], [-s, -s, 0.0, 1.0]])
    return (marker_pose_in_base(settings) @ local.T).T[:, :3]


def marker_quad_size_m(marker_size_m: float) -> float:
    """Side of the textured quad: the marker plus its white quiet zone on both sides (m)."""
    return marker_size_m * (1.0 + 2.0 * MARKER_MARGIN_FRACTION)


# ---- object layout -------------------------------------------------------------------------------
LAYOUT_ATTEMPTS = 50  # whole-scene restarts before giving up
TRIES_PER_OBJECT = 300  # position draws per object within one attempt
UNMODELLED_NEARBY_M = 0.15  # how far beside the objects' region an unmodelled box may stand (no region of its own)
KEEPOUT_MIN_TOP_M = 0.002  # bodies whose top is above this are obstacles for spawning (the table is not)

Aabb = tuple[Sequence[float], Sequence[float]]  # (min xyz, max xyz), base frame, m
Rect = tuple[float, float, float, float]  # (x0, y0, x1, y1), base frame, m


@dataclass(frozen=True)
class Placement:
    """Where one object of the config starts: its name (`<class>[_<colour>]_<i>`), template, colour,
    centre position (m, base frame; resting on the table at z = 0), yaw about z (rad), lying or upright."""

    name: str
    template: ObjectTemplate
    color: str | None
    position: tuple[float, float, float]
    yaw: float
    lying: bool


def _circle_hits_rect(cx: float, cy: float, r: float, rect: Rect) -> bool:
    x0, y0, x1, y1 = rect
    dx = max(x0 - cx, 0.0, cx - x1)
    dy = max(y0 - cy, 0.0, cy - y1)
    return dx * dx + dy * dy < r * r


def keepout_rects(boxes: Sequence[Aabb], gap: float) -> list[Rect]:
    """xy rectangles objects must not touch: each box whose top is above the table (the robot base, bins,
    the marker plate, obstacles; not the table itself), grown by `gap` on every side."""
    rects = []
    for lo, hi in boxes:
        if hi[2] > KEEPOUT_MIN_TOP_M:
            rects.append((lo[0] - gap, lo[1] - gap, hi[0] + gap, hi[1] + gap))
    return rects


def place_unmodelled_obstacle(
    world: WorldSettings, seed: int, placements: Sequence[Placement], obstacles: Sequence[Aabb] = ()
) -> tuple[float, float, float] | None:
    """The centre of `world.unmodelled_obstacle` (None when off): drawn from its own stream of the scene
    seed (the objects' placements are the same with or without it), its footprint circle clear of every
    object's and of the fixtures (`obstacles`, as for `sample_layout`). WorldError when it does not fit."""
    cfg = world.unmodelled_obstacle
    if cfg is None:
        return None
    objs = world.objects
    (x0, x1), (y0, y1) = cfg.region_x or objs.region_x, cfg.region_y or objs.region_y
    gap = objs.min_gap_m if cfg.min_gap_m is None else cfg.min_gap_m
    r = math.hypot(cfg.size_m[0], cfg.size_m[1]) / 2.0
    keepouts = keepout_rects(obstacles, gap)
    circles = [(p.position[0], p.position[1], p.template.footprint_radius(p.lying)) for p in placements]
    rng = np.random.default_rng([seed, 0x0B57])
    # no region given and the objects leave no room in theirs (the warehouse's cubes fill a 11 x 24 cm
    # region): the box stands beside them, within UNMODELLED_NEARBY_M of their region
    grow = (0.0,) if cfg.region_x or cfg.region_y else (0.0, UNMODELLED_NEARBY_M)
    for g in grow:
        for _ in range(TRIES_PER_OBJECT * LAYOUT_ATTEMPTS):
            x, y = float(rng.uniform(x0 - g, x1 + g)), float(rng.uniform(y0 - g, y1 + g))
            if any(_circle_hits_rect(x, y, r, k) for k in keepouts):
                continue
            if all(math.hypot(x - px, y - py) >= r + pr + gap for px, py, pr in circles):
                return (x, y, cfg.size_m[2] / 2.0)
    raise WorldError(
        f"cannot place world.unmodelled_obstacle (size {list(cfg.size_m)}) clear of the objects in region "
        f"x={[x0, x1]} y={[y0, y1]} with a gap of {gap} m; make it smaller or give it a region"
    )


def sample_layout(objects: ObjectSettings, seed: int, obstacles: Sequence[Aabb] = ()) -> list[Placement]:
    """Seeded, non-overlapping placements of `objects.items` in the spawn region, in config order.

    `obstacles`: axis-aligned boxes (min, max) of the bodies already in the scene; objects keep
    `min_gap_m` from each one that stands above the table and from each other. The same arguments give
    the same placements, bit for bit. Raises ConfigError for an unknown colour and WorldError when the
    region is too crowded to place every object.
    """
    cfg = objects
    rng = np.random.default_rng(seed)
    todo: list[tuple[str, ObjectTemplate, str | None, bool, float]] = []
    used: dict[str, int] = {}
    for spec in cfg.items:
        tmpl = OBJECT_TEMPLATES[spec.cls]
        if spec.color is not None:
            color_rgba(spec.color)  # ConfigError for an unknown colour, before anything is placed
        for _ in range(spec.count):
            base = f"{spec.cls}_{spec.color}" if spec.color else spec.cls
            name = f"{base}_{used.get(base, 0)}"
            used[base] = used.get(base, 0) + 1
            lying = bool(rng.random() < cfg.lying_probability) and spec.cls != "obstacle"
            yaw = float(rng.uniform(-math.pi, math.pi)) if cfg.random_yaw else 0.0
            todo.append((name, tmpl, spec.color, lying, yaw))
    if not todo:
        return []
    (x0, x1), (y0, y1) = cfg.region_x, cfg.region_y
    gap = cfg.min_gap_m
    keepouts = keepout_rects(obstacles, gap)
    radii = [t[1].footprint_radius(t[3]) for t in todo]
    order = sorted(range(len(todo)), key=lambda i: -radii[i])  # big ones first
    for _attempt in range(LAYOUT_ATTEMPTS):
        placed: dict[int, tuple[float, float]] = {}
        for i in order:
            r = radii[i]
            for _try in range(TRIES_PER_OBJECT):
                x, y = float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1))
                if any(_circle_hits_rect(x, y, r, k) for k in keepouts):
                    continue
                if all(math.hypot(x - px, y - py) >= r + radii[j] + gap for j, (px, py) in placed.items()):
                    placed[i] = (x, y)
                    break
            else:
                break
        if len(placed) == len(todo):
            out = []
            for i, (name, tmpl, color, lying, yaw) in enumerate(todo):
                x, y = placed[i]
                out.append(Placement(name, tmpl, color, (x, y, tmpl.height(lying) / 2.0), yaw, lying))
            return out
    worst = max(range(len(todo)), key=lambda i: radii[i])
    raise WorldError(
        f"cannot place {len(todo)} objects without overlap in region x={list(cfg.region_x)} "
        f"y={list(cfg.region_y)} with min_gap_m={gap} after {LAYOUT_ATTEMPTS} attempts "
        f"(largest footprint radius {radii[worst]:.3f} m: {todo[worst][0]}); enlarge the region, "
        "lower the counts, the gap or lying_probability, or move fixtures out of the region"
    )
