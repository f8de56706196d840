"""A RealSense D435i-like sensor model applied to rendered frames (rendering itself is noise-free).

Depth error grows with the square of the distance, as for any stereo camera: RMS = z^2 * subpixel /
(focal_px * baseline_m), Intel's own model (~1 mm at 0.5 m, ~4 mm at 1 m, ~15 mm at 2 m with the
defaults). Invalid pixels (depth 0) appear at random and, more often, at depth edges where a stereo
matcher loses the correspondence. Depth is quantised to the sensor's depth unit and limited to its range.
Everything is drawn from a caller-supplied generator, so a seed reproduces the frame exactly;
`PrefetchedDraws` draws a burst's numbers ahead on a second thread, the same numbers.
"""

from __future__ import annotations

import copy
import sys
import threading
from dataclasses import dataclass

import numpy as np

from twin.camera import RGBDFrame
from twin.config import DepthNoiseSettings

__all__ = ["PrefetchedDraws", "apply_sensor_noise", "burst_draws", "depth_noise_rms", "sensor_burst"]


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


@dataclass(frozen=True)
class _CleanDepth:
    """What the sensor model reads from a rendered depth image before it adds anything: the same for every
    frame of a burst (one render), so a burst works it out once."""

    valid: np.ndarray  # (H, W) bool: has depth
    all_valid: bool
    edges: np.ndarray  # (H, W) bool: valid pixels at a depth jump
    rms: np.ndarray  # (H, W) RMS depth error of each pixel, m

    @classmethod
    def of(cls, depth_m: np.ndarray, noise: DepthNoiseSettings) -> _CleanDepth:
        depth = np.asarray(depth_m, dtype=np.float64)
        valid = depth > 0
        all_valid = bool(valid.all())
        edges = _depth_edges(depth, noise.edge_threshold_m)
        if not all_valid:
            edges &= valid
        return cls(valid, all_valid, edges, depth_noise_rms(depth, noise))


