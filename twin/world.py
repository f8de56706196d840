"""The simulated cell: the one module of twin that imports PyBullet.

A `World` owns one PyBullet physics client (DIRECT unless a GUI is asked for) and builds the scene of a
config: the UR5e with its gripper at the origin (the world frame IS the robot base frame), the fixtures
(table, bins, the ArUco base plate, obstacles) and the objects, placed where
`twin.scene_layout.sample_layout` puts them for the seed (in the spawn region, without overlap). It
drives the arm by joint position control at the physics rate and the gripper by force-limited closing,
and it exposes ground truth for metrics and tests only. URDFs are found by `Settings.resolve`; the
marker's texture is generated once by `twin.assets` into the cache directory.

Determinism: every PyBullet call passes this world's client id, overlapping pairs are processed in a
deterministic order, and the scene is built by the same call sequence for the same config and seed, so
two worlds given the same calls produce bit-identical states. `reset()` rebuilds the scene the same way
(a restored snapshot would keep solver caches and drift by ~40 um).

Grasping is physical: the fingers squeeze the object and friction holds it; nothing is attached.
"""

from __future__ import annotations

import importlib.util
import logging
import math
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from twin.assets import marker_quad_obj
from twin.config import Settings
from twin.kinematics import JOINT_NAMES, URArm
from twin.types import matrix_to_quat

if TYPE_CHECKING:
    from twin.camera import Intrinsics, RGBDFrame
from twin.errors import ConfigError, InvalidRequestError, WorldError
from twin.scene_layout import (
    PLATE_SIZE_M,
    Placement,
    color_rgba,
    find_marker_plate,
    is_marker_plate,
    marker_pose_in_base,
    marker_quad_size_m,
    place_unmodelled_obstacle,
    sample_layout,
)
from twin.timing import stage
from twin.transforms import rpy_to_matrix
from twin.urdf_model import RobotModel

__all__ = [
    "ARM_JOINT_NAMES",
    "FINGER_JOINT_NAMES",
    "FINGER_TRAVEL_M",
    "ContactPoint",
    "ObjectState",
    "World",
    "WorldView",
    "marker_pose_in_base",
    "physics_parts_missing",
]

log = logging.getLogger("twin")

ARM_JOINT_NAMES = JOINT_NAMES
FINGER_JOINT_NAMES = ("left_finger_joint", "right_finger_joint")
FINGER_TRAVEL_M = 0.0425  # each finger, along tool0 x; the opening is the sum of both

_FINGER_LINKS = ("left_finger", "right_finger")


@dataclass(frozen=True)
class ObjectState:
    """Ground truth of one scene object (base frame, metres, quaternion x-y-z-w).

    `size` is the object's (x, y, z) extent in its own frame (cylinders: diameter, diameter, height);
    `lying` is true when the object's z axis is closer to horizontal than vertical.
    """

    id: int
    name: str
    cls: str
    color: str | None
    position: np.ndarray
    orientation_xyzw: np.ndarray
    lying: bool
    size: tuple[float, float, float]


@dataclass(frozen=True)
class ContactPoint:
    """One contact or closest-point pair between body A (link A) and body B (link B).

    Link -1 is a body's base. `distance` < 0 is penetration. `normal_on_b` points from B to A.
    """

    body_a: int
    body_b: int
    link_a: int
    link_b: int
    position_on_a: np.ndarray
    position_on_b: np.ndarray
    normal_on_b: np.ndarray
    distance: float
    normal_force: float


