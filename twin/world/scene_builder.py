"""Building a `World`'s scene: the engine parameters and every body, from a config and a seed.

`build_scene` loads the UR5e with its gripper at the origin (the world frame IS the robot base frame), the
fixtures (table, bins, the ArUco base plate and its marker quad, obstacles), the objects where
`twin.scene_layout.sample_layout` puts them for the seed, the unmodelled obstacle, and the object physics
faults (`world.objects.mass_scale` / `friction_scale`). It returns a `BuiltScene`: the ids and indices the
stepper drives and reads. It always makes the same PyBullet calls in the same order for the same config
and seed, which is what makes two worlds (and a world and its `reset()`) evolve bit-identically.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twin.assets import marker_quad_obj
from twin.config import Settings
from twin.errors import ConfigError, WorldError
from twin.object_visuals import REALISTIC_CLASSES, VARIANTS, realistic_urdf
from twin.robot import Robot
from twin.scene_layout import (
    PLATE_SIZE_M,
    Placement,
    color_rgba,
    is_marker_plate,
    marker_pose_in_base,
    marker_quad_size_m,
    place_unmodelled_obstacle,
    sample_layout,
)
from twin.transforms import rpy_to_matrix
from twin.types import matrix_to_quat
from twin.world.bullet import URDF_FLAGS, pb
from twin.world.values import ARM_JOINT_NAMES, FINGER_JOINT_NAMES, FINGER_LINKS, physics_parts_missing

__all__ = ["BuiltScene", "build_scene"]

log = logging.getLogger("twin")

# `world.sleep_at_rest`: a body sleeps once |v|^2 + |w|^2 (m/s, rad/s) has stayed below this for Bullet's 2 s
_SLEEP_MOTION = 1e-5


@dataclass(frozen=True)
class BuiltScene:
    """What the builder hands the stepper: the bodies of one built scene and the robot's indices.

    `bodies`: every body by name ('robot', fixture names, object names, 'aruco_marker',
    'unmodelled_obstacle'); `objects`: the loose objects' body ids -> their placement, in config order;
    `arm` / `fingers`: the PyBullet joint indices of ARM_JOINT_NAMES / FINGER_JOINT_NAMES.
    """

    robot_id: int
    joint_index: dict[str, int]
    link_index: dict[str, int]
    arm: list[int]
    fingers: list[int]
    bodies: dict[str, int]
    fixtures: dict[str, int]
    objects: dict[int, Placement]
    marker_id: int | None
    unmodelled_obstacle_centre: tuple[float, float, float] | None  # ground truth; it is static
    object_scales: dict[str, dict[str, float]]  # object name -> knob ('mass', 'friction') -> factor drawn


def build_scene(client_id: int, settings: Settings, seed: int, dt: float, robot: Robot) -> BuiltScene:
    """Engine parameters and every body, always by the same call sequence (determinism, reset).

    The client must be freshly connected or reset (no bodies yet); the renderer plugin, if any, is loaded
    before (bodies created earlier render blank). `robot`: the config's robot (its URDF, read once)."""
    return _SceneBuilder(client_id, settings, seed, robot).build(dt)


