"""Recording does not change a run: what an observer renders never reaches what the sensors see.

The leak this guards against: PyBullet's EGL renderer draws no shadows in the first two frames of a world,
so a recorder's frames (rendered while the world steps) turned a run's first capture from a shadowless one
into a shadowed one, and the perception error of the objects changed (`twin run robocup --seed 3`: can_0
0.42 -> 0.31 mm with `--record`). On a machine without the EGL plugin every frame comes from TinyRenderer,
which has no such state, and these tests pass trivially.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from twin.camera import Intrinsics, true_camera_pose
from twin.config import load_config
from twin.perception.capture import Capture, capture_frame
from twin.recording import Recorder
from twin.world import World, WorldView

ROOT = Path(__file__).resolve().parent.parent
ROBOCUP = load_config(ROOT / "configs/robocup.yaml")


def test_a_world_renders_its_first_frame_as_it_renders_every_later_one() -> None:
    cam = ROBOCUP.camera
    with World(ROBOCUP, seed=3) as world:
        T = true_camera_pose(cam, world.seed, world.link_matrix("tool0"))
        frames = [world.render(T, Intrinsics.from_settings(cam), near_m=cam.near_m, far_m=cam.far_m) for _ in range(3)]
    for k, f in enumerate(frames[1:], start=2):
        changed = int(np.count_nonzero(f.rgb != frames[0].rgb))
        assert changed == 0, f"renderer {world.renderer}: {changed} colour values of frame {k} differ from frame 1"
        assert np.array_equal(f.depth_m, frames[0].depth_m)


def _settle_and_capture(recorder: Recorder | None) -> tuple[Capture, np.ndarray]:
    """The start of a RoboCup run: the scene settles, the wrist camera captures (settling, rendering, sensor
    noise, depth filter); returns the capture and the objects' poses after it."""
    with World(ROBOCUP, seed=3) as world:
        if recorder is not None:
            recorder.attach(world)
        world.step(int(0.25 / world.dt))
        cap = capture_frame(world, ROBOCUP)
        poses = np.array([np.concatenate(world.object_pose(i)) for i in world.object_ids()])
    return cap, poses


def test_a_recorded_capture_is_the_plain_capture(tmp_path: Path) -> None:
    plain, plain_poses = _settle_and_capture(None)
    recorder = Recorder(tmp_path / "run.mp4")
    recorded, recorded_poses = _settle_and_capture(recorder)
    assert len(recorder.frames) > 2  # it did render while the world stepped
    assert np.array_equal(recorded_poses, plain_poses)
    assert np.array_equal(recorded.q, plain.q)
    assert np.array_equal(recorded.T_base_camera_nominal, plain.T_base_camera_nominal)
    assert np.array_equal(recorded.frame.depth_m, plain.frame.depth_m)
    changed = int(np.count_nonzero(recorded.frame.rgb != plain.frame.rgb))
    assert changed == 0, f"{changed} colour values of the captured frame changed because a recorder rendered"


def test_observers_get_a_read_only_view_and_disturbers_the_world() -> None:
    seen: list[object] = []
    with World(ROBOCUP, seed=3, renderer="tiny") as world:
        world.observe(seen.append, every_s=world.dt)
        world.disturb(seen.append, every_s=world.dt)
        world.step(1)
    view, full = seen
    assert isinstance(view, WorldView) and full is world
    for name in ("step", "reset", "set_joint_targets", "reset_joints", "close_gripper", "set_object_pose"):
        assert not hasattr(view, name), name
