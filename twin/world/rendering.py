"""A `World`'s camera images: the EGL renderer plugin (or TinyRenderer) and RGB-D frames from PyBullet."""

from __future__ import annotations

import importlib.util
import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from twin.camera import Intrinsics, RGBDFrame, depth_from_zbuffer, gl_projection_matrix, gl_view_matrix, look_at
from twin.config import LightSettings
from twin.timing import stage
from twin.world.bullet import pb, quiet_fds, quiet_stdout

__all__ = [
    "EGL_WARM_UP_FRAMES",
    "Light",
    "jittered_light",
    "load_egl_renderer",
    "render_labelled",
    "scene_light",
    "warm_up_egl",
]

log = logging.getLogger("twin")

# PyBullet's EGL renderer draws no shadows in the first two frames a physics client renders (measured: one
# camera rendered 6 times gives frames 1-2 without shadows, 3-6 identical with them; other cameras or sizes
# count the same; `reset()` keeps the count). A frame's colours then depended on how many frames anyone had
# rendered before it: a recorder's frames made a run's first capture a shadowed one. `World.render` renders
# these frames first, unseen, so every frame it returns depends on the scene and the camera alone.
EGL_WARM_UP_FRAMES = 2


# the direction a jittered light tilts from when `world.light.direction` is not set (up, a little from the side)
_NOMINAL_LIGHT = (0.3, -0.2, 1.0)


@dataclass(frozen=True)
class Light:
    """A frame's light: direction from the scene towards it (3,), world frame, unit; RGB colour (3,)."""

    direction: np.ndarray
    color: np.ndarray


def scene_light(cfg: LightSettings, seed: int) -> Light | None:
    """The light of scene `seed` under `world.light`: None (PyBullet's own light) when it is off; otherwise
    `jittered_light` of its direction and colour, drawn from the seed (a stream of its own)."""
    jitter = cfg.direction_jitter_deg > 0 or cfg.color_jitter > 0
    if cfg.direction is None and not jitter and cfg.color == (1.0, 1.0, 1.0):
        return None
    d = np.asarray(cfg.direction if cfg.direction is not None else _NOMINAL_LIGHT, dtype=float)
    if not jitter:
        return Light(d / np.linalg.norm(d), np.asarray(cfg.color, dtype=float))
    rng = np.random.default_rng([seed, 43])
    return jittered_light(d, cfg.color, cfg.direction_jitter_deg, cfg.color_jitter, rng)


def jittered_light(
    direction: ArrayLike, color: ArrayLike, tilt_deg: float, color_jitter: float, rng: np.random.Generator
) -> Light:
    """A light tilted from `direction` by up to `tilt_deg` (uniform over the spherical cap: cos(tilt)
    uniform in [cos(max), 1], azimuth uniform) with each channel of `color` scaled by a factor drawn from
    [1 - color_jitter, 1 + color_jitter]; drawn from `rng` in that order (scene lights, `twin.dataset`)."""
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    cos_t = rng.uniform(math.cos(math.radians(tilt_deg)), 1.0)
    az = rng.uniform(0.0, 2.0 * math.pi)
    a = np.cross([0.0, 1.0, 0.0] if abs(d[1]) < 0.9 else [1.0, 0.0, 0.0], d)  # straight up: a = x, b = y
    a /= np.linalg.norm(a)
    b = np.cross(d, a)
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    d = cos_t * d + sin_t * (math.cos(az) * a + math.sin(az) * b)
    scale = rng.uniform(1.0 - color_jitter, 1.0 + color_jitter, 3)
    return Light(d, np.clip(np.asarray(color, dtype=float) * scale, 0.0, 3.0))


def load_egl_renderer(client_id: int) -> bool:
    """Load the EGL renderer into a client before any body exists (bodies created earlier render blank).
    False when it cannot be loaded: the software TinyRenderer renders then."""
    try:
        spec = importlib.util.find_spec("eglRenderer")
        if spec is not None and spec.origin:
            with quiet_fds(1, 2):  # "EGL device choice: -1 of 1." on stderr, banners on stdout
                plugin = pb.loadPlugin(spec.origin, "_eglRendererPlugin", physicsClientId=client_id)
            if plugin >= 0:
                return True
    except Exception as e:  # noqa: BLE001 - any failure means: use the software TinyRenderer
        log.debug("EGL renderer unavailable (%s), using TinyRenderer", e)
    return False


def warm_up_egl(client_id: int) -> None:
    """Render the EGL renderer's shadowless first frames (`EGL_WARM_UP_FRAMES`), 1x1, unseen."""
    view = gl_view_matrix(look_at((1.0, 0.0, 1.0), (0.0, 0.0, 0.0)))
    projection = gl_projection_matrix(Intrinsics(1, 1, 1.0, 1.0), 0.05, 5.0)
    with stage("rendering"), quiet_stdout():
        for _ in range(EGL_WARM_UP_FRAMES):
            pb.getCameraImage(
                1,
                1,
                viewMatrix=view,
                projectionMatrix=projection,
                renderer=pb.ER_BULLET_HARDWARE_OPENGL,
                flags=pb.ER_NO_SEGMENTATION_MASK,
                physicsClientId=client_id,
            )


def render_labelled(
    client_id: int,
    egl: bool,
    T_world_camera: np.ndarray,
    intrinsics: Intrinsics,
    near_m: float,
    far_m: float,
    light: Light | None = None,
    *,
    segmentation: bool = True,
) -> tuple[RGBDFrame, np.ndarray | None]:
    """An RGB-D frame from an OpenCV-convention camera pose (4, 4) with pinhole intrinsics, by the EGL
    renderer (warmed up: `warm_up_egl`) or TinyRenderer, under `light` (None: PyBullet's own), and with
    `segmentation` the body id seen at each pixel (H, W) int32, -1 where no body is (a labelled dataset's
    ground truth: `twin.dataset`). Depth is converted from PyBullet's non-linear z-buffer to metres along
    the optical axis."""
    lit = {} if light is None else {"lightDirection": light.direction.tolist(), "lightColor": light.color.tolist()}
    with stage("rendering"), quiet_stdout(egl):
        _, _, rgba, zbuf, seg = pb.getCameraImage(
            intrinsics.width,
            intrinsics.height,
            viewMatrix=gl_view_matrix(T_world_camera),
            projectionMatrix=gl_projection_matrix(intrinsics, near_m, far_m),
            renderer=pb.ER_BULLET_HARDWARE_OPENGL if egl else pb.ER_TINY_RENDERER,
            flags=0 if segmentation else pb.ER_NO_SEGMENTATION_MASK,
            physicsClientId=client_id,
            **lit,
        )
    h, w = intrinsics.height, intrinsics.width
    rgb = np.asarray(rgba, dtype=np.uint8).reshape(h, w, 4)[:, :, :3].copy()
    zb = np.asarray(zbuf, dtype=np.float64).reshape(h, w)
    ids = None
    if segmentation:
        raw = np.asarray(seg, dtype=np.int64).reshape(h, w)
        ids = np.where(raw < 0, -1, raw & ((1 << 24) - 1)).astype(np.int32)  # the body; the link sits above bit 24
    return RGBDFrame(rgb, depth_from_zbuffer(zb, near_m, far_m), intrinsics), ids