def _as_vec(x: Any, n: int, what: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.shape != (n,):
        raise InvalidRequestError(f"{what} must have shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InvalidRequestError(f"{what} must be finite, got {a.tolist()}")
    return a


def _flush_c_stdout() -> None:
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except Exception:  # noqa: BLE001 - not on every platform; then some noise may get through
        pass


@contextmanager
def _quiet_fds(*fds: int) -> Iterator[None]:
    """Silence C-level writes to these file descriptors (1: stdout, 2: stderr) while the block runs: PyBullet
    and its EGL plugin print banners from C (`printf`), which `sys.stdout`/`sys.stderr` never see. Keep the
    block short: Python's own writes to a silenced fd (a log line) are lost too."""
    saved: list[tuple[int, int]] = []  # (fd, a copy of what it was)
    try:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        with open(os.devnull, "wb") as devnull:
            for fd in fds:
                saved.append((fd, os.dup(fd)))
                os.dup2(devnull.fileno(), fd)
    except (OSError, ValueError, AttributeError):  # no such fd, or a closed stream: what it printed shows
        pass
    try:
        yield
    finally:
        _flush_c_stdout()
        for fd, copy in saved:
            os.dup2(copy, fd)
            os.close(copy)


with _quiet_fds(2):  # "pybullet build time: ..." on stderr, at every import: no output of twin's
    import pybullet as pb


# Implicit cylinders: PyBullet otherwise meshes every cylinder into a polygon, and its geometry then
# differs from the FCL planning scene's exact cylinders by up to 2 mm.
_URDF_FLAGS = pb.URDF_USE_INERTIA_FROM_FILE | pb.URDF_USE_IMPLICIT_CYLINDER
# PyBullet's EGL renderer draws no shadows in the first two frames a physics client renders (measured: one
# camera rendered 6 times gives frames 1-2 without shadows, 3-6 identical with them; other cameras or sizes
# count the same; `reset()` keeps the count). A frame's colours then depended on how many frames anyone had
# rendered before it: a recorder's frames made a run's first capture a shadowed one. `World.render` renders
# these frames first, unseen, so every frame it returns depends on the scene and the camera alone.
_EGL_WARM_UP_FRAMES = 2
# `world.sleep_at_rest`: a body sleeps once |v|^2 + |w|^2 (m/s, rad/s) has stayed below this for Bullet's 2 s
_SLEEP_MOTION = 1e-5


@contextmanager
def _quiet_stdout(active: bool = True) -> Iterator[None]:
    """Silence C-level writes to stdout (fd 1) from PyBullet plugins; library code prints nothing."""
    if not active:
        yield
        return
    with _quiet_fds(1):
        yield


@dataclass
class _FaultyTracking:
    """The state of a sluggish, noisy joint controller (`robot.tracking_*`, a fault model)."""

    alpha: float  # the share of the remaining gap the lagged target closes per physics step
    noise_rad: float
    rng: np.random.Generator
    commanded: np.ndarray = field(default_factory=lambda: np.zeros(6))
    lagged: np.ndarray = field(default_factory=lambda: np.zeros(6))

    @classmethod
    def from_settings(cls, settings: Settings, seed: int, dt: float) -> _FaultyTracking | None:
        r = settings.robot
        if r.tracking_time_constant_s == 0 and r.tracking_noise_rad == 0:
            return None  # the ideal controller: targets go to the motors as commanded
        tau = r.tracking_time_constant_s
        alpha = 1.0 if tau == 0 else 1.0 - math.exp(-dt / tau)
        return cls(alpha, r.tracking_noise_rad, np.random.default_rng([seed, 0x7AC]))


def physics_parts_missing(model: RobotModel) -> list[str]:
    """The joints and links of twin's arm and gripper the physics drives or reads that a robot URDF lacks
    (a spheres-only collision model has no finger joints: it can plan but not run in physics)."""
    missing = [n for n in ARM_JOINT_NAMES + FINGER_JOINT_NAMES if n not in model.joints]
    return missing + [n for n in ("tool0", "tcp", *_FINGER_LINKS) if n not in model.link_index]


class World:
    """A PyBullet world built from `settings` and `seed`; see the module docstring.

    Joint vectors are (6,) arrays in the order shoulder_pan .. wrist_3, radians. Poses are in the base
    (= world) frame, metres, quaternions x-y-z-w.
    """

    def __init__(
        self,
        settings: Settings,
        seed: int = 0,
        *,
        gui: bool | None = None,
        renderer: Literal["auto", "egl", "tiny"] = "auto",
    ) -> None:
        """Connect, build the scene of `settings` with objects placed from `seed`.

        `gui`: None takes settings.world.gui. `renderer`: "auto" tries the EGL plugin and falls back to
        TinyRenderer silently; "egl" requires it (WorldError otherwise); "tiny" skips it (faster to
        build when nothing will be rendered). The choice is in `self.renderer`.
        """
        if renderer not in ("auto", "egl", "tiny"):
            raise InvalidRequestError(f"renderer must be 'auto', 'egl' or 'tiny', got {renderer!r}")
        self._renderer_request = renderer
        self.settings = settings
        self.seed = int(seed)
        if self.seed < 0:
            raise InvalidRequestError(f"seed must be a non-negative integer, got {self.seed}")
        self._gui = settings.world.gui if gui is None else bool(gui)
        self._cid = -1
        self._egl = False
        self._egl_warm = False  # the renderer has rendered its warm-up frames (see _EGL_WARM_UP_FRAMES)
        self._steps = 0
        # how many times `reset()` rebuilt the scene: per-world bookkeeping kept outside the world (the sensor
        # noise streams of `twin.perception.capture`) starts over when it changes, as for a new world
        self.generation = 0
        # called while stepping: (every n steps, fn, whether fn gets the world itself or a read-only view)
        self._observers: list[tuple[int, Callable[[Any], None], bool]] = []
        self.dt = 1.0 / settings.world.physics_hz
        try:
            self._cid = pb.connect(pb.GUI if self._gui else pb.DIRECT)
        except pb.error:
            self._cid = -1
        if self._cid < 0:
            raise WorldError("could not connect to PyBullet" + (" (GUI needs a display)" if self._gui else ""))
        try:
            with _quiet_stdout():  # the EGL plugin prints banners on stdout when it loads and initialises
                self._build()
        except BaseException:
            self.close()
            raise

    # ---- construction ---------------------------------------------------------------------------
    def _build(self) -> None:
        if self._gui:
            self.renderer = "opengl"
        elif self._renderer_request == "tiny":
            self.renderer = "tiny"
        else:
            self.renderer = self._load_egl()
            if self.renderer != "egl" and self._renderer_request == "egl":
                raise WorldError("the EGL renderer plugin could not be loaded (renderer='egl' was asked for)")
        find_marker_plate(self.settings)  # ConfigError when there are several plates
        self._build_scene()
        log.debug(
            "world built: %d fixtures, %d objects, renderer %s, seed %d",
            len(self._fixtures),
            len(self._objects),
            self.renderer,
            self.seed,
        )

    def _build_scene(self) -> None:
        """Engine parameters and every body, always by the same call sequence (determinism, reset)."""
        c = self._cid
        pb.setPhysicsEngineParameter(
            fixedTimeStep=self.dt, numSubSteps=0, deterministicOverlappingPairs=1, physicsClientId=c
        )
        pb.setGravity(0.0, 0.0, self.settings.world.gravity, physicsClientId=c)
        self._bodies: dict[str, int] = {}
        self._load_robot()
        self._fixtures: dict[str, int] = {}
        self._marker_id: int | None = None
        for fx in self.settings.world.fixtures:
            self._load_fixture(fx.name, fx.urdf, fx.position, fx.rpy)
            if is_marker_plate(fx):
                self._add_marker_quad()
        self._objects: dict[int, Placement] = {}
        objects = self.settings.world.objects
        wants_boxes = any(spec.count for spec in objects.items) or self.settings.world.unmodelled_obstacle is not None
        boxes = self._obstacle_boxes() if wants_boxes else []
        placements = sample_layout(objects, self.seed, boxes)
        for sp in placements:
            self._load_object(sp)
        self.unmodelled_obstacle_centre: tuple[float, float, float] | None = None  # ground truth; it is static
        centre = place_unmodelled_obstacle(self.settings.world, self.seed, placements, boxes)
        if centre is not None:
            self._add_unmodelled_obstacle(centre)
        self._vary_object_physics()
        self._tracking = _FaultyTracking.from_settings(self.settings, self.seed, self.dt)
        self._apply_initial_commands()
        self._steps = 0

    def _load_egl(self) -> str:
        """Load the EGL renderer before any body exists (bodies created earlier render blank)."""
        try:
            spec = importlib.util.find_spec("eglRenderer")
            if spec is not None and spec.origin:
                with _quiet_fds(1, 2):  # "EGL device choice: -1 of 1." on stderr, banners on stdout
                    plugin = pb.loadPlugin(spec.origin, "_eglRendererPlugin", physicsClientId=self._cid)
                if plugin >= 0:
                    self._egl = True
                    return "egl"
        except Exception as e:  # noqa: BLE001 - any failure means: use the software TinyRenderer
            log.debug("EGL renderer unavailable (%s), using TinyRenderer", e)
        return "tiny"

    def _urdf(self, path: str) -> str:
        p = self.settings.resolve(path)
        if not p.is_file():
            raise ConfigError(f"URDF not found: {path} (resolved to {p})")
        return str(p)

    def _load_robot(self) -> None:
        c = self._cid
        urdf = self._urdf(self.settings.robot.urdf)
        model = RobotModel.from_urdf(urdf)
        missing = physics_parts_missing(model)
        if missing:  # a collision model without twin's gripper plans (`execute: false`) but cannot run physics
            raise WorldError(f"robot URDF {self.settings.robot.urdf} lacks joints/links {missing} the physics needs")
        # the URDF's root where the arm's base is the world origin (a root above the arm: `URArm.urdf_base`)
        root = URArm.from_settings(self.settings).urdf_base(model)
        try:
            self.robot_id = pb.loadURDF(
                urdf,
                root[:3, 3].tolist(),
                [0, 0, 0, 1] if np.array_equal(root, np.eye(4)) else matrix_to_quat(root[:3, :3]).tolist(),
                useFixedBase=True,
                flags=_URDF_FLAGS,
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
        for link in _FINGER_LINKS:
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
                flags=_URDF_FLAGS,
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

    def _load_object(self, sp: Placement) -> None:
        c = self._cid
        R = rpy_to_matrix((0.0, 0.0, sp.yaw))
        if sp.lying:
            R = R @ rpy_to_matrix(sp.template.lying_rpy)
        try:
            bid = pb.loadURDF(
                self._urdf(sp.template.urdf),
                list(sp.position),
                matrix_to_quat(R).tolist(),
                flags=_URDF_FLAGS,
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

    def _vary_object_physics(self) -> None:
        """Each object's mass (and inertia) and friction times a factor drawn uniformly from
        `world.objects.mass_scale` / `friction_scale`, per object in config order, from the scene seed (one
        stream per knob, so switching one on leaves the other's draws alone). A fault model: the catalogue
        the task knows is unchanged, and at [1, 1] nothing is drawn or changed. `object_scales` keeps them."""
        cfg, c = self.settings.world.objects, self._cid
        self.object_scales: dict[str, dict[str, float]] = {sp.name: {} for sp in self._objects.values()}
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
                self.object_scales[sp.name][knob] = f

    def _apply_initial_commands(self) -> None:
        """Robot at home, motors holding home, gripper open: the state `reset()` returns to."""
        home = np.asarray(self.settings.robot.home, dtype=float)
        c = self._cid
        for j, q in zip(self._arm, home, strict=True):
            pb.resetJointState(self.robot_id, j, float(q), 0.0, physicsClientId=c)
        half = self.settings.gripper.max_opening_m / 2.0
        for j in self._fingers:
            pb.resetJointState(self.robot_id, j, half, 0.0, physicsClientId=c)
        self._hold(home)
        self.open_gripper()

    def _hold(self, q: np.ndarray) -> None:
        """Targets at q, the arm having been put there: a faulty controller starts from it, without lag."""
        if self._tracking is not None:
            self._tracking.lagged, self._tracking.commanded = q.copy(), q.copy()
            self._send_joint_targets(q, np.zeros(6))
        else:
            self.set_joint_targets(q)

    # ---- lifecycle ------------------------------------------------------------------------------
    @property
    def client_id(self) -> int:
        """The PyBullet physics client id (pass it as physicsClientId for reference queries)."""
        return self._cid

    @property
    def sim_time(self) -> float:
        """Seconds simulated since the world was built or last reset."""
        return self._steps * self.dt

    @property
    def connected(self) -> bool:
        """False once `close()` was called."""
        return self._cid >= 0

    def _check(self) -> int:
        if self._cid < 0:
            raise WorldError("the world is closed")
        return self._cid

    def step(self, n: int = 1) -> None:
        """Advance the physics by n steps of 1/physics_hz seconds."""
        c = self._check()
        if n < 0:
            raise InvalidRequestError(f"cannot step a negative number of times ({n})")
        with stage("physics"):
            for _ in range(int(n)):
                if self._tracking is not None:
                    self._track()
                pb.stepSimulation(physicsClientId=c)
                self._steps += 1
                if self._observers:
                    for every, fn, full_access in self._observers:
                        if self._steps % every == 0:
                            fn(self if full_access else self.view())

    def _track(self) -> None:
        """One physics step of the faulty controller (`robot.tracking_*`): the target it sends follows the
        commanded one through a first-order lag, plus noise; the velocity feed-forward is its rate."""
        t = self._tracking
        assert t is not None
        previous = t.lagged.copy()
        t.lagged += t.alpha * (t.commanded - t.lagged)
        target = t.lagged + (t.rng.normal(0.0, t.noise_rad, 6) if t.noise_rad > 0 else 0.0)
        self._send_joint_targets(target, (t.lagged - previous) / self.dt)

    def observe(self, fn: Callable[[WorldView], None], *, every_s: float) -> None:
        """Call `fn(view)` every `every_s` simulated seconds while stepping (recorders, viewers, GUI pacing).

        `view` is the world's `WorldView`: it reads state and renders, and can change neither the
        simulation nor what the sensors see, so a run with observers gives the run without them."""
        self._observers.append((self._every(every_s), fn, False))

    def view(self) -> WorldView:
        """A read-only view of this world: what observers get."""
        return WorldView(self)

    def disturb(self, fn: Callable[[World], None], *, every_s: float) -> None:
        """Call `fn(world)` every `every_s` simulated seconds while stepping, with full access: test setups
        and fault injection that are meant to change the run (e.g. snatching a held object)."""
        self._observers.append((self._every(every_s), fn, True))

    def _every(self, every_s: float) -> int:
        return max(1, int(round(every_s / self.dt)))

    def reset(self) -> None:
        """Back to the state after construction: robot at home, objects at their sampled poses.

        The scene is rebuilt from scratch (same ids, same call sequence), so a reset world evolves
        bit-identically to a new one; restoring a saved state leaves solver caches behind (~40 um drift).
        Everything a new world starts with starts over: the simulated time, the arm's and the gripper's
        commands, a faulty controller's lag and noise stream (`robot.tracking_*`), and, through
        `generation`, the sensor noise streams of its captures (the first capture after a reset draws what
        a new world's first capture draws). What the caller attached stays: observers and disturbers
        (`observe`, `disturb`; they count steps from the reset like from construction), and the renderer
        (its warm-up frames are done; PyBullet keeps its frame count across a reset).
        """
        c = self._check()
        with _quiet_stdout(self._egl):
            pb.resetSimulation(physicsClientId=c)
            self._build_scene()
        self.generation += 1

    def close(self) -> None:
        """Disconnect from PyBullet (idempotent)."""
        if self._cid >= 0:
            try:
                with _quiet_stdout(self._egl):  # the EGL plugin says goodbye on stdout
                    pb.disconnect(physicsClientId=self._cid)
            except pb.error:
                pass
            self._cid = -1

    def __enter__(self) -> World:
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def __del__(self) -> None:
        # A finaliser must not raise. Not contextlib.suppress: at interpreter shutdown this module's globals
        # (`suppress` too) may already be None, while the builtin Exception is still there.
        try:  # noqa: SIM105
            self.close()
        except Exception:  # noqa: BLE001
            pass

    # ---- arm ------------------------------------------------------------------------------------
    def set_joint_targets(
        self, q: Sequence[float] | np.ndarray, qd: Sequence[float] | np.ndarray | None = None
    ) -> None:
        """Joint position targets for the arm (held until changed), with optional velocity feed-forward.

        Force-limited by robot.max_joint_force, position gain robot.position_gain, velocity capped at
        robot.max_joint_vel. `q`, `qd`: (6,) rad, rad/s.
        """
        self._check()
        q = _as_vec(q, 6, "q")
        qd = np.zeros(6) if qd is None else _as_vec(qd, 6, "qd")
        if self._tracking is not None:  # the faulty controller passes them on step by step (`_track`)
            self._tracking.commanded = q.copy()
            return
        self._send_joint_targets(q, qd)

    def _send_joint_targets(self, q: np.ndarray, qd: np.ndarray) -> None:
        c = self._cid
        r = self.settings.robot
        for k, j in enumerate(self._arm):
            pb.setJointMotorControl2(
                self.robot_id,
                j,
                pb.POSITION_CONTROL,
                targetPosition=float(q[k]),
                targetVelocity=float(qd[k]),
                force=float(r.max_joint_force[k]),
                positionGain=r.position_gain,
                velocityGain=1.0,
                maxVelocity=r.max_joint_vel,
                physicsClientId=c,
            )

    def reset_joints(self, q: Sequence[float] | np.ndarray) -> None:
        """Teleport the arm to q (zero velocity) and hold it there: for setup and tests, not for motion."""
        c = self._check()
        q = _as_vec(q, 6, "q")
        for k, j in enumerate(self._arm):
            pb.resetJointState(self.robot_id, j, float(q[k]), 0.0, physicsClientId=c)
        self._hold(q)

    def joint_positions(self) -> np.ndarray:
        """(6,) arm joint angles, rad."""
        c = self._check()
        return np.array([s[0] for s in pb.getJointStates(self.robot_id, self._arm, physicsClientId=c)])

    def joint_velocities(self) -> np.ndarray:
        """(6,) arm joint velocities, rad/s."""
        c = self._check()
        return np.array([s[1] for s in pb.getJointStates(self.robot_id, self._arm, physicsClientId=c)])

    # ---- gripper --------------------------------------------------------------------------------
    def set_gripper_opening(self, width_m: float, *, speed_m_s: float | None = None) -> None:
        """Move both fingers symmetrically to an opening (m, clipped to 0..max_opening_m)."""
        c = self._check()
        g = self.settings.gripper
        half = float(np.clip(width_m, 0.0, g.max_opening_m)) / 2.0
        v = (g.speed_m_s if speed_m_s is None else float(speed_m_s)) / 2.0
        for j in self._fingers:
            pb.setJointMotorControl2(
                self.robot_id,
                j,
                pb.POSITION_CONTROL,
                targetPosition=half,
                targetVelocity=0.0,
                force=g.force_n,
                positionGain=0.2,
                velocityGain=1.0,
                maxVelocity=v,
                physicsClientId=c,
            )

    def open_gripper(self) -> None:
        """Open to gripper.max_opening_m at gripper.speed_m_s."""
        self.set_gripper_opening(self.settings.gripper.max_opening_m)

    def close_gripper(self, *, force_n: float | None = None, speed_m_s: float | None = None) -> None:
        """Close at a speed (default gripper.speed_m_s) until blocked, then squeeze with force_n per finger.

        Each finger is a velocity motor limited to `force_n` (default gripper.force_n), so on an object
        the grip force settles at that value, as on a Robotiq gripper (times `gripper.force_scale`, a
        fault model: a worn gripper squeezes less than it is told).
        """
        c = self._check()
        g = self.settings.gripper
        f = (g.force_n if force_n is None else float(force_n)) * g.force_scale
        v = (g.speed_m_s if speed_m_s is None else float(speed_m_s)) / 2.0
        for j in self._fingers:
            pb.setJointMotorControl2(
                self.robot_id, j, pb.VELOCITY_CONTROL, targetVelocity=-v, force=f, physicsClientId=c
            )

    # Sensor readings: what a real Robotiq 2F-85 reports (finger position from the joint encoders, motor
    # current). Tasks decide "holding / slipped / dropped" from these alone.
    def gripper_opening(self) -> float:
        """Sensor reading: the distance between the finger pads from the finger joint encoders, m
        (0 = fully closed, pads touching)."""
        c = self._check()
        return float(sum(s[0] for s in pb.getJointStates(self.robot_id, self._fingers, physicsClientId=c)))

    def gripper_settled(self, *, tol_m_s: float = 2e-3) -> bool:
        """Sensor reading: True when both fingers have stopped (closed on an object, fully closed or at
        the target), from the finger encoders' velocities."""
        c = self._check()
        return all(abs(s[1]) < tol_m_s for s in pb.getJointStates(self.robot_id, self._fingers, physicsClientId=c))

    def gripper_effort(self) -> float:
        """Sensor reading: the mean force the two finger motors applied in the last step, N (a Robotiq
        reports motor current). Squeezing an object or pressing the closed pads together it sits at the
        force limit, so on its own it does not tell the two apart; the opening does."""
        c = self._check()
        return float(np.mean([abs(s[3]) for s in pb.getJointStates(self.robot_id, self._fingers, physicsClientId=c)]))

    def grasped_object(self) -> int | None:
        """Ground truth (judging, metrics, the simulated safety monitor and tests; never a task's decision):
        id of the object both fingers touch (contacts of the last step), or None."""
        c = self._check()
        touching = []
        for link in _FINGER_LINKS:
            pts = pb.getContactPoints(bodyA=self.robot_id, linkIndexA=self._link_index[link], physicsClientId=c)
            touching.append({p[2] for p in pts if p[2] in self._objects})
        both = touching[0] & touching[1]
        return min(both) if both else None

    def grasp_settled(self, *, tol_m_s: float = 2e-3) -> bool:
        """Ground truth (tests): True when the fingers have stopped on an object that both of them touch."""
        return self.gripper_settled(tol_m_s=tol_m_s) and self.grasped_object() is not None

    # ---- ground truth (metrics and tests only) ----------------------------------------------------
    def body_ids(self) -> dict[str, int]:
        """Every body by name: 'robot', fixture names, object names, 'aruco_marker'."""
        return dict(self._bodies)

    def link_indices(self) -> dict[str, int]:
        """Robot link name -> PyBullet link index ('base_link' is -1)."""
        return dict(self._link_index)

    def object_ids(self) -> list[int]:
        """Body ids of the scene objects, in config order."""
        return list(self._objects)

    def object_pose(self, body_id: int) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,), quaternion xyzw (4,)) of an object (its geometric centre)."""
        c = self._check()
        pos, quat = pb.getBasePositionAndOrientation(body_id, physicsClientId=c)
        return np.array(pos), np.array(quat)

    def object_velocity(self, body_id: int) -> tuple[np.ndarray, np.ndarray]:
        """(linear (3,) m/s, angular (3,) rad/s) velocity of an object: the judge's "at rest" test."""
        c = self._check()
        if body_id not in self._objects:
            raise InvalidRequestError(f"{body_id} is not an object id; objects: {self.object_ids()}")
        lin, ang = pb.getBaseVelocity(body_id, physicsClientId=c)
        return np.array(lin), np.array(ang)

    def object_state(self, body_id: int) -> ObjectState:
        """Ground truth of one object."""
        if body_id not in self._objects:
            raise InvalidRequestError(f"{body_id} is not an object id; objects: {self.object_ids()}")
        sp = self._objects[body_id]
        pos, quat = self.object_pose(body_id)
        z_axis = np.array(pb.getMatrixFromQuaternion(quat.tolist())).reshape(3, 3)[:, 2]
        return ObjectState(
            id=body_id,
            name=sp.name,
            cls=sp.template.cls,
            color=sp.color,
            position=pos,
            orientation_xyzw=quat,
            lying=bool(abs(z_axis[2]) < math.sqrt(0.5)),
            size=sp.template.size,
        )

    def objects(self) -> list[ObjectState]:
        """Ground truth of every object, in config order."""
        return [self.object_state(i) for i in self._objects]

    def set_object_pose(
        self, body_id: int, position: Sequence[float] | np.ndarray, orientation_xyzw: Sequence[float] | np.ndarray
    ) -> None:
        """Teleport an object (zero velocity): for test setups, never during a measured run."""
        c = self._check()
        if body_id not in self._objects:
            raise InvalidRequestError(f"{body_id} is not an object id; objects: {self.object_ids()}")
        pos = _as_vec(position, 3, "position")
        quat = _as_vec(orientation_xyzw, 4, "orientation_xyzw")
        pb.resetBasePositionAndOrientation(
            body_id, pos.tolist(), (quat / np.linalg.norm(quat)).tolist(), physicsClientId=c
        )
        pb.resetBaseVelocity(body_id, [0, 0, 0], [0, 0, 0], physicsClientId=c)
        pb.changeDynamics(body_id, -1, activationState=pb.ACTIVATION_STATE_WAKE_UP, physicsClientId=c)

    def link_pose(self, link_name: str) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,), quaternion xyzw (4,)) of a robot link frame (e.g. 'tool0', 'tcp')."""
        c = self._check()
        if link_name not in self._link_index:
            raise InvalidRequestError(f"unknown robot link {link_name!r}; links: {', '.join(self._link_index)}")
        j = self._link_index[link_name]
        if j < 0:
            pos, quat = pb.getBasePositionAndOrientation(self.robot_id, physicsClientId=c)
        else:
            s = pb.getLinkState(self.robot_id, j, computeForwardKinematics=True, physicsClientId=c)
            pos, quat = s[4], s[5]
        return np.array(pos), np.array(quat)

    def render(self, T_world_camera: np.ndarray, intrinsics: Intrinsics, *, near_m: float, far_m: float) -> RGBDFrame:
        """Render an RGB-D frame from an OpenCV-convention camera pose (4, 4) with pinhole intrinsics.

        Depth is converted from PyBullet's non-linear z-buffer to metres along the optical axis.
        """
        from twin.camera import RGBDFrame, depth_from_zbuffer, gl_projection_matrix, gl_view_matrix

        c = self._check()
        if self._egl and not self._egl_warm:
            self._warm_up_renderer()
        with stage("rendering"), _quiet_stdout(self._egl):
            _, _, rgba, zbuf, _ = pb.getCameraImage(
                intrinsics.width,
                intrinsics.height,
                viewMatrix=gl_view_matrix(T_world_camera),
                projectionMatrix=gl_projection_matrix(intrinsics, near_m, far_m),
                renderer=pb.ER_BULLET_HARDWARE_OPENGL if self._egl else pb.ER_TINY_RENDERER,
                flags=pb.ER_NO_SEGMENTATION_MASK,
                physicsClientId=c,
            )
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(intrinsics.height, intrinsics.width, 4)[:, :, :3].copy()
        zb = np.asarray(zbuf, dtype=np.float64).reshape(intrinsics.height, intrinsics.width)
        return RGBDFrame(rgb, depth_from_zbuffer(zb, near_m, far_m), intrinsics)

    def _warm_up_renderer(self) -> None:
        """Render the EGL renderer's shadowless first frames (`_EGL_WARM_UP_FRAMES`), 1x1, unseen."""
        from twin.camera import Intrinsics, gl_projection_matrix, gl_view_matrix, look_at

        view = gl_view_matrix(look_at((1.0, 0.0, 1.0), (0.0, 0.0, 0.0)))
        projection = gl_projection_matrix(Intrinsics(1, 1, 1.0, 1.0), 0.05, 5.0)
        with stage("rendering"), _quiet_stdout():
            for _ in range(_EGL_WARM_UP_FRAMES):
                pb.getCameraImage(
                    1,
                    1,
                    viewMatrix=view,
                    projectionMatrix=projection,
                    renderer=pb.ER_BULLET_HARDWARE_OPENGL,
                    flags=pb.ER_NO_SEGMENTATION_MASK,
                    physicsClientId=self._cid,
                )
        self._egl_warm = True

    def link_matrix(self, link_name: str) -> np.ndarray:
        """(4, 4) pose of a robot link frame in the base frame."""
        pos, quat = self.link_pose(link_name)
        T = np.eye(4)
        T[:3, :3] = np.array(pb.getMatrixFromQuaternion(quat.tolist())).reshape(3, 3)
        T[:3, 3] = pos
        return T

    def marker_pose(self) -> np.ndarray:
        """(4, 4) ground-truth pose of the ArUco marker frame (OpenCV convention) in the base frame."""
        c = self._check()
        if self._marker_id is None:
            raise WorldError("this scene has no ArUco plate (add a fixture with urdf: urdf/aruco_plate.urdf)")
        pos, quat = pb.getBasePositionAndOrientation(self._marker_id, physicsClientId=c)
        T = np.eye(4)
        T[:3, :3] = np.array(pb.getMatrixFromQuaternion(quat)).reshape(3, 3)
        T[:3, 3] = pos
        return T

    @staticmethod
    def _points(raw: Sequence[Any]) -> list[ContactPoint]:
        return [
            ContactPoint(
                body_a=p[1],
                body_b=p[2],
                link_a=p[3],
                link_b=p[4],
                position_on_a=np.array(p[5]),
                position_on_b=np.array(p[6]),
                normal_on_b=np.array(p[7]),
                distance=float(p[8]),
                normal_force=float(p[9]),
            )
            for p in raw
        ]

    def contacts(self, body_a: int | None = None, body_b: int | None = None) -> list[ContactPoint]:
        """Contact points of the last physics step, optionally filtered to body A (and body B)."""
        c = self._check()
        kw: dict[str, int] = {}
        if body_a is not None:
            kw["bodyA"] = body_a
        if body_b is not None:
            if body_a is None:
                raise InvalidRequestError("give body_a when filtering by body_b")
            kw["bodyB"] = body_b
        return self._points(pb.getContactPoints(physicsClientId=c, **kw))

    def robot_contacts(self, *, ignore: Sequence[int] = ()) -> list[ContactPoint]:
        """Contacts between the robot (any link) and any other body except `ignore` (e.g. the grasped object)."""
        skip = set(ignore)
        return [p for p in self.contacts(self.robot_id) if p.body_b not in skip and p.body_b != self.robot_id]

    def unexpected_contacts(
        self, *, ignore: Sequence[int] = (), fingers_may_touch_objects: bool = False
    ) -> list[tuple[str, str]]:
        """(robot link, body) names of the robot's contacts in the last step that a protective stop reacts to.

        Not counted: bodies in `ignore` (the held object), the robot with itself, the base link on what it
        stands on (it is fixed there) and, with `fingers_may_touch_objects`, a finger on a loose object (a
        finger brushing the object it is about to grasp or has just let go of is part of grasping).
        This is the simulated cell's safety monitor, read by the executor; tasks never decide with it."""
        skip = set(ignore)
        fingers = {self._link_index[n] for n in _FINGER_LINKS}
        link_name = {i: n for n, i in self._link_index.items()}
        body_name = {i: n for n, i in self._bodies.items()}
        out: set[tuple[str, str]] = set()
        for p in self.contacts(self.robot_id):
            if p.body_b in skip or p.body_b == self.robot_id or p.link_a == -1:
                continue
            if fingers_may_touch_objects and p.link_a in fingers and p.body_b in self._objects:
                continue
            name = self._objects[p.body_b].name if p.body_b in self._objects else body_name.get(p.body_b, str(p.body_b))
            out.add((link_name.get(p.link_a, str(p.link_a)), name))
        return sorted(out)

    def touched_objects(self) -> tuple[int, ...]:
        """Loose objects the robot touches in the last step (body ids, ascending): what a safety monitor
        lets a retreat after a protective stop push away from (see `Cell.recover`)."""
        return tuple(sorted({p.body_b for p in self.contacts(self.robot_id) if p.body_b in self._objects}))

    def closest_points(
        self, body_a: int, body_b: int, max_distance_m: float, *, link_a: int | None = None, link_b: int | None = None
    ) -> list[ContactPoint]:
        """Closest-point pairs closer than max_distance_m (negative distance = penetration); no stepping."""
        c = self._check()
        kw: dict[str, int] = {}
        if link_a is not None:
            kw["linkIndexA"] = link_a
        if link_b is not None:
            kw["linkIndexB"] = link_b
        return self._points(pb.getClosestPoints(body_a, body_b, max_distance_m, physicsClientId=c, **kw))


