"""Taking a frame the way the reference systems do, and nothing more.

Fixed mount (seeds 000/001): let the scene settle, render from the camera's real pose (the configured one
times `camera.extrinsic_error`). Wrist mount (seed 002): put the arm in the capture pose (~0.7 m above
the table), wait the settling pause, render. The frame then goes through the sensor model, once per frame
of the burst the depth filter averages (`perception.depth_filter`: the last frames of the pause, one
render, as the scene is at rest), and through the filter. What perception gets back is the frame, the
measured joint angles and the camera pose that the robot's own kinematics predicts (for a wrist camera:
forward kinematics of the measured joints times the configured hand-eye offset) - never simulator ground
truth. A late frame (`camera.latency_s`, a fault model) shows the world that long before the joints
read with it.

The arm is teleported to the capture pose (`World.reset_joints`): a perception run needs no planner. A
task that moves there with a planner calls `capture_frame(..., move=False)` once it has arrived.
"""

from __future__ import annotations

import logging
import time
import weakref
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from twin.camera import Intrinsics, RGBDFrame, camera_pose, true_camera_pose
from twin.config import Settings
from twin.perception.depth_filter import filter_frames
from twin.perception.noise import PrefetchedDraws, burst_draws, sensor_burst
from twin.timing import stage

if TYPE_CHECKING:
    from twin.world import World

__all__ = ["Capture", "capture_frame", "noise_rng", "prefetch_next_capture", "wrist_camera_offset"]

log = logging.getLogger("twin")


@dataclass(frozen=True)
class Capture:
    """One captured frame with what the robot knows about where the camera was.

    `frame`: the RGB-D frame after the sensor model. `q`: (6,) measured joint angles, rad.
    `T_base_camera_nominal`: (4, 4) camera pose from the configured mount (fixed) or from forward
    kinematics of `q` and the hand-eye offset (wrist); the ArUco calibration estimates it independently.
    `timings_s`: seconds spent settling (physics), rendering and in the sensor model.
    """

    frame: RGBDFrame
    q: np.ndarray
    T_base_camera_nominal: np.ndarray
    mount: str
    pose_name: str
    timings_s: dict[str, float] = field(default_factory=dict)


def wrist_camera_offset(settings: Settings) -> np.ndarray:
    """(4, 4) pose of the wrist camera in the tool0 frame (the hand-eye calibration of the config)."""
    T = np.eye(4)
    T[:3, 3] = settings.camera.wrist_offset_m
    return T


def noise_rng(seed: int, stream: int = 0) -> np.random.Generator:
    """The generator of the sensor noise for scene `seed` (separate from the layout's generator)."""
    return np.random.default_rng([int(seed), 0x5EED, int(stream)])


@dataclass
class _NoiseBook:
    """A world's capture bookkeeping since it was built or last reset (`World.generation`).

    `taken`: captures so far; each capture's noise is drawn from its own stream (a real sensor's noise is
    new in every frame), the first from stream 0, and a run stays repeatable. `next_draws`: the noise draws
    of the next capture (its index and them), started by `prefetch_next_capture`. `off_plan`: its frames
    left the plan (pixels without depth: the draws depend on the image), so it is not prefetched.
    """

    generation: int
    taken: int = 0
    next_draws: tuple[int, PrefetchedDraws] | None = None
    off_plan: bool = False


_books: weakref.WeakKeyDictionary[Any, _NoiseBook] = weakref.WeakKeyDictionary()


def _book(world: World) -> _NoiseBook:
    """The world's bookkeeping; a reset world (another generation) starts a new one, as a new world does."""
    book = _books.get(world)
    if book is None or book.generation != world.generation:
        book = _books[world] = _NoiseBook(world.generation)
    return book


