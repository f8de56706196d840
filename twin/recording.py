"""Video of a run from an overview camera framed on the cell: frames sampled while the world steps (every
`speed / fps` simulated seconds, so the video plays `speed` times faster than the run), each under a
caption with the simulated time, the speed-up and the stage in progress, with the task's landmarks (the
warehouse's drop zones) drawn on the table; written as MP4 or GIF."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from twin.annotate import banner, cell_points, draw_circle_on_table, framed_overview
from twin.camera import Intrinsics
from twin.errors import ConfigError
from twin.types import Landmark

if TYPE_CHECKING:
    from twin.world import World, WorldView

__all__ = ["Recorder"]

_SUFFIXES = (".mp4", ".gif")
_MAX_SPEED = 100.0


class Recorder:
    """Attach to a world with `Recorder(path).attach(world)`, tell it the stage in progress with `stage()`;
    `save()` writes the file.

    It sees the world only through the read-only `WorldView` an observer gets, so a recorded run is the
    run without the recorder (tests/test_record_parity.py)."""

    def __init__(
        self,
        path: str | Path,
        *,
        fps: float = 10.0,
        width: int = 480,
        height: int = 360,
        speed: float = 1.0,
        landmarks: Sequence[Landmark] = (),
    ):
        self.path = Path(path)
        if self.path.suffix.lower() not in _SUFFIXES:
            raise ConfigError(f"--record must end in .mp4 or .gif, got {str(self.path)!r}")
        if not 0.0 < speed <= _MAX_SPEED:
            raise ConfigError(f"--speed must be above 0 and at most {_MAX_SPEED:g} (times real time), got {speed:g}")
        self.fps = float(fps)
        self.speed = float(speed)
        f = width / 2.0 / np.tan(np.radians(30))
        self.intr = Intrinsics(width, height, f, f)
        self.T = np.eye(4)
        self.landmarks = tuple(landmarks)
        self.caption = ""
        self.frames: list[np.ndarray] = []

    def attach(self, world: World) -> Recorder:
        view = world.view()
        self.T = framed_overview(cell_points(view), self.intr)
        world.observe(self._grab, every_s=self.speed / self.fps)
        self._grab(view)
        return self

    def stage(self, text: str) -> None:
        """The stage in progress (what the task works on and the stage), shown under the time from now on."""
        self.caption = text

    def _grab(self, world: WorldView) -> None:
        image = np.ascontiguousarray(world.render(self.T, self.intr, near_m=0.05, far_m=8.0).rgb)
        for mark in self.landmarks:
            draw_circle_on_table(image, self.T, self.intr, mark, color=(255, 230, 120), scale=0.35)
        head = f"t {world.sim_time:6.1f} s  x{self.speed:g}" + (f"  {self.caption}" if self.caption else "")
        self.frames.append(banner(image, head, height=22, scale=0.42))

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
