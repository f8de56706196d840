"""Seeded warehouse transfer scenes for testing and benchmarking `nmpc`, and an independent FCL check.

A scene (seeds 000/001): the warehouse cell with the blue obstacle wall at a random place in front of the
pick area, its perceived box (the true AABB with a few mm of perception error, extended by 0.5 m in +-y)
added to the planning scene, a 50 mm cube held in the closed gripper, a random start with the tool facing
down on one side of the wall and a drop (or pick) pose on the other side, as a pose goal or (one in five)
a joint goal. Starts and goals are valid: reachable, collision-free, proxy spheres clear of the box.

Why here and not in tests: the test and the benchmark must run exactly the same 50 scenes.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import fcl
import numpy as np

from twin.plugin import (
    BoxBounds,
    MotionRequest,
    PlanningScene,
    Pose,
    PoseGoal,
    Settings,
    Trajectory,
    URArm,
    densify,
    limits_from_settings,
    load_config,
)

__all__ = [
    "CUBE_SIZE_M",
    "GOAL_TOLERANCE_M",
    "TrajectoryCheck",
    "TransferScene",
    "build_scene",
    "check_trajectory",
    "transfer_scenes",
]

CUBE_SIZE_M = 0.05
GOAL_TOLERANCE_M = 0.03  # SPEC: the seed's NMPC stops within 3 cm of the goal
_OBSTACLE_SIZE = np.array([0.12, 0.30, 0.20])
_EXTENSION_Y_M = 0.5
_PERCEIVED = "perceived_obstacle"
_END_CLEARANCE_M = 0.05


@dataclass(frozen=True, eq=False)
class TransferScene:
    """One seeded transfer: the obstacle's true centre, its perceived (extended) box, the request."""

    index: int
    obstacle_center: np.ndarray
    perceived_box: BoxBounds
    request: MotionRequest
    direction: str  # "over_out": pick side -> drop side; "over_in": the way back
    T_tcp_cube: np.ndarray


