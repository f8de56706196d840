"""Scene snapshots for people: what the camera sees where perception uses it (a wrist camera at the
capture pose, a fixed one where it is mounted) and an overview framed on the cell with every object and
fixture named, side by side in one PNG with a title over each panel. The names (objects, fixtures, the
task's drop zones) are placed together so none is written over another (`annotate.draw_labels`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twin.annotate import Label, banner, cell_points, draw_circle_on_table, draw_labels, framed_overview
from twin.camera import Intrinsics, true_camera_pose
from twin.config import Settings
from twin.errors import ConfigError
from twin.tasks import task_landmarks

__all__ = ["SceneViews", "render_views", "save_snapshot"]

_OVERVIEW_SCALE = 1.5  # the overview is rendered this much larger than the camera image
_LABEL_LIFT_M = 0.03  # names are written this far above an object's centre
_NAME_COLOR = (255, 255, 255)
_ZONE_COLOR = (255, 230, 120)  # a drop zone's circle and name


@dataclass(frozen=True)
class SceneViews:
    """The two panels of a snapshot (RGB, H x W x 3) and what each shows."""

    camera: np.ndarray
    camera_title: str
    overview: np.ndarray
    overview_title: str
    camera_pose: np.ndarray  # (4, 4) where each view was rendered from (base frame, OpenCV camera)
    overview_pose: np.ndarray
    overview_intrinsics: Intrinsics
    points: np.ndarray  # (N, 3) what the overview frames: bodies and robot links (`annotate.cell_points`)
    labels: tuple[Label, ...] = ()  # the names written on the overview, where (no two boxes overlap)


def _overview_intrinsics(settings: Settings) -> Intrinsics:
    w, h = (int(round(_OVERVIEW_SCALE * v)) for v in (settings.camera.width, settings.camera.height))
    f = w / 2.0 / np.tan(np.radians(30))  # 60 degrees across
    return Intrinsics(w, h, f, f)


def render_views(settings: Settings, *, settle_s: float = 0.5) -> SceneViews:
    """Render the scene of `settings` (its seed): the camera from the pose perception uses it at (a wrist
    camera with the arm at `camera.capture_pose`, as the task's capture stage puts it; the mount error
    of the seed included) and the labelled overview."""
    from twin.world import World  # lazy: pybullet

    cam = settings.camera
    intr = Intrinsics.from_settings(cam)
    with World(settings, seed=settings.seed, gui=False) as world:
        if cam.mount == "wrist":
            world.reset_joints(cam.capture_pose)
        world.step(int(round(settle_s * settings.world.physics_hz)))
        T_cam = true_camera_pose(cam, world.seed, world.link_matrix("tool0"))
        image = world.render(T_cam, intr, near_m=cam.near_m, far_m=cam.far_m).rgb
        where = "wrist, arm at the capture pose" if cam.mount == "wrist" else "fixed mount"
        camera_title = f"camera ({where}): what perception sees"
        wide = _overview_intrinsics(settings)
        objects = world.objects()
        named = [(o.position + [0.0, 0.0, _LABEL_LIFT_M], o.name, _NAME_COLOR) for o in objects]
        named += [
            (np.asarray(f.position, dtype=float), f.name, _NAME_COLOR)
            for f in settings.world.fixtures
            if f.name != "table"
        ]
        points = cell_points(world)
        T_over = framed_overview(points, wide)
        overview = np.ascontiguousarray(world.render(T_over, wide, near_m=0.05, far_m=8.0).rgb)
    for mark in task_landmarks(settings):
        draw_circle_on_table(overview, T_over, wide, mark, color=_ZONE_COLOR, name=False)
        named.append((np.asarray(mark.position, dtype=float), mark.name, _ZONE_COLOR))
    labels = draw_labels(overview, T_over, wide, named)
    return SceneViews(
        camera=image,
        camera_title=camera_title,
        overview=overview,
        overview_title=f"overview: {settings.name}, seed {world.seed}, {len(objects)} objects",
        camera_pose=T_cam,
        overview_pose=T_over,
        overview_intrinsics=wide,
        points=points,
        labels=tuple(labels),
    )


def _panel(image: np.ndarray, title: str, height: int) -> np.ndarray:
    import cv2

    if image.shape[0] != height:
        width = int(round(image.shape[1] * height / image.shape[0]))
        image = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    return banner(image, title)


def save_snapshot(settings: Settings, path: str | Path) -> Path:
    """Render `render_views` and write them side by side, titled, to `path` (PNG); returns the path."""
    import cv2

    out = Path(path)
    if out.suffix.lower() != ".png":
        raise ConfigError(f"--snapshot must name a .png file, got {str(out)!r}")
    views = render_views(settings)
    height = views.overview.shape[0]
    image = np.concatenate(
        [_panel(views.camera, views.camera_title, height), _panel(views.overview, views.overview_title, height)],
        axis=1,
    )
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(f"cannot write {out}: {e.strerror}") from None
    if not cv2.imwrite(str(out), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
        raise ConfigError(f"cannot write {out}")
    return out
