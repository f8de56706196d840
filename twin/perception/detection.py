"""What a detector plugin returns, and the frame-wide cloud that detectors and pose estimation share.

A detector turns an RGB-D frame (plus the camera pose in the base frame) into `Detection`s: a class,
a colour, a confidence and a pixel mask - the role YOLO plays in seed 002, where the mask is the depth
crop. Detectors are plugins (`registry.add_detector`) implementing the `Detector` protocol; the pose
estimation that follows (`twin.tasks.robocup.perception`) only needs the mask.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from twin.camera import RGBDFrame, point_cloud_within
from twin.perception.cloud_geometry import Plane, fit_plane_ransac, transform_points
from twin.timing import stage

if TYPE_CHECKING:
    from twin.config import RobocupPerceptionSettings

__all__ = [
    "CLASSES",
    "Detection",
    "Detector",
    "SceneCloud",
    "detection_label",
    "needs_ground_truth",
    "scene_cloud",
    "table_noise",
    "table_threshold_for",
    "white_balance_gains",
    "with_ground_truth",
]

CLASSES = ("bottle", "can", "spam", "marker", "cube")
"""Object classes; cubes are further told apart by colour (cube_red, cube_blue, ...): 8 detection classes."""


def detection_label(cls: str, color: str | None) -> str:
    """The seed's detection class name: the class, or cube_<colour> for cubes."""
    return f"{cls}_{color}" if cls == "cube" and color else cls


@dataclass(frozen=True)
class Detection:
    """One detected object.

    `cls`: one of CLASSES; `color`: colour name (cubes) or None; `confidence` in [0, 1]; `pixels`: (n,)
    flat indices (row * width + column) of the object's pixels; `bbox`: (u_min, v_min, u_max, v_max) px.
    `info`: detector-specific extras (features, distances) for debugging and reports.
    """

    cls: str
    color: str | None
    confidence: float
    pixels: np.ndarray
    bbox: tuple[int, int, int, int]
    info: dict[str, Any]

    @property
    def label(self) -> str:
        return detection_label(self.cls, self.color)


@runtime_checkable
class Detector(Protocol):
    """A detector plugin: `cls(params, context)`, then `detect(...)` per frame.

    Set the class attribute `needs_ground_truth = True` to be handed the simulator's ground truth
    (only the labelled `oracle` detector does; it exists for ablations).
    """

    def detect(
        self, frame: RGBDFrame, T_base_camera: np.ndarray, *, cloud: SceneCloud | None = None, ground_truth: Any = None
    ) -> list[Detection]:
        """Detections in `frame`; `T_base_camera` (4, 4) is the estimated camera pose; `cloud` the
        frame-wide base-frame cloud when the caller has it already (else the detector builds it)."""
        ...


def needs_ground_truth(detector: Any) -> bool:
    """Does this detector (instance or class) declare `needs_ground_truth = True` (default False)?"""
    return bool(getattr(detector, "needs_ground_truth", False))


class _GroundTruthFed:
    """A detector that declares `needs_ground_truth`, bound to the objects its caller (the judge, or the
    perception evaluation) read from the simulator: perception code calls it like any detector."""

    def __init__(self, detector: Detector, ground_truth: Any):
        self.detector = detector
        self.ground_truth = ground_truth

    @property
    def last_timings_s(self) -> dict[str, float]:
        return dict(getattr(self.detector, "last_timings_s", {}))

    def detect(
        self, frame: RGBDFrame, T_base_camera: np.ndarray, *, cloud: SceneCloud | None = None, ground_truth: Any = None
    ) -> list[Detection]:
        return self.detector.detect(frame, T_base_camera, cloud=cloud, ground_truth=self.ground_truth)


def with_ground_truth(detector: Detector, ground_truth: Any) -> Detector:
    """The ORACLE hand-off, in one place: `detector` bound to `ground_truth` if it declares
    `needs_ground_truth`, else `detector` itself (it never sees the truth)."""
    return _GroundTruthFed(detector, ground_truth) if needs_ground_truth(detector) else detector


@dataclass(frozen=True)
class SceneCloud:
    """Every valid pixel of a frame as a base-frame point, with its colour and pixel index, plus the
    table plane (normal up) fitted to them. `height` is each point's signed height above the table.
    `table_noise_m`: the spread of the table's points about the plane (robust RMS; 0 when not measured);
    `table_threshold_m`: the height above which a point is not table (`table_threshold_for`).
    `timings_s`: seconds for back-projection ("cloud") and the table plane ("plane")."""

    points: np.ndarray
    rgb: np.ndarray
    pixels: np.ndarray
    table: Plane
    height: np.ndarray
    image_shape: tuple[int, int]
    timings_s: dict[str, float] = field(default_factory=dict)
    table_noise_m: float = 0.0
    table_threshold_m: float = 0.008
    camera_origin: np.ndarray | None = None  # (3,) base frame: where the rays to the points start

    def select(self, pixels: np.ndarray) -> np.ndarray:
        """Indices into `points` of the given flat pixel indices (pixels without depth are skipped)."""
        lookup = np.full(self.image_shape[0] * self.image_shape[1], -1, dtype=np.int64)
        lookup[self.pixels] = np.arange(len(self.pixels))
        idx = lookup[np.asarray(pixels, dtype=np.int64)]
        return idx[idx >= 0]


