"""Video of a run from the overview camera: frames sampled while the world steps, written as MP4 or GIF."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from twin.camera import OVERVIEW_EYE, OVERVIEW_TARGET, Intrinsics, look_at
from twin.errors import ConfigError

if TYPE_CHECKING:
    from twin.world import World, WorldView

__all__ = ["Recorder"]

_SUFFIXES = (".mp4", ".gif")


class Recorder:
    """Attach to a world with `Recorder(path).attach(world)`; `save()` writes the file.

    It sees the world only through the read-only `WorldView` an observer gets, so a recorded run is the
    run without the recorder (tests/test_record_parity.py)."""

    def __init__(self, path: str | Path, *, fps: float = 10.0, width: int = 480, height: int = 360):
        self.path = Path(path)
        if self.path.suffix.lower() not in _SUFFIXES:
            raise ConfigError(f"--record must end in .mp4 or .gif, got {str(self.path)!r}")
        self.fps = float(fps)
        f = width / 2.0 / np.tan(np.radians(30))
        self.intr = Intrinsics(width, height, f, f)
        self.T = look_at(OVERVIEW_EYE, OVERVIEW_TARGET)
        self.frames: list[np.ndarray] = []

    def attach(self, world: World) -> Recorder:
        world.observe(self._grab, every_s=1.0 / self.fps)
        self._grab(world.view())
        return self

    def _grab(self, world: WorldView) -> None:
        self.frames.append(world.render(self.T, self.intr, near_m=0.05, far_m=6.0).rgb)

    def save(self) -> Path:
        if not self.frames:
            raise ConfigError("nothing was recorded")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise ConfigError(f"cannot write {self.path}: {e.strerror}") from None
        if self.path.suffix.lower() == ".gif":
            try:
                from PIL import Image
            except ImportError:
                raise ConfigError("writing a GIF needs Pillow (pip install 'twin[plots]'); use .mp4 instead") from None
            imgs = [Image.fromarray(f) for f in self.frames]
            imgs[0].save(self.path, save_all=True, append_images=imgs[1:], duration=int(1000 / self.fps), loop=0)
        else:
            import cv2

            h, w = self.frames[0].shape[:2]
            out = cv2.VideoWriter(str(self.path), cv2.VideoWriter.fourcc(*"mp4v"), self.fps, (w, h))
            if not out.isOpened():
                raise ConfigError(f"cannot write {self.path}")
            for f in self.frames:
                out.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
            out.release()
        return self.path