def capture_frame(
    world: World,
    settings: Settings,
    *,
    pose: Literal["capture", "calibration"] = "capture",
    move: bool = True,
    settle_s: float | None = None,
    rng: np.random.Generator | None = None,
    prefetch_noise: bool = True,
) -> Capture:
    """Settle, render and add sensor noise; for a wrist camera first go to the capture/calibration pose.

    `settle_s`: None takes `camera.settle_s`. `rng`: None draws the noise from `noise_rng(world.seed, n)`
    for the world's n-th capture (n = 0, 1, ..., counted since the world was built or last reset).
    `prefetch_noise`: the noise's random numbers are drawn on a second thread while the scene settles
    (`PrefetchedDraws`: the same numbers, only sooner), unless `prefetch_next_capture` started them earlier.
    """
    cam = settings.camera
    if cam.mount == "wrist" and move:
        q_target = cam.capture_pose if pose == "capture" or cam.calibration_pose is None else cam.calibration_pose
        world.reset_joints(np.asarray(q_target, dtype=float))
    settle = cam.settle_s if settle_s is None else float(settle_s)
    steps = int(round(settle * settings.world.physics_hz))
    late = min(steps, int(round(cam.latency_s * settings.world.physics_hz)))  # the frame is from this far back
    depth_filter = settings.perception.depth_filter
    book = _book(world)
    plan = _burst_plan(settings) if prefetch_noise and not book.off_plan else []
    draws: np.random.Generator | PrefetchedDraws
    if rng is None:
        n = book.taken
        book.taken = n + 1
        pending, book.next_draws = book.next_draws, None
        if pending is not None and pending[0] == n and pending[1].plan == plan:
            draws = pending[1]
        else:
            rng = noise_rng(world.seed, n)
            draws = PrefetchedDraws(rng, plan) if plan else rng
    else:
        draws = PrefetchedDraws(rng, plan) if plan else rng
    t0 = time.perf_counter()
    world.step(steps - late)
    t1 = time.perf_counter()
    q = world.joint_positions()
    if cam.mount == "wrist":
        T_nominal = world.robot.arm.fk(q, "flange") @ wrist_camera_offset(settings)
        T_render = true_camera_pose(cam, world.seed, world.link_matrix("tool0"))
    else:
        T_nominal = camera_pose(cam)
        T_render = true_camera_pose(cam, world.seed)
    intr = Intrinsics.from_settings(cam)
    t2 = time.perf_counter()
    clean = world.render(T_render, intr, near_m=cam.near_m, far_m=cam.far_m)
    t3 = time.perf_counter()
    if late:  # a late frame: the world goes on while it is on its way, and the joints are read on arrival
        world.step(late)
        q = world.joint_positions()
        if cam.mount == "wrist":
            T_nominal = world.robot.arm.fk(q, "flange") @ wrist_camera_offset(settings)
        t1 += time.perf_counter() - t3
    with stage("perception.noise") as noise:
        # the burst the depth filter averages: the last frames of the settling pause, one render (the scene
        # is at rest), each with its own sensor noise; the colour image is the first frame's
        frames = sensor_burst(clean, cam.noise, draws, depth_filter.temporal_frames)
        if isinstance(draws, PrefetchedDraws):
            draws.finish()
            if not draws.followed_plan:
                book.off_plan = True
    with stage("perception.depth_filter") as filtering:
        frame = filter_frames(frames, depth_filter)
    log.debug("captured a %dx%d frame at the %s pose (mount %s)", intr.width, intr.height, pose, cam.mount)
    timings = {"settle": t1 - t0, "render": t3 - t2, "noise": noise.seconds, "depth_filter": filtering.seconds}
    return Capture(frame, q, T_nominal, cam.mount, pose, timings)


def prefetch_next_capture(world: World, settings: Settings) -> None:
    """Start drawing the sensor noise of the world's next capture (that takes its noise from the world's
    stream) on a second thread: a task calls this once it has perceived a capture, so the draws run while
    the arm works (not beside perception) and are ready when the next capture settles. Changes no number."""
    plan = _burst_plan(settings)
    book = _book(world)
    n, pending = book.taken, book.next_draws
    if plan and not book.off_plan and (pending is None or pending[0] != n or pending[1].plan != plan):
        book.next_draws = (n, PrefetchedDraws(noise_rng(world.seed, n), plan))


def _burst_plan(settings: Settings) -> list[tuple[str, int]]:
    """The noise draws of one capture's burst (`burst_draws`) for this camera and depth filter."""
    cam = settings.camera
    return burst_draws(cam.noise, (cam.height, cam.width), settings.perception.depth_filter.temporal_frames)
