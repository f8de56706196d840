"""Pictures for newcomers: `twin scene --snapshot` shows the camera where perception uses it (a wrist camera
at the capture pose) beside an overview framed on the cell with names on it; `--record` videos are framed
the same way, say the time, the speed-up and the stage, draw the warehouse's drop zones, and `--speed`
shortens them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.cli_runner import twin
from twin.annotate import place_labels, project
from twin.camera import Intrinsics, true_camera_pose
from twin.config import load_config
from twin.errors import ConfigError
from twin.recording import Recorder
from twin.snapshot import render_views
from twin.tasks import task_landmarks
from twin.world import World

ROOT = Path(__file__).resolve().parent.parent


def _inside(T: np.ndarray, intr: Intrinsics, p: np.ndarray) -> bool:
    uv = project(T, intr, p)
    return uv is not None and 0 <= uv[0] < intr.width and 0 <= uv[1] < intr.height


def test_the_wrist_camera_is_shown_where_perception_uses_it_and_the_overview_frames_the_cell() -> None:
    settings = load_config(ROOT / "configs/robocup.yaml", ["seed=3"])
    views = render_views(settings)
    cam = Intrinsics.from_settings(settings.camera)
    with World(settings, seed=3) as world:  # the arm at its home pose
        objects = [o.position for o in world.objects()]
        home_camera = true_camera_pose(settings.camera, world.seed, world.link_matrix("tool0"))
    # at the capture pose every object is in the wrist camera's image; at the home pose (the old snapshot) not
    assert all(_inside(views.camera_pose, cam, p) for p in objects)
    assert not all(_inside(home_camera, cam, p) for p in objects)
    assert "capture pose" in views.camera_title
    # the overview holds every body and robot link, and they fill it: the outermost is near an edge
    wide = views.overview_intrinsics
    pixels = np.array([project(views.overview_pose, wide, p) for p in views.points], dtype=float)
    assert np.all((pixels >= 0) & (pixels < [wide.width, wide.height]))
    spread = (pixels.max(axis=0) - pixels.min(axis=0)) / [wide.width, wide.height]
    assert spread.max() > 0.6, spread  # the old fixed overview left the cell in a third of the image
    assert views.overview.shape == (wide.height, wide.width, 3)


def test_the_snapshot_writes_two_titled_panels(tmp_path: Path) -> None:
    out = tmp_path / "scene.png"
    r = twin("scene", str(ROOT / "configs/warehouse.yaml"), "--snapshot", str(out))
    assert r.returncode == 0, r.stderr
    import cv2

    image = cv2.imread(str(out))
    assert image is not None and image.shape[1] > image.shape[0]  # side by side
    strip = image[:20]
    assert strip.mean() < 60 and strip.max() > 200  # a dark title strip with light text over the panels


def _apart(boxes: list[tuple[int, int, int, int]]) -> bool:
    return all(
        a[2] <= b[0] or b[2] <= a[0] or a[3] <= b[1] or b[3] <= a[1]
        for i, a in enumerate(boxes)
        for b in boxes[i + 1 :]
    )


@pytest.mark.parametrize("config", ["warehouse.yaml", "robocup.yaml"])
def test_the_overview_writes_every_name_near_its_point_and_none_over_another(config: str) -> None:
    """The warehouse of the report wrote 'warehouse_cube_green_0' over 'warehouse_cube_red_0' and 'obstacle'
    over 'green drop'; robocup 'can_0' against 'aruco_plate'."""
    settings = load_config(ROOT / "configs" / config)
    views = render_views(settings)
    labels = views.labels
    with World(settings, seed=settings.seed) as world:
        objects = {o.name for o in world.objects()}
    names = {label.text for label in labels}
    assert objects <= names and "aruco_plate" in names
    assert {m.name for m in task_landmarks(settings)} <= names  # the drop zones are placed with the rest
    boxes = [label.box for label in labels]
    assert _apart(boxes), [(label.text, label.box) for label in labels]
    h, w = views.overview.shape[:2]
    for label in labels:
        x0, y0, x1, y1 = label.box
        assert 0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h
        u, v = label.anchor  # within a few lines of its point: read as its name
        assert max(x0 - u, u - x1, 0) + max(y0 - v, v - y1, 0) < 80, label


def test_labels_crowded_on_one_row_are_pushed_apart() -> None:
    """Five long names on points 20 px apart on one row: each written beside its point would cover the next."""
    anchors = [(100 + 20 * i, 200) for i in range(5)]
    boxes = place_labels(anchors, [(150, 14)] * 5, (400, 640))
    assert _apart(boxes)
    assert boxes[0] == (104, 182, 254, 196)  # the first (leftmost, on top) where a single label goes: right-above
    assert all(0 <= b[0] and b[2] <= 640 and 0 <= b[1] and b[3] <= 400 for b in boxes)


def test_the_warehouse_task_names_its_drop_zones() -> None:
    settings = load_config(ROOT / "configs/warehouse.yaml")
    marks = task_landmarks(settings)
    zones = settings.task.warehouse.drop_zones
    assert [m.name for m in marks] == [f"{c} drop" for c in zones]
    assert all(m.radius_m == settings.task.warehouse.drop_radius_m for m in marks)
    assert task_landmarks(load_config(ROOT / "configs/robocup.yaml")) == []  # its bins are bodies already


def test_a_recording_plays_faster_with_speed_and_captions_each_frame(tmp_path: Path) -> None:
    settings = load_config(ROOT / "configs/warehouse.yaml")
    frames = {}
    for speed in (1.0, 4.0):
        rec = Recorder(tmp_path / f"x{speed:g}.mp4", speed=speed, landmarks=task_landmarks(settings))
        with World(settings, seed=0) as world:
            rec.attach(world)
            rec.stage("red cube: transfer")
            world.step(int(round(2.0 / world.dt)))
        frames[speed] = rec.frames
        assert rec.caption == "red cube: transfer"
        rec.save()
        assert (tmp_path / f"x{speed:g}.mp4").stat().st_size > 0
    # 2 s simulated at 10 frames per second of video: 21 frames at real time, 6 at 4x
    assert len(frames[1.0]) == 21 and len(frames[4.0]) == 6
    first = frames[1.0][0]
    assert first.shape == (360 + 22, 480, 3)  # the caption strip over the 480 x 360 view
    assert first[:22].mean() < 80 and first[:22].max() > 200
    # the drop zones are drawn: the pale yellow of their circles is in the frame, not in a plain render
    yellowish = np.all(np.abs(first[22:].astype(int) - [255, 230, 120]) < 12, axis=-1)
    assert int(yellowish.sum()) > 50


def test_a_bad_speed_is_a_one_line_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="--speed must be above 0"):
        Recorder(tmp_path / "x.mp4", speed=0.0)
    r = twin("run", str(ROOT / "configs/warehouse.yaml"), "--record", str(tmp_path / "x.mp4"), "--speed", "-2")
    assert r.returncode == 2 and "--speed must be above 0" in r.stderr and "Traceback" not in r.stderr