def scene_cloud(
    frame: RGBDFrame,
    T_base_camera: np.ndarray,
    params: RobocupPerceptionSettings,
    *,
    seed: int = 0,
    table_rgb: np.ndarray | None = None,
) -> SceneCloud:
    """Back-project the frame within the depth limits, map it to the base frame, fit the table plane.

    The plane is fitted by RANSAC on every 4th point (threshold: half the table removal threshold), then
    refitted on its inliers; it is the largest plane in view, which from the capture pose is the table.
    Then the table's noise is measured and the table threshold set from it (`table_threshold_for`), and,
    given the table's own colour `table_rgb` (and `params.white_balance`), the colours are white-balanced
    on the table (`white_balance_gains`).
    """
    with stage("perception.cloud") as cloud_stage:
        H, W = frame.depth_m.shape
        pts, rgb, pixels = point_cloud_within(frame, params.min_depth_m, params.max_depth_m)
        base = transform_points(T_base_camera, pts)
        sub = base[::4]
    with stage("perception.plane") as plane_stage:
        plane = fit_plane_ransac(sub, params.table_threshold_m / 2, iterations=200, rng=np.random.default_rng(seed))
        plane = plane.oriented(np.array([0.0, 0.0, 10.0]))  # normal up: towards a point high above the table
        plane = Plane(plane.normal, plane.offset, np.zeros(0, dtype=bool))
        height = plane.distance(base)
        noise = table_noise(height[::4])
    timings = {"cloud": cloud_stage.seconds, "plane": plane_stage.seconds}
    threshold = table_threshold_for(noise, params)
    if table_rgb is not None and params.white_balance:
        gains = white_balance_gains(rgb[::4][np.abs(height[::4]) < threshold], table_rgb)
        if gains is not None:
            rgb = np.clip(rgb * gains, 0.0, 1.0)
    origin = np.asarray(T_base_camera, dtype=float)[:3, 3].copy()
    return SceneCloud(base, rgb, pixels, plane, height, (H, W), timings, noise, threshold, origin)


# a light whose colour moves the table's chromaticity by less than this is left alone: the rendered table
# matches its model colour to 0.001 under the nominal light, a warm light of [1.2, 1.0, 0.8] moves it ~0.1
_WHITE_BALANCE_MIN_SHIFT = 0.01


def white_balance_gains(table_rgb_measured: np.ndarray, table_rgb: np.ndarray) -> np.ndarray | None:
    """Per-channel gains (3,) that give the table's points (n, 3) the chromaticity of its model colour
    `table_rgb`, brightness kept: a light of another colour, or a white balance off, undone on the one
    surface whose colour is known. None when there are no table points or the shift is negligible."""
    if len(table_rgb_measured) == 0:
        return None
    m = np.median(table_rgb_measured, axis=0)
    ref = np.asarray(table_rgb, dtype=float)
    if np.any(m <= 1e-6) or np.linalg.norm(ref) <= 1e-9:
        return None
    shift = m / np.linalg.norm(m) - ref / np.linalg.norm(ref)
    if float(np.abs(shift).max()) < _WHITE_BALANCE_MIN_SHIFT:
        return None
    gains = (ref / np.linalg.norm(ref)) / (m / np.linalg.norm(m))
    return gains * (np.linalg.norm(m) / np.linalg.norm(m * gains))  # the table's brightness kept


def table_noise(height: np.ndarray, band_m: float = 0.05) -> float:
    """Robust RMS of the table's points about its plane, from the points below it (within `band_m`):
    nothing but the table's own noise lies there, while objects and their edges lie above. 0.0 if none."""
    below = height[(height <= 0.0) & (height > -band_m)]
    return float(1.4826 * np.median(-below)) if len(below) else 0.0


def table_threshold_for(noise_m: float, params: RobocupPerceptionSettings) -> float:
    """The height above the table plane from which a point belongs to an object: `table_threshold_m`, or
    `table_threshold_sigmas` times the measured table noise when that is larger (a noisier sensor, or a
    farther table, spreads the table's points higher)."""
    if params.table_threshold_sigmas is None:
        return params.table_threshold_m
    return max(params.table_threshold_m, params.table_threshold_sigmas * noise_m)