class WorldView:
    """A read-only view of a `World`: what an observer (`World.observe`: a recorder, a viewer) gets.

    It reads state and renders; it cannot step, command the robot, move bodies or capture (a capture
    draws sensor noise from the world's stream). Its renders go through `World.render`, whose frames
    depend on the scene and the camera alone, so rendering here changes no later sensor frame.
    """

    __slots__ = ("_world",)

    def __init__(self, world: World) -> None:
        self._world = world

    @property
    def seed(self) -> int:
        return self._world.seed

    @property
    def dt(self) -> float:
        return self._world.dt

    @property
    def sim_time(self) -> float:
        """Seconds simulated since the world was built or last reset."""
        return self._world.sim_time

    @property
    def renderer(self) -> str:
        return self._world.renderer

    def joint_positions(self) -> np.ndarray:
        """(6,) arm joint angles, rad."""
        return self._world.joint_positions()

    def gripper_opening(self) -> float:
        """The distance between the finger pads, m."""
        return self._world.gripper_opening()

    def body_ids(self) -> dict[str, int]:
        """Every body by name: 'robot', fixture names, object names, 'aruco_marker'."""
        return self._world.body_ids()

    def object_ids(self) -> list[int]:
        """Body ids of the scene objects, in config order."""
        return self._world.object_ids()

    def link_indices(self) -> dict[str, int]:
        """Robot link name -> PyBullet link index."""
        return self._world.link_indices()

    def objects(self) -> list[ObjectState]:
        """Ground truth of every object, in config order."""
        return self._world.objects()

    def object_pose(self, body_id: int) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,), quaternion xyzw (4,)) of an object."""
        return self._world.object_pose(body_id)

    def link_pose(self, link_name: str) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,), quaternion xyzw (4,)) of a robot link frame."""
        return self._world.link_pose(link_name)

    def link_matrix(self, link_name: str) -> np.ndarray:
        """(4, 4) pose of a robot link frame in the base frame."""
        return self._world.link_matrix(link_name)

    def render(self, T_world_camera: np.ndarray, intrinsics: Intrinsics, *, near_m: float, far_m: float) -> RGBDFrame:
        """An RGB-D frame from an OpenCV-convention camera pose (4, 4): `World.render`."""
        return self._world.render(T_world_camera, intrinsics, near_m=near_m, far_m=far_m)