class _SceneBuilder:
    """One scene being built: the bodies so far (one builder per build)."""

    def __init__(self, client_id: int, settings: Settings, seed: int, robot: Robot) -> None:
        self._cid = client_id
        self.settings = settings
        self.robot = robot
        self.seed = seed
        self._bodies: dict[str, int] = {}
        self._fixtures: dict[str, int] = {}
        self._objects: dict[int, Placement] = {}
        self._marker_id: int | None = None
        self.unmodelled_obstacle_centre: tuple[float, float, float] | None = None

    def build(self, dt: float) -> BuiltScene:
        c = self._cid
        pb.setPhysicsEngineParameter(
            fixedTimeStep=dt, numSubSteps=0, deterministicOverlappingPairs=1, physicsClientId=c
        )
        pb.setGravity(0.0, 0.0, self.settings.world.gravity, physicsClientId=c)
        self._load_robot()
        for fx in self.settings.world.fixtures:
            self._load_fixture(fx.name, fx.urdf, fx.position, fx.rpy)
            if is_marker_plate(fx):
                self._add_marker_quad()
        objects = self.settings.world.objects
        wants_boxes = any(spec.count for spec in objects.items) or self.settings.world.unmodelled_obstacle is not None
        boxes = self._obstacle_boxes() if wants_boxes else []
        placements = sample_layout(objects, self.seed, boxes)
        looks = self._looks(placements)
        for sp in placements:
            self._load_object(sp, looks.get(sp.name))
        centre = place_unmodelled_obstacle(self.settings.world, self.seed, placements, boxes)
        if centre is not None:
            self._add_unmodelled_obstacle(centre)
        object_scales = self._vary_object_physics()
        return BuiltScene(
            robot_id=self.robot_id,
            joint_index=self._joint_index,
            link_index=self._link_index,
            arm=self._arm,
            fingers=self._fingers,
            bodies=self._bodies,
            fixtures=self._fixtures,
            objects=self._objects,
            marker_id=self._marker_id,
            unmodelled_obstacle_centre=self.unmodelled_obstacle_centre,
            object_scales=object_scales,
        )

    def _urdf(self, path: str) -> str:
        p = self.settings.resolve(path)
        if not p.is_file():
            raise ConfigError(f"URDF not found: {path} (resolved to {p})")
        return str(p)

    def _load_robot(self) -> None:
        c = self._cid
        urdf = self._urdf(self.settings.robot.urdf)
        model = self.robot.urdf_model
        missing = physics_parts_missing(model)
        if missing:  # a collision model without twin's gripper plans (`execute: false`) but cannot run physics
            raise WorldError(f"robot URDF {self.settings.robot.urdf} lacks joints/links {missing} the physics needs")
        # where the arm's base is the world origin: the URDF's root (a root above the arm: `URArm.urdf_base`)
        root = self.robot.urdf_base
        try:
            self.robot_id = pb.loadURDF(
                urdf,
                root[:3, 3].tolist(),
                [0, 0, 0, 1] if np.array_equal(root, np.eye(4)) else matrix_to_quat(root[:3, :3]).tolist(),
                useFixedBase=True,
                flags=URDF_FLAGS,
                physicsClientId=c,
            )
        except pb.error as e:
            raise WorldError(f"cannot load robot URDF {self.settings.robot.urdf}: {e}") from None
        self._bodies["robot"] = self.robot_id
        self._joint_index: dict[str, int] = {}
        self._link_index: dict[str, int] = {model.root: -1}
        for j in range(pb.getNumJoints(self.robot_id, physicsClientId=c)):
            info = pb.getJointInfo(self.robot_id, j, physicsClientId=c)
            self._joint_index[info[1].decode()] = j
            self._link_index[info[12].decode()] = j
        self._arm = [self._joint_index[n] for n in ARM_JOINT_NAMES]
        self._fingers = [self._joint_index[n] for n in FINGER_JOINT_NAMES]
        for link in FINGER_LINKS:
            # friction anchors stop the slow creep of a friction grip under gravity
            pb.changeDynamics(
                self.robot_id,
                self._link_index[link],
                lateralFriction=self.settings.gripper.finger_friction,
                frictionAnchor=1,
                physicsClientId=c,
            )

    def _load_fixture(self, name: str, urdf: str, position: Sequence[float], rpy: Sequence[float]) -> None:
        c = self._cid
        try:
            bid = pb.loadURDF(
                self._urdf(urdf),
                list(position),
                pb.getQuaternionFromEuler(list(rpy)),
                useFixedBase=True,
                flags=URDF_FLAGS,
                physicsClientId=c,
            )
        except pb.error as e:
            raise WorldError(f"cannot load fixture {name!r} from {urdf}: {e}") from None
        if name in self._bodies:
            raise ConfigError(f"fixture name {name!r} clashes with another body name")
        self._fixtures[name] = bid
        self._bodies[name] = bid

    def _add_unmodelled_obstacle(self, centre: tuple[float, float, float]) -> None:
        """`world.unmodelled_obstacle`: a static grey box at `centre`, body name "unmodelled_obstacle"."""
        c = self._cid
        cfg = self.settings.world.unmodelled_obstacle
        assert cfg is not None
        half = [v / 2.0 for v in cfg.size_m]
        col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=c)
        vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=[0.45, 0.45, 0.5, 1.0], physicsClientId=c)
        bid = pb.createMultiBody(0.0, col, vis, list(centre), physicsClientId=c)
        self._bodies["unmodelled_obstacle"] = bid
        self.unmodelled_obstacle_centre = centre

    def _add_marker_quad(self) -> None:
        """The marker: a visual-only textured quad on the plate's top face (pose: scene_layout)."""
        c = self._cid
        side = marker_quad_size_m(self.settings.aruco.size_m)
        if side > PLATE_SIZE_M:
            log.warning(
                "ArUco quad (%.3f m with its white border) is wider than the plate (%.3f m)", side, PLATE_SIZE_M
            )
        obj = marker_quad_obj(self.settings.aruco)  # generated once, in the cache directory
        vs = pb.createVisualShape(pb.GEOM_MESH, fileName=str(obj), meshScale=[side, side, 1.0], physicsClientId=c)
        if vs < 0:
            raise WorldError(f"could not load the marker quad {obj}")
        T = marker_pose_in_base(self.settings)
        quat = matrix_to_quat(T[:3, :3])
        self._marker_id = pb.createMultiBody(
            baseMass=0,
            baseCollisionShapeIndex=-1,
            baseVisualShapeIndex=vs,
            basePosition=T[:3, 3].tolist(),
            baseOrientation=quat.tolist(),
            physicsClientId=c,
        )
        self._bodies["aruco_marker"] = self._marker_id

    def _obstacle_boxes(self) -> list[tuple[Sequence[float], Sequence[float]]]:
        """Axis-aligned boxes (min, max) of the robot base and every link of every fixture, for the layout."""
        c = self._cid
        boxes = [pb.getAABB(self.robot_id, -1, physicsClientId=c)]
        for bid in self._fixtures.values():
            boxes.extend(
                pb.getAABB(bid, link, physicsClientId=c) for link in range(-1, pb.getNumJoints(bid, physicsClientId=c))
            )
        return boxes

    def _looks(self, placements: Sequence[Placement]) -> dict[str, int]:
        """With `world.visuals: realistic`, each object of a class with realistic looks gets one of
        `VARIANTS`, drawn from the scene seed in config order (a stream of its own: the layout's draws and the
        physics do not change); {} when the visuals are flat."""
        if self.settings.world.visuals != "realistic":
            return {}
        rng = np.random.default_rng([self.seed, 42])
        return {sp.name: int(rng.integers(VARIANTS)) for sp in placements if sp.template.cls in REALISTIC_CLASSES}

    def _load_object(self, sp: Placement, look: int | None) -> None:
        c = self._cid
        R = rpy_to_matrix((0.0, 0.0, sp.yaw))
        if sp.lying:
            R = R @ rpy_to_matrix(sp.template.lying_rpy)
        urdf = self._urdf(sp.template.urdf)
        if look is not None:
            urdf = str(realistic_urdf(sp.template.cls, look, Path(urdf)))
        try:
            bid = pb.loadURDF(
                urdf,
                list(sp.position),
                matrix_to_quat(R).tolist(),
                flags=URDF_FLAGS,
                physicsClientId=c,
            )
        except pb.error as e:
            raise WorldError(f"cannot load object {sp.name!r} from {sp.template.urdf}: {e}") from None
        if sp.name in self._bodies:
            raise ConfigError(f"object name {sp.name!r} clashes with a fixture name")
        if sp.color is not None:
            pb.changeVisualShape(bid, -1, rgbaColor=list(color_rgba(sp.color)), physicsClientId=c)
        if self.settings.world.sleep_at_rest:
            pb.changeDynamics(
                bid,
                -1,
                activationState=pb.ACTIVATION_STATE_ENABLE_SLEEPING,
                sleepThreshold=_SLEEP_MOTION,
                physicsClientId=c,
            )
        self._objects[bid] = sp
        self._bodies[sp.name] = bid

    def _vary_object_physics(self) -> dict[str, dict[str, float]]:
        """Each object's mass (and inertia) and friction times a factor drawn uniformly from
        `world.objects.mass_scale` / `friction_scale`, per object in config order, from the scene seed (one
        stream per knob, so switching one on leaves the other's draws alone). A fault model: the catalogue
        the task knows is unchanged, and at [1, 1] nothing is drawn or changed. Returns the factors drawn
        (`World.object_scales`)."""
        cfg, c = self.settings.world.objects, self._cid
        object_scales: dict[str, dict[str, float]] = {sp.name: {} for sp in self._objects.values()}
        for stream, (lo, hi), knob in ((1, cfg.mass_scale, "mass"), (2, cfg.friction_scale, "friction")):
            if lo == hi == 1.0:
                continue
            rng = np.random.default_rng([self.seed, 0x0B1E, stream])
            for bid, sp in self._objects.items():
                f = float(rng.uniform(lo, hi))
                info = pb.getDynamicsInfo(bid, -1, physicsClientId=c)
                if knob == "mass":
                    inertia = [f * v for v in info[2]]
                    pb.changeDynamics(bid, -1, mass=f * info[0], localInertiaDiagonal=inertia, physicsClientId=c)
                else:
                    pb.changeDynamics(bid, -1, lateralFriction=f * info[1], physicsClientId=c)
                object_scales[sp.name][knob] = f
        return object_scales
