"""`World`: a PyBullet physics client stepping the scene of a config, the facade the rest of twin drives.

`twin.world.scene_builder` builds the scene; a `World` connects, has it built (again at `reset()`), steps
the physics, drives the arm by joint position control at the physics rate and the gripper by
force-limited closing, reads its sensors (joint and finger encoders, the finger motors' effort, camera
images: `twin.world.rendering`) and, through `GroundTruth` (`twin.world.truth`), what the physics says
for judging, metrics and tests. A `WorldView` is its read-only face for observers.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from twin.config import Settings
from twin.errors import InvalidRequestError, WorldError
from twin.robot import Robot
from twin.scene_layout import find_marker_plate
from twin.timing import stage
from twin.world.bullet import pb, quiet_stdout
from twin.world.rendering import Light, load_egl_renderer, render_labelled, scene_light, warm_up_egl
from twin.world.scene_builder import BuiltScene, build_scene
from twin.world.tracking import FaultyTracking
from twin.world.truth import GroundTruth
from twin.world.values import FINGER_LINKS, ObjectState, as_vec

if TYPE_CHECKING:
    from twin.camera import Intrinsics, RGBDFrame

__all__ = ["World", "WorldView"]

_ZERO6 = np.zeros(6)
_ZERO6.flags.writeable = False

log = logging.getLogger("twin")


class World(GroundTruth):
    """A PyBullet world built from `settings` and `seed`; see the `twin.world` package docstring.

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
        robot: Robot | None = None,
    ) -> None:
        """Connect, build the scene of `settings` with objects placed from `seed`.

        `robot`: the config's robot, built once for a run and handed down (`PluginContext.robot`); None
        builds it from `settings.robot`.

        `gui`: None takes settings.world.gui. `renderer`: "auto" tries the EGL plugin and falls back to
        TinyRenderer silently; "egl" requires it (WorldError otherwise); "tiny" skips it (faster to
        build when nothing will be rendered). The choice is in `self.renderer`.
        """
        if renderer not in ("auto", "egl", "tiny"):
            raise InvalidRequestError(f"renderer must be 'auto', 'egl' or 'tiny', got {renderer!r}")
        self._renderer_request = renderer
        self.settings = settings
        self.robot = robot if robot is not None else Robot.from_settings(settings)
        self.seed = int(seed)
        if self.seed < 0:
            raise InvalidRequestError(f"seed must be a non-negative integer, got {self.seed}")
        self._gui = settings.world.gui if gui is None else bool(gui)
        self._cid = -1
        self._egl = False
        self._egl_warm = False  # the renderer has rendered its warm-up frames (see EGL_WARM_UP_FRAMES)
        self.light = scene_light(settings.world.light, self.seed)  # the scene's light (None: PyBullet's)
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
            with quiet_stdout():  # the EGL plugin prints banners on stdout when it loads and initialises
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
            self._egl = load_egl_renderer(self._cid)  # before any body exists (those render blank)
            self.renderer = "egl" if self._egl else "tiny"
            if self.renderer != "egl" and self._renderer_request == "egl":
                raise WorldError("the EGL renderer plugin could not be loaded (renderer='egl' was asked for)")
        find_marker_plate(self.settings)  # ConfigError when there are several plates
        self._build_scene()
        log.debug(
            "world built: %d fixtures, %d objects, renderer %s, seed %d",
            len(self._scene.fixtures),
            len(self._scene.objects),
            self.renderer,
            self.seed,
        )

    def _build_scene(self) -> None:
        """Every body (`build_scene`), then the controller and the commands a new world starts with."""
        self._scene: BuiltScene = build_scene(self._cid, self.settings, self.seed, self.dt, self.robot)
        self.robot_id = self._scene.robot_id
        self.unmodelled_obstacle_centre = self._scene.unmodelled_obstacle_centre  # ground truth; it is static
        self.object_scales = self._scene.object_scales  # `world.objects.mass_scale` / `friction_scale` drawn
        self._tracking = FaultyTracking.from_settings(self.settings, self.seed, self.dt)
        r = self.settings.robot
        # the arm's motor settings as PyBullet takes them, converted once: the executor sends targets every step
        self._arm_motors = [(j, float(f)) for j, f in zip(self._scene.arm, r.max_joint_force, strict=True)]
        self._arm_gain, self._arm_max_vel = float(r.position_gain), float(r.max_joint_vel)
        self._apply_initial_commands()
        self._steps = 0

    def _apply_initial_commands(self) -> None:
        """Robot at home, motors holding home, gripper open: the state `reset()` returns to."""
        home = np.asarray(self.settings.robot.home, dtype=float)
        c = self._cid
        for j, q in zip(self._scene.arm, home, strict=True):
            pb.resetJointState(self.robot_id, j, float(q), 0.0, physicsClientId=c)
        half = self.settings.gripper.max_opening_m / 2.0
        for j in self._scene.fingers:
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
        """One physics step of the faulty controller (`robot.tracking_*`): it sends its lagged, noisy target."""
        assert self._tracking is not None
        self._send_joint_targets(*self._tracking.advance(self.dt))

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
        with quiet_stdout(self._egl):
            pb.resetSimulation(physicsClientId=c)
            self._build_scene()
        self.generation += 1

    def close(self) -> None:
        """Disconnect from PyBullet (idempotent)."""
        if self._cid >= 0:
            try:
                with quiet_stdout(self._egl):  # the EGL plugin says goodbye on stdout
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
        q = as_vec(q, 6, "q")
        qd = _ZERO6 if qd is None else as_vec(qd, 6, "qd")
        if self._tracking is not None:  # the faulty controller passes them on step by step (`_track`)
            self._tracking.commanded = q.copy()
            return
        self._send_joint_targets(q, qd)

    def _send_joint_targets(self, q: np.ndarray, qd: np.ndarray) -> None:
        # called every physics step while the arm moves: the per-joint settings are converted once
        # (`_build_scene`), the targets in one `tolist` each (the same Python floats as float(q[k]))
        c, body, gain, vmax = self._cid, self.robot_id, self._arm_gain, self._arm_max_vel
        for (j, force), qk, qdk in zip(self._arm_motors, q.tolist(), qd.tolist(), strict=True):
            pb.setJointMotorControl2(
                body,
                j,
                pb.POSITION_CONTROL,
                targetPosition=qk,
                targetVelocity=qdk,
                force=force,
                positionGain=gain,
                velocityGain=1.0,
                maxVelocity=vmax,
                physicsClientId=c,
            )

    def reset_joints(self, q: Sequence[float] | np.ndarray) -> None:
        """Teleport the arm to q (zero velocity) and hold it there: for setup and tests, not for motion."""
        c = self._check()
        q = as_vec(q, 6, "q")
        for k, j in enumerate(self._scene.arm):
            pb.resetJointState(self.robot_id, j, float(q[k]), 0.0, physicsClientId=c)
        self._hold(q)

    def joint_positions(self) -> np.ndarray:
        """(6,) arm joint angles, rad."""
        c = self._check()
        return np.array([s[0] for s in pb.getJointStates(self.robot_id, self._scene.arm, physicsClientId=c)])

    def joint_velocities(self) -> np.ndarray:
        """(6,) arm joint velocities, rad/s."""
        c = self._check()
        return np.array([s[1] for s in pb.getJointStates(self.robot_id, self._scene.arm, physicsClientId=c)])

    # ---- gripper --------------------------------------------------------------------------------
    def set_gripper_opening(self, width_m: float, *, speed_m_s: float | None = None) -> None:
        """Move both fingers symmetrically to an opening (m, clipped to 0..max_opening_m)."""
        c = self._check()
        g = self.settings.gripper
        half = float(np.clip(width_m, 0.0, g.max_opening_m)) / 2.0
        v = (g.speed_m_s if speed_m_s is None else float(speed_m_s)) / 2.0
        for j in self._scene.fingers:
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
        for j in self._scene.fingers:
            pb.setJointMotorControl2(
                self.robot_id, j, pb.VELOCITY_CONTROL, targetVelocity=-v, force=f, physicsClientId=c
            )

    # Sensor readings: what a real Robotiq 2F-85 reports (finger position from the joint encoders, motor
    # current). Tasks decide "holding / slipped / dropped" from these alone.
    def gripper_opening(self) -> float:
        """Sensor reading: the distance between the finger pads from the finger joint encoders, m
        (0 = fully closed, pads touching)."""
        c = self._check()
        return float(sum(s[0] for s in pb.getJointStates(self.robot_id, self._scene.fingers, physicsClientId=c)))

    def gripper_settled(self, *, tol_m_s: float = 2e-3) -> bool:
        """Sensor reading: True when both fingers have stopped (closed on an object, fully closed or at
        the target), from the finger encoders' velocities."""
        c = self._check()
        return all(
            abs(s[1]) < tol_m_s for s in pb.getJointStates(self.robot_id, self._scene.fingers, physicsClientId=c)
        )

    def gripper_effort(self) -> float:
        """Sensor reading: the mean force the two finger motors applied in the last step, N (a Robotiq
        reports motor current). Squeezing an object or pressing the closed pads together it sits at the
        force limit, so on its own it does not tell the two apart; the opening does."""
        c = self._check()
        return float(
            np.mean([abs(s[3]) for s in pb.getJointStates(self.robot_id, self._scene.fingers, physicsClientId=c)])
        )

    def grasped_object(self) -> int | None:
        """Ground truth (judging, metrics, the simulated safety monitor and tests; never a task's decision):
        id of the object both fingers touch (contacts of the last step), or None."""
        c = self._check()
        touching = []
        for link in FINGER_LINKS:
            pts = pb.getContactPoints(bodyA=self.robot_id, linkIndexA=self._scene.link_index[link], physicsClientId=c)
            touching.append({p[2] for p in pts if p[2] in self._scene.objects})
        both = touching[0] & touching[1]
        return min(both) if both else None

    def grasp_settled(self, *, tol_m_s: float = 2e-3) -> bool:
        """Ground truth (tests): True when the fingers have stopped on an object that both of them touch."""
        return self.gripper_settled(tol_m_s=tol_m_s) and self.grasped_object() is not None

    def render(
        self,
        T_world_camera: np.ndarray,
        intrinsics: Intrinsics,
        *,
        near_m: float,
        far_m: float,
        light: Light | None = None,
    ) -> RGBDFrame:
        """Render an RGB-D frame from an OpenCV-convention camera pose (4, 4) with pinhole intrinsics, under
        `light` (None: the scene's, `self.light`).

        Depth is converted from PyBullet's non-linear z-buffer to metres along the optical axis.
        """
        return self.render_labelled(T_world_camera, intrinsics, near_m=near_m, far_m=far_m, light=light, ids=False)[0]

    def render_labelled(
        self,
        T_world_camera: np.ndarray,
        intrinsics: Intrinsics,
        *,
        near_m: float,
        far_m: float,
        light: Light | None = None,
        ids: bool = True,
    ) -> tuple[RGBDFrame, np.ndarray | None]:
        """`render`, and with `ids` the body id seen at each pixel (H, W), -1 for none: ground truth for
        labelled images (`twin.dataset`), never for perception."""
        c = self._check()
        if self._egl and not self._egl_warm:
            warm_up_egl(c)  # every frame returned then depends on the scene and the camera alone
            self._egl_warm = True
        return render_labelled(
            c, self._egl, T_world_camera, intrinsics, near_m, far_m, light or self.light, segmentation=ids
        )


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
