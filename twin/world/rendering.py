"""A `World`'s camera images: the EGL renderer plugin (or TinyRenderer) and RGB-D frames from PyBullet."""

from __future__ import annotations

import importlib.util
import logging

import numpy as np

from twin.camera import Intrinsics, RGBDFrame, depth_from_zbuffer, gl_projection_matrix, gl_view_matrix, look_at
from twin.timing import stage
from twin.world.bullet import pb, quiet_fds, quiet_stdout

__all__ = ["EGL_WARM_UP_FRAMES", "load_egl_renderer", "render_rgbd", "warm_up_egl"]

log = logging.getLogger("twin")

# PyBullet's EGL renderer draws no shadows in the first two frames a physics client renders (measured: one
# camera rendered 6 times gives frames 1-2 without shadows, 3-6 identical with them; other cameras or sizes
# count the same; `reset()` keeps the count). A frame's colours then depended on how many frames anyone had
# rendered before it: a recorder's frames made a run's first capture a shadowed one. `World.render` renders
# these frames first, unseen, so every frame it returns depends on the scene and the camera alone.
EGL_WARM_UP_FRAMES = 2


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


def render_rgbd(
    client_id: int, egl: bool, T_world_camera: np.ndarray, intrinsics: Intrinsics, near_m: float, far_m: float
) -> RGBDFrame:
    """An RGB-D frame from an OpenCV-convention camera pose (4, 4) with pinhole intrinsics, by the EGL
    renderer (warmed up: `warm_up_egl`) or TinyRenderer. Depth is converted from PyBullet's non-linear
    z-buffer to metres along the optical axis."""
    with stage("rendering"), quiet_stdout(egl):
        _, _, rgba, zbuf, _ = pb.getCameraImage(
            intrinsics.width,
            intrinsics.height,
            viewMatrix=gl_view_matrix(T_world_camera),
            projectionMatrix=gl_projection_matrix(intrinsics, near_m, far_m),
            renderer=pb.ER_BULLET_HARDWARE_OPENGL if egl else pb.ER_TINY_RENDERER,
            flags=pb.ER_NO_SEGMENTATION_MASK,
            physicsClientId=client_id,
        )
    rgb = np.asarray(rgba, dtype=np.uint8).reshape(intrinsics.height, intrinsics.width, 4)[:, :, :3].copy()
    zb = np.asarray(zbuf, dtype=np.float64).reshape(intrinsics.height, intrinsics.width)
    return RGBDFrame(rgb, depth_from_zbuffer(zb, near_m, far_m), intrinsics)
