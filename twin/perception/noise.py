"""A RealSense D435i-like sensor model applied to rendered frames (rendering itself is noise-free).

Depth error grows with the square of the distance, as for any stereo camera: RMS = z^2 * subpixel /
(focal_px * baseline_m), Intel's own model (~1 mm at 0.5 m, ~4 mm at 1 m, ~15 mm at 2 m with the
defaults). Invalid pixels (depth 0) appear at random and, more often, at depth edges where a stereo
matcher loses the correspondence. Depth is quantised to the sensor's depth unit and limited to its range.
Everything is drawn from a caller-supplied generator, so a seed reproduces the frame exactly.
"""

from __future__ import annotations

import numpy as np

from twin.camera import RGBDFrame
from twin.config import DepthNoiseSettings

__all__ = ["apply_sensor_noise", "depth_noise_rms", "sensor_burst"]


def depth_noise_rms(z_m: np.ndarray | float, noise: DepthNoiseSettings) -> np.ndarray:
    """RMS depth error (m) at depth z (m): z^2 * subpixel / (focal_px * baseline_m), times `noise.scale`."""
    z = np.asarray(z_m, dtype=float)
    return z * z * (noise.subpixel * noise.scale) / (noise.focal_px * noise.baseline_m)


def _depth_edges(depth: np.ndarray, threshold_m: float) -> np.ndarray:
    """Pixels with a 4-neighbour whose depth differs by more than the threshold (or is invalid)."""
    d = depth
    edge = np.zeros(d.shape, dtype=bool)
    jump_x = np.abs(np.diff(d, axis=1)) > threshold_m
    jump_y = np.abs(np.diff(d, axis=0)) > threshold_m
    edge[:, :-1] |= jump_x
    edge[:, 1:] |= jump_x
    edge[:-1, :] |= jump_y
    edge[1:, :] |= jump_y
    return edge


def apply_sensor_noise(
    frame: RGBDFrame,
    noise: DepthNoiseSettings,
    rng: np.random.Generator,
    *,
    rgb_noise: bool = True,
    static: np.ndarray | None = None,
) -> RGBDFrame:
    """A copy of `frame` with D435i-like depth noise, dropouts and colour noise; unchanged when disabled.

    `rgb_noise` False leaves the colour image as rendered and draws nothing for it (the extra frames of a
    burst, whose colour nobody uses). `static`: the capture's standard-normal field (H, W) behind the
    `static_fraction` of the noise variance that repeats in every frame (drawn here when None and needed).
    """
    if not noise.enabled:
        return frame
    # The same draws in the same order and the same arithmetic as the plain formulas; what is saved is
    # gathering and scattering when every pixel has depth (the usual case) and temporary arrays.
    depth = frame.depth_m.astype(np.float64, copy=True)
    valid = depth > 0
    all_valid = bool(valid.all())
    edges = _depth_edges(depth, noise.edge_threshold_m)
    if not all_valid:
        edges &= valid
    n_valid = depth.size if all_valid else int(np.count_nonzero(valid))
    s = noise.static_fraction
    if s > 0:  # a share of the variance fixed for the capture, the rest new in every frame
        if static is None:
            static = rng.standard_normal(depth.shape)
        e = rng.standard_normal(depth.shape) * np.sqrt(1.0 - s) + static * np.sqrt(s)
        depth[valid] += (e * depth_noise_rms(depth, noise))[valid]
    elif all_valid:
        depth += rng.standard_normal(n_valid).reshape(depth.shape) * depth_noise_rms(depth, noise)
    else:
        depth[valid] += rng.standard_normal(n_valid) * depth_noise_rms(depth[valid], noise)
    drop = rng.random(depth.shape) < noise.dropout_fraction
    drop |= edges & (rng.random(depth.shape) < noise.edge_dropout_fraction)
    drop |= depth < noise.min_range_m
    drop |= depth > noise.max_range_m
    if noise.depth_unit_m > 0:
        depth /= noise.depth_unit_m
        np.round(depth, out=depth)
        depth *= noise.depth_unit_m
    if not all_valid:
        drop |= ~valid
    depth[drop] = 0.0
    rgb = frame.rgb
    if rgb_noise and noise.color_gain != (1.0, 1.0, 1.0):  # the light's colour, before the sensor's noise
        rgb = np.clip(np.rint(rgb * np.asarray(noise.color_gain, dtype=np.float32)), 0, 255).astype(np.uint8)
    if rgb_noise and noise.rgb_noise_std > 0:
        noisy = rng.standard_normal(rgb.shape).astype(np.float32)
        noisy *= noise.rgb_noise_std
        noisy += rgb  # uint8 + float32 -> float32: the same sum as rgb.astype(float32) + noise
        np.rint(noisy, out=noisy)
        np.clip(noisy, 0, 255, out=noisy)
        rgb = noisy.astype(np.uint8)
    return RGBDFrame(rgb, depth, frame.intrinsics)


def sensor_burst(frame: RGBDFrame, noise: DepthNoiseSettings, rng: np.random.Generator, n: int) -> list[RGBDFrame]:
    """`n` frames of a scene at rest (one rendered `frame`), each with its own sensor noise, sharing the
    capture's static share of it; colour noise on the first only. n = 1 is `apply_sensor_noise` itself."""
    static = rng.standard_normal(frame.depth_m.shape) if noise.enabled and noise.static_fraction > 0 else None
    out = [apply_sensor_noise(frame, noise, rng, static=static)]
    out += [apply_sensor_noise(frame, noise, rng, rgb_noise=False, static=static) for _ in range(n - 1)]
    return out
