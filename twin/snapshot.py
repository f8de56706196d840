"""Scene snapshots for people: the configured camera's view and an overview, side by side in one PNG."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from twin.camera import OVERVIEW_EYE, OVERVIEW_TARGET, Intrinsics, look_at, true_camera_pose
from twin.config import Settings
from twin.errors import ConfigError

__all__ = ["render_views", "save_snapshot"]


def render_views(settings: Settings, *, settle_s: float = 0.5) -> dict[str, np.ndarray]:
    """RGB images (H, W, 3) of the scene of `settings` (seed included): 'camera' and 'overview'."""
    from twin.world import World

    cam = settings.camera
    intr = Intrinsics.from_settings(cam)
    with World(settings, seed=settings.seed, gui=False) as world:
        world.step(int(round(settle_s * settings.world.physics_hz)))
        T_cam = true_camera_pose(cam, world.seed, world.link_matrix("tool0"))
        views = {"camera": world.render(T_cam, intr, near_m=cam.near_m, far_m=cam.far_m).rgb}
        wide = Intrinsics(
            cam.width, cam.height, cam.width / 2.0 / np.tan(np.radians(30)), cam.width / 2.0 / np.tan(np.radians(30))
        )
        views["overview"] = world.render(look_at(OVERVIEW_EYE, OVERVIEW_TARGET), wide, near_m=0.05, far_m=6.0).rgb
    return views


def save_snapshot(settings: Settings, path: str | Path) -> Path:
    """Render `render_views` and write them side by side to `path` (PNG); returns the path written."""
    import cv2

    out = Path(path)
    if out.suffix.lower() != ".png":
        raise ConfigError(f"--snapshot must name a .png file, got {str(out)!r}")
    views = render_views(settings)
    image = np.concatenate([views["camera"], views["overview"]], axis=1)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(f"cannot write {out}: {e.strerror}") from None
    if not cv2.imwrite(str(out), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
        raise ConfigError(f"cannot write {out}")
    return out
