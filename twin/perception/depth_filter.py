"""Depth post-processing before perception, as a RealSense pipeline does it on the host.

A stereo camera's depth error is largely independent from frame to frame and from pixel to pixel, so the
SDK's post-processing blocks average it away where the scene holds still (the part that is the same in
every frame, `camera.noise.static_fraction` in the sensor model, no averaging over time removes):

- temporal: the per-pixel mean of the valid depths over the last frames of the settling pause (the
  camera streams at 30 fps; the reference systems took one frame after a 1-3 s pause, so the frames are
  there for the taking); a pixel that is valid in fewer than `min_valid_fraction` of them stays a hole
  (the SDK's "persistency");
- spatial: an edge-preserving (bilateral) filter whose range sigma follows the noise measured in the
  frame itself, so depth steps at object edges are not smeared into the table.

`depth_noise_coefficient` measures the noise of a frame from the differences of neighbouring pixels
(the D435i model: RMS = c * z^2), so neither filter needs to be told how noisy the sensor is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from twin.camera import RGBDFrame
from twin.config import DepthFilterSettings

__all__ = ["depth_noise_coefficient", "filter_frames", "spatial_filter", "temporal_average"]

_MAD_TO_SIGMA = 1.4826  # a Gaussian's standard deviation per median absolute deviation


def temporal_average(frames: Sequence[RGBDFrame], min_valid_fraction: float = 0.5) -> RGBDFrame:
    """The per-pixel mean of the valid depths of `frames` (same camera, scene at rest), colour of the
    first; pixels valid in fewer than ceil(min_valid_fraction * len(frames)) frames are holes (0)."""
    if not frames:
        raise ValueError("temporal_average needs at least one frame")
    if len(frames) == 1:
        return frames[0]
    total = np.zeros(frames[0].depth_m.shape, dtype=np.float64)
    count = np.zeros(frames[0].depth_m.shape, dtype=np.int32)
    for f in frames:
        valid = f.depth_m > 0
        total += f.depth_m  # holes add 0
        count += valid
    need = max(1, math.ceil(min_valid_fraction * len(frames)))
    depth = np.divide(total, count, out=np.zeros_like(total), where=count >= need)
    return RGBDFrame(frames[0].rgb, depth, frames[0].intrinsics)


def depth_noise_coefficient(depth_m: np.ndarray) -> float:
    """c in RMS = c * z^2, measured from three horizontally neighbouring valid pixels: their second
    difference a - 2b + c, over z^2, is noise times sqrt(6) on any smooth surface, tilted ones too (a
    slope cancels), and the median ignores the few depth edges. 0.0 when no three neighbours are valid."""
    a, b, c = depth_m[:, :-2], depth_m[:, 1:-1], depth_m[:, 2:]
    ok = (a > 0) & (b > 0) & (c > 0)
    if not ok.any():
        return 0.0
    zb = b[ok]
    rel = np.abs(a[ok] - 2.0 * zb + c[ok]) / (zb * zb)
    return float(_MAD_TO_SIGMA * np.median(rel) / math.sqrt(6.0))


def spatial_filter(depth_m: np.ndarray, noise_coefficient: float, *, radius_px: int, range_sigmas: float) -> np.ndarray:
    """Bilateral filter of the depth image (holes stay holes): neighbours within `radius_px` are averaged
    when their depth is within a few `range_sigmas` of the expected noise at the frame's median depth;
    the unchanged depth when the noise is 0."""
    import cv2

    valid = depth_m > 0
    if noise_coefficient <= 0 or not valid.any():
        return depth_m
    z = float(np.median(depth_m[valid]))
    sigma_range = range_sigmas * noise_coefficient * z * z
    # a hole (0) differs from any surface by far more than sigma_range, so it gets no weight and takes none
    out = cv2.bilateralFilter(depth_m.astype(np.float32), 2 * radius_px + 1, sigma_range, radius_px / 2.0)
    out = out.astype(np.float64)
    out[~valid] = 0.0
    return out


def filter_frames(frames: Sequence[RGBDFrame], settings: DepthFilterSettings) -> RGBDFrame:
    """The frame perception gets from a burst: the temporal average, then the spatial filter if on."""
    frame = temporal_average(frames, settings.min_valid_fraction)
    if not settings.spatial:
        return frame
    c = depth_noise_coefficient(frame.depth_m)
    depth = spatial_filter(
        frame.depth_m, c, radius_px=settings.spatial_radius_px, range_sigmas=settings.spatial_range_sigmas
    )
    return RGBDFrame(frame.rgb, depth, frame.intrinsics)