def apply_sensor_noise(
    frame: RGBDFrame,
    noise: DepthNoiseSettings,
    rng: np.random.Generator | PrefetchedDraws,
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
    return _noisy(frame, _CleanDepth.of(frame.depth_m, noise), noise, rng, rgb_noise=rgb_noise, static=static)


def _noisy(
    frame: RGBDFrame,
    clean: _CleanDepth,
    noise: DepthNoiseSettings,
    rng: np.random.Generator | PrefetchedDraws,
    *,
    rgb_noise: bool,
    static: np.ndarray | None,
) -> RGBDFrame:
    # The same draws in the same order and the same arithmetic as the plain formulas; what is saved is
    # gathering and scattering when every pixel has depth (the usual case) and temporary arrays.
    depth = frame.depth_m.astype(np.float64, copy=True)
    valid, all_valid, edges = clean.valid, clean.all_valid, clean.edges
    n_valid = depth.size if all_valid else int(np.count_nonzero(valid))
    s = noise.static_fraction
    if s > 0:  # a share of the variance fixed for the capture, the rest new in every frame
        if static is None:
            static = rng.standard_normal(depth.shape)
        e = rng.standard_normal(depth.shape) * np.sqrt(1.0 - s) + static * np.sqrt(s)
        depth[valid] += (e * clean.rms)[valid]
    elif all_valid:
        depth += rng.standard_normal(n_valid).reshape(depth.shape) * clean.rms
    else:
        depth[valid] += rng.standard_normal(n_valid) * clean.rms[valid]
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


def sensor_burst(
    frame: RGBDFrame, noise: DepthNoiseSettings, rng: np.random.Generator | PrefetchedDraws, n: int
) -> list[RGBDFrame]:
    """`n` frames of a scene at rest (one rendered `frame`), each with its own sensor noise, sharing the
    capture's static share of it; colour noise on the first only. n = 1 is `apply_sensor_noise` itself."""
    if not noise.enabled:
        return [frame] * n
    static = rng.standard_normal(frame.depth_m.shape) if noise.static_fraction > 0 else None
    clean = _CleanDepth.of(frame.depth_m, noise)
    out = [_noisy(frame, clean, noise, rng, rgb_noise=True, static=static)]
    out += [_noisy(frame, clean, noise, rng, rgb_noise=False, static=static) for _ in range(n - 1)]
    return out


def burst_draws(noise: DepthNoiseSettings, shape: tuple[int, int], n: int) -> list[tuple[str, int]]:
    """The draws (method, count) `sensor_burst` makes, in order, for an n-frame burst of a frame of `shape`
    (H, W) in which every pixel has depth (a pixel without depth changes the counts)."""
    if not noise.enabled:
        return []
    px = shape[0] * shape[1]
    plan = [("standard_normal", px)] if noise.static_fraction > 0 else []
    for k in range(n):
        plan += [("standard_normal", px), ("random", px), ("random", px)]
        if k == 0 and noise.rgb_noise_std > 0:
            plan.append(("standard_normal", 3 * px))
    return plan


# While a prefetch thread draws, the interpreter hands the GIL over every 0.5 ms instead of every 5 ms:
# between its ~25 fills (which run without the GIL) the thread needs the GIL for a moment, and the main
# thread stepping the physics would otherwise keep it for the whole default interval each time, so that
# both end up waiting (measured: 720 steps and one burst's draws 69 ms together, 33 ms with 0.5 ms).
_SWITCH_INTERVAL_S = 5e-4


class _FastSwitching:
    """A context: the short switch interval while any prefetch thread is inside, the old one after."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._users = 0
        self._saved = 0.0

    def __enter__(self) -> None:
        with self._lock:
            if self._users == 0:
                self._saved = sys.getswitchinterval()
                sys.setswitchinterval(min(self._saved, _SWITCH_INTERVAL_S))
            self._users += 1

    def __exit__(self, *exc: object) -> None:
        with self._lock:
            self._users -= 1
            if self._users == 0:
                sys.setswitchinterval(self._saved)


_fast_switching = _FastSwitching()


class PrefetchedDraws:
    """A generator's next draws, made ahead on a second thread (numpy fills arrays without the GIL), so that
    a burst's random numbers (~30 ms for 8 VGA frames) are drawn while the scene settles instead of after.

    Stands in for `rng` in `sensor_burst`: it hands out the prefetched arrays while the calls follow `plan`
    and, at the first call that does not, draws the plan's used part again from `rng` and goes on drawing
    from it directly. Either way every call returns what the same call on `rng` would have, and `finish()`
    leaves `rng` where drawing directly would have left it: prefetching changes timings, never a number.
    """

    def __init__(self, rng: np.random.Generator, plan: list[tuple[str, int]]):
        self._rng = rng
        self._plan = plan
        self._arrays: list[np.ndarray | None] = []
        self._ahead = copy.deepcopy(rng)
        self._used = 0
        self._direct = False
        self._left_plan = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._draw, name="twin-noise-prefetch", daemon=True)
        self._thread.start()

    @property
    def plan(self) -> list[tuple[str, int]]:
        """The draws (method, count) made ahead, in order."""
        return self._plan

    @property
    def followed_plan(self) -> bool:
        """False once a call did not follow the plan (from then on the draws are made directly)."""
        return not self._left_plan

    def _draw(self) -> None:
        with _fast_switching:
            for method, count in self._plan:
                if self._stop.is_set():
                    return
                self._arrays.append(getattr(self._ahead, method)(count))

    def _take(self, method: str, size: int | tuple[int, ...]) -> np.ndarray:
        count = int(np.prod(size))
        if not self._direct:
            if self._used < len(self._plan) and self._plan[self._used] == (method, count):
                self._thread.join()
                out = self._arrays[self._used]
                assert out is not None
                self._arrays[self._used] = None  # handed out: not kept alive here
                self._used += 1
                return out.reshape(size)
            self._left_plan = True
            self._go_direct()
        out = getattr(self._rng, method)(size)
        assert isinstance(out, np.ndarray)
        return out

    def _go_direct(self) -> None:
        self._stop.set()  # what the thread draws from here on is not needed (it draws from a copy of rng)
        for method, count in self._plan[: self._used]:  # the stream up to here, drawn again
            getattr(self._rng, method)(count)
        self._direct = True

    def standard_normal(self, size: int | tuple[int, ...]) -> np.ndarray:
        return self._take("standard_normal", size)

    def random(self, size: int | tuple[int, ...]) -> np.ndarray:
        return self._take("random", size)

    def finish(self) -> None:
        """Put `rng` where the calls made so far, drawn directly, would have put it."""
        if self._direct:
            return
        if self._used == len(self._plan):
            self._thread.join()
            self._rng.bit_generator.state = self._ahead.bit_generator.state
        else:
            self._left_plan = True
            self._go_direct()
        self._direct = True
        self._arrays = []