def _down(yaw: float) -> np.ndarray:
    """Rotation of a tool facing down (tool z = -world z), turned by `yaw` about world z."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])


def _cell(settings: Settings, obstacle_center: np.ndarray | None, *, only: tuple[str, ...] | None = None) -> Settings:
    """The config with its obstacle wall moved to `obstacle_center` and made a known fixture (the scene that
    checks a run holds the true wall; the planner sees only the perceived box), keeping only the fixtures
    named in `only` (None: all)."""
    fixtures = []
    for f in settings.world.fixtures:
        if f.name == "obstacle" and obstacle_center is not None:
            f = f.model_copy(update={"position": tuple(obstacle_center), "known": True})
        if only is None or f.name in only:
            fixtures.append(f)
    return settings.model_copy(update={"world": settings.world.model_copy(update={"fixtures": fixtures})})


def build_scene(
    settings: Settings, ts: TransferScene, *, with_fixtures: bool = True, holding: bool = True
) -> PlanningScene:
    """The FCL planning scene of `ts`: the cell with the obstacle moved to its place, the perceived box,
    the cube held in the gripper (closed on it). `with_fixtures=False` keeps the table only."""
    scene = PlanningScene.from_settings(_cell(settings, ts.obstacle_center, only=None if with_fixtures else ("table",)))
    if with_fixtures:
        b = ts.perceived_box
        scene.add_box_bounds(_PERCEIVED, b.lo, b.hi)
    scene.set_gripper_opening(CUBE_SIZE_M)
    if holding:
        scene.attach_box("cube", (CUBE_SIZE_M,) * 3, ts.T_tcp_cube)
    return scene


def _ik_near(kin: URArm, T: np.ndarray, ref: np.ndarray) -> np.ndarray | None:
    sols = kin.ik(T, "tcp")
    if sols.shape[0] == 0:
        return None
    return sols[int(np.argmin(np.abs(sols - ref).max(axis=1)))]


def _box_only_scene(settings: Settings, ts: TransferScene, cache: dict[str, PlanningScene]) -> PlanningScene:
    """The arm holding the cube, with only the perceived box (one scene reused: the box is replaced)."""
    scene = cache.get("scene")
    if scene is None:
        scene = PlanningScene.from_settings(_cell(settings, None, only=()))
        scene.set_gripper_opening(CUBE_SIZE_M)
        cache["scene"] = scene
    if scene.attached is not None:
        scene.detach()
    scene.attach_box("cube", (CUBE_SIZE_M,) * 3, ts.T_tcp_cube)
    b = ts.perceived_box
    scene.add_box_bounds(_PERCEIVED, b.lo, b.hi)
    return scene


def transfer_scenes(n: int = 50, seed: int = 0, *, settings: Settings | None = None) -> list[TransferScene]:
    """`n` seeded transfer scenes over the obstacle wall (deterministic for a given seed)."""
    settings = settings or load_config("warehouse")
    kin = URArm(model=settings.robot.model)
    limits = limits_from_settings(settings)
    home = np.array(settings.robot.home)
    rng = np.random.default_rng(seed)
    out: list[TransferScene] = []
    boxes_only_cache: dict[str, PlanningScene] = {}
    while len(out) < n:
        oc = np.array([rng.uniform(-0.45, -0.40), rng.uniform(-0.05, 0.25), 0.10])
        lo, hi = oc - _OBSTACLE_SIZE / 2, oc + _OBSTACLE_SIZE / 2
        noise = rng.uniform(-0.005, 0.005, 6)
        box = BoxBounds(
            lo[0] + noise[0], hi[0] + noise[1], lo[1] + noise[2], hi[1] + noise[3], 0.0, hi[2] + abs(noise[5])
        )
        box = box.extended_y(_EXTENSION_Y_M)
        pick = np.array([rng.uniform(lo[0] - 0.17, lo[0] - 0.08), rng.uniform(0.0, 0.30), rng.uniform(0.05, 0.12)])
        drop = np.array([rng.uniform(hi[0] + 0.08, -0.22), rng.uniform(-0.25, 0.30), rng.uniform(0.06, 0.12)])
        out_dir = rng.uniform() < 0.7
        a, b = (pick, drop) if out_dir else (drop, pick)
        yaw_a, yaw_b = rng.uniform(-math.pi, math.pi, 2)
        joint_goal = rng.uniform() < 0.2
        cube_yaw = rng.uniform(-0.3, 0.3)
        Ta, Tb = np.eye(4), np.eye(4)
        Ta[:3, :3], Ta[:3, 3] = _down(yaw_a), a
        Tb[:3, :3], Tb[:3, 3] = _down(yaw_b), b
        q_start = _ik_near(kin, Ta, home)
        if q_start is None:
            continue
        q_goal = _ik_near(kin, Tb, q_start)
        if q_goal is None:
            continue
        T_cube = np.eye(4)
        T_cube[:3, :3] = np.array(
            [[math.cos(cube_yaw), -math.sin(cube_yaw), 0], [math.sin(cube_yaw), math.cos(cube_yaw), 0], [0, 0, 1]]
        )
        # NMPC reaches positions (orientation free) within 3 cm; `joint_goal` is still drawn so that the
        # scenes stay the ones measured before goals carried their tolerances
        del joint_goal
        goal = PoseGoal(Pose.from_matrix(Tb), position_tolerance_m=GOAL_TOLERANCE_M, orientation_tolerance_rad=None)
        ts = TransferScene(
            len(out),
            oc,
            box,
            MotionRequest(q_start, goal, limits, seed=seed * 1000 + len(out)),
            "over_out" if out_dir else "over_in",
            T_cube,
        )
        # valid ends: the whole arm and the cube clear the perceived box by >= 5 cm and nothing collides
        box_only = _box_only_scene(settings, ts, boxes_only_cache)
        if min(box_only.min_distance(q, include_self=False).distance for q in (q_start, q_goal)) < _END_CLEARANCE_M:
            continue
        checker = build_scene(settings, ts)
        if checker.in_collision(q_start) or checker.in_collision(q_goal):
            continue
        out.append(ts)
    return out


@dataclass(frozen=True)
class TrajectoryCheck:
    """Independent FCL verdict on an executed trajectory: proxy spheres vs the perceived box, robot and
    held cube vs the table (signed distances, m; > 0 is clear)."""

    samples: int
    min_sphere_box_m: float
    min_table_m: float

    @property
    def ok(self) -> bool:
        return self.min_sphere_box_m > 0.0 and self.min_table_m > 0.0


def check_trajectory(
    traj: Trajectory,
    ts: TransferScene,
    spheres_fn: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    table_scene: PlanningScene,
    kin: URArm,
) -> TrajectoryCheck:
    """Densify `traj` (<= 0.01 rad, <= 5 mm of TCP travel between samples) and measure with FCL: every
    proxy sphere (`spheres_fn(qs) -> (centres (m, n, 3), radii (n,))`) against the perceived box, and the
    robot + held cube against a table-only scene."""
    qs = densify(traj, kin, max_step_rad=0.01, max_step_m=0.005)
    centres, radii = spheres_fn(qs)
    b = ts.perceived_box
    box = fcl.CollisionObject(fcl.Box(*(b.hi - b.lo)), fcl.Transform(0.5 * (b.lo + b.hi)))
    req, best = fcl.DistanceRequest(enable_signed_distance=True), math.inf
    spheres = [fcl.CollisionObject(fcl.Sphere(float(r))) for r in radii]
    for frame in centres:
        for obj, c in zip(spheres, frame, strict=True):
            obj.setTranslation(c)
            res = fcl.DistanceResult()
            d = fcl.distance(obj, box, req, res)
            if d < best:
                best = d
    table = float(table_scene.min_distance_batch(qs, include_self=False).min())
    return TrajectoryCheck(qs.shape[0], float(best), table)
