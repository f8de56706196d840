"""Perception against ground truth: `twin perceive` and `twin calibrate` in one library call each.

This module (with the labelled oracle detector) is the only perception code that reads simulator
ground truth, and it does so only after the estimates are made, to score them.

Scoring follows seed 002: per true object S = 0.7 * max(0, 1 - |dp_xy| / 0.20) * 100 + 0.3 * S_orient,
S_orient = 100 when the vertical/horizontal label matches, else 0; a missed object scores 0.
Estimates are matched to true objects one-to-one by x-y distance (Hungarian, gate `MATCH_GATE_M`),
regardless of class, so a wrong class shows as a class error, not as a miss plus a false positive.

Conventions: `position_error_m` is the x-y distance (the score's |dp_xy|). A cube is always "vertical"
(its faces are interchangeable, so lying on a side is the same shape). `yaw_error_deg` compares the
grasp yaw with the ideal grasp yaw of the true pose modulo the object's symmetry (half a turn; a quarter
for cubes); it is null for upright cylinders, which have no yaw, and when the pipeline estimates none.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from scipy.optimize import linear_sum_assignment

from twin.camera import true_camera_pose
from twin.config import Settings
from twin.errors import ConfigError
from twin.perception.aruco import Calibration, MarkerNotFound, calibrate, transform_error
from twin.perception.capture import Capture, capture_frame, noise_rng, prefetch_next_capture
from twin.perception.detection import detection_label, with_ground_truth
from twin.perception.pipeline import camera_extrinsics, make_detector
from twin.planning import make_context
from twin.scene_layout import OBJECT_TEMPLATES, find_marker_plate
from twin.transforms import rpy_to_matrix as rpy_matrix
from twin.types import BoxBounds, quat_to_matrix

if TYPE_CHECKING:
    from twin.camera import RGBDFrame
    from twin.perception.detection import Detector
    from twin.world import ObjectState, World

__all__ = [
    "MATCH_GATE_M",
    "CalibrationReport",
    "PerceptionReport",
    "Pipelines",
    "RobocupPipeline",
    "WarehousePipeline",
    "ideal_grasp_yaw",
    "match",
    "orientation_truth",
    "run_calibration",
    "run_perception",
    "score",
    "true_obstacle_box",
    "yaw_error_deg",
]

log = logging.getLogger("twin")

MATCH_GATE_M = 0.10


def score(dp_xy_m: float | None, orientation_ok: bool) -> float:
    """Seed 002's per-object score S (0..100); a missed object (dp None) scores 0."""
    if dp_xy_m is None:
        return 0.0
    return 0.7 * max(0.0, 1.0 - dp_xy_m / 0.20) * 100.0 + 0.3 * (100.0 if orientation_ok else 0.0)


def orientation_truth(obj: ObjectState) -> str:
    """'vertical' or 'horizontal' (the object's z axis nearer horizontal); cubes are always vertical."""
    if obj.cls in ("cube", "warehouse_cube"):
        return "vertical"
    return "horizontal" if obj.lying else "vertical"


def _is_cylinder(cls: str) -> bool:
    """Whether an object class is a cylinder (bottle, can, marker), as its template says."""
    template = OBJECT_TEMPLATES.get(cls)
    return template is not None and template.shape == "cylinder"


def ideal_grasp_yaw(obj: ObjectState) -> tuple[float, float] | None:
    """(yaw, symmetry period) of the best top-down grasp for the true pose; None when any yaw will do."""
    R = quat_to_matrix(obj.orientation_xyzw)
    if _is_cylinder(obj.cls):
        if not obj.lying:
            return None
        return math.atan2(R[1, 2], R[0, 2]) + math.pi / 2, math.pi
    horiz = [k for k in range(3) if math.hypot(R[0, k], R[1, k]) > 0.7]
    if not horiz:
        return None
    if obj.cls in ("cube", "warehouse_cube"):
        k = horiz[0]
        return math.atan2(R[1, k], R[0, k]) + math.pi / 4, math.pi / 2
    k = min(horiz, key=lambda k: obj.size[k])
    return math.atan2(R[1, k], R[0, k]), math.pi


def yaw_error_deg(yaw_est: float | None, obj: ObjectState) -> float | None:
    """|yaw_est - ideal| modulo the symmetry period, degrees; None when undefined."""
    ideal = ideal_grasp_yaw(obj)
    if ideal is None or yaw_est is None:
        return None
    target, period = ideal
    d = (yaw_est - target + period / 2) % period - period / 2
    return abs(math.degrees(d))


def match(est_xy: np.ndarray, true_xy: np.ndarray, gate_m: float = MATCH_GATE_M) -> dict[int, int]:
    """true index -> estimate index, one-to-one, minimising total x-y distance within the gate."""
    if len(est_xy) == 0 or len(true_xy) == 0:
        return {}
    D = np.linalg.norm(true_xy[:, None, :2] - est_xy[None, :, :2], axis=2)
    rows, cols = linear_sum_assignment(np.where(D <= gate_m, D, 1e6))
    return {int(r): int(c) for r, c in zip(rows, cols, strict=True) if D[r, c] <= gate_m}


def true_obstacle_box(settings: Settings) -> BoxBounds | None:
    """The warehouse obstacle's AABB from its fixture pose and model size (fixtures never move)."""
    t = OBJECT_TEMPLATES["obstacle"]
    for fx in settings.world.fixtures:
        if fx.urdf.replace("\\", "/").endswith(t.urdf.split("/")[-1]):
            R = rpy_matrix(fx.rpy)
            half = np.abs(R) @ (np.array(t.size) / 2.0)
            c = np.array(fx.position)
            lo, hi = c - half, c + half
            return BoxBounds(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])
    return None


def _box_dict(b: BoxBounds | None) -> dict[str, float] | None:
    if b is None:
        return None
    return {k: float(getattr(b, k)) for k in ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")}


def _true_camera(world: World, settings: Settings) -> np.ndarray:
    tool0 = world.link_matrix("tool0") if settings.camera.mount == "wrist" else None
    return true_camera_pose(settings.camera, world.seed, tool0)


@dataclass(frozen=True)
class CalibrationReport:
    """ArUco calibration against the true camera pose (both T_base_camera, 4x4)."""

    translation_error_m: float
    rotation_error_deg: float
    method: str
    T_base_camera: np.ndarray
    T_base_camera_true: np.ndarray
    reprojection_px: float
    n_points: int
    calibration: Calibration
    q: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        """The `calibration` part of the JSON."""
        return {
            "translation_error_m": self.translation_error_m,
            "rotation_error_deg": self.rotation_error_deg,
            "method": self.method,
            "reprojection_px": self.reprojection_px,
            "points": self.n_points,
            "T_base_camera": self.T_base_camera.tolist(),
            "T_base_camera_true": self.T_base_camera_true.tolist(),
        }


def _calibrate_in(world: World, settings: Settings, capture: Capture) -> CalibrationReport:
    T_true = _true_camera(world, settings)
    cal = calibrate(capture.frame, settings)
    dt, dr = transform_error(cal.T_base_camera, T_true)
    return CalibrationReport(
        dt, dr, cal.method, cal.T_base_camera, T_true, cal.marker.reprojection_px, cal.marker.n_points, cal, capture.q
    )


def run_calibration(settings: Settings, *, seed: int | None = None, renderer: str = "auto") -> CalibrationReport:
    """Build the scene, take the calibration view (wrist: `camera.calibration_pose`), estimate
    T_base_camera from the base marker and compare it with the truth. MarkerNotFound when not visible."""
    from twin.world import World  # lazy: pybullet

    seed = settings.seed if seed is None else int(seed)
    if find_marker_plate(settings) is None:
        raise ConfigError("the config has no ArUco plate fixture (urdf: urdf/aruco_plate.urdf) to calibrate with")
    with World(settings, seed, renderer=renderer) as world:  # type: ignore[arg-type]
        cap = capture_frame(world, settings, pose="calibration", rng=noise_rng(seed, 1))
        return _calibrate_in(world, settings, cap)


@dataclass(frozen=True)
class PerceptionReport:
    """Every true object with its estimate and errors, false positives, calibration, timings."""

    config: str
    seed: int
    pipeline: str
    detector: str | None
    objects: list[dict[str, Any]]
    false_positives: int
    calibration: dict[str, Any] | None
    obstacle: dict[str, Any] | None
    timings_s: dict[str, float] = field(default_factory=dict)
    estimates: list[dict[str, Any]] = field(default_factory=list)

    @property
    def score_mean(self) -> float:
        return float(np.mean([o["score"] for o in self.objects])) if self.objects else 0.0

    def to_dict(self) -> dict[str, Any]:
        """The JSON of `twin perceive`."""
        return {
            "config": self.config,
            "seed": self.seed,
            "pipeline": self.pipeline,
            "detector": self.detector,
            "objects": self.objects,
            "false_positives": self.false_positives,
            "calibration": self.calibration,
            "score_mean": self.score_mean,
            "obstacle": self.obstacle,
            "estimates": self.estimates,
            "timings_s": self.timings_s,
        }


def _object_row(obj: ObjectState, label_true: str, est: dict[str, Any] | None) -> dict[str, Any]:
    o_true = orientation_truth(obj)
    row: dict[str, Any] = {
        "name": obj.name,
        "class_true": label_true,
        "class_est": None,
        "orientation_true": o_true,
        "orientation_est": None,
        "color_true": obj.color,
        "color_est": None,
        "position_error_m": None,
        "yaw_error_deg": None,
        "score": 0.0,
    }
    if est is None:
        return row
    dp = float(np.linalg.norm(np.asarray(est["position"])[:2] - obj.position[:2]))
    row.update(
        class_est=est["class"],
        orientation_est=est["orientation"],
        color_est=est["color"],
        position_error_m=dp,
        yaw_error_deg=yaw_error_deg(est.get("yaw"), obj),
        score=score(dp, est["orientation"] == o_true),
    )
    return row


class WarehousePipeline(Protocol):
    """The warehouse pipeline (`twin.tasks.warehouse.perception.perceive_warehouse`): cubes and the
    obstacle's box in one frame; its result has `cubes`, `obstacle`, `obstacle_extended`,
    `obstacle_points` and `timings_s`."""

    def __call__(self, frame: RGBDFrame, T_base_camera: np.ndarray, params: Any, *, seed: int = ...) -> Any: ...


class RobocupPipeline(Protocol):
    """The RoboCup pipeline (`twin.tasks.robocup.perception.perceive_robocup`): an estimate per detection;
    its result has `objects` (ObjectEstimate-like) and `timings_s`."""

    def __call__(
        self, frame: RGBDFrame, T_base_camera: np.ndarray, settings: Settings, detector: Detector, *, seed: int = ...
    ) -> Any: ...


@dataclass(frozen=True)
class Pipelines:
    """The pipelines `run_perception` scores, chosen by `perception.pipeline`. They belong to the tasks
    (`twin.tasks.<name>.perception`), which sit above perception, so the caller hands them in:
    `Pipelines(warehouse=perceive_warehouse, robocup=perceive_robocup)`."""

    warehouse: WarehousePipeline
    robocup: RobocupPipeline


def _warehouse_estimates(res: Any, settings: Settings) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The warehouse result as estimates (one per cube) and the obstacle's box against the truth."""
    estimates = [
        {
            "class": "warehouse_cube",
            "color": c.color_label,
            "orientation": "vertical",
            "position": c.centroid.tolist(),
            "yaw": None,
            "points": c.n_points,
        }
        for c in res.cubes
    ]
    box_true = true_obstacle_box(settings)
    face_err = None
    if res.obstacle is not None and box_true is not None:
        face_err = float(np.max(np.abs(np.r_[res.obstacle.lo - box_true.lo, res.obstacle.hi - box_true.hi])))
    obstacle = {
        "box_est": _box_dict(res.obstacle),
        "box_extended": _box_dict(res.obstacle_extended),
        "box_true": _box_dict(box_true),
        "max_face_error_m": face_err,
        "points": res.obstacle_points,
    }
    return estimates, obstacle


def _robocup_estimates(res: Any) -> list[dict[str, Any]]:
    """The RoboCup result as estimates, one per object estimated."""
    return [
        {
            "class": e.label,
            "color": e.color,
            "orientation": e.orientation,
            "orientation_pca": e.orientation_pca,
            "position": e.position.tolist(),
            "yaw": e.yaw,
            "grasp": e.grasp.tolist(),
            "source": e.source,
            "icp_rmse": e.icp_rmse,
            "points": e.n_points,
            "confidence": e.confidence,
        }
        for e in res.objects
    ]


def _scored_rows(objs: list[ObjectState], estimates: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], int]:
    """Every true object's row (its matched estimate, if any, scored) and the count of false positives."""
    m = match(
        np.array([e["position"] for e in estimates]).reshape(-1, 3),
        np.array([o.position for o in objs]).reshape(-1, 3),
    )
    rows: list[dict[str, Any]] = []
    for i, o in enumerate(objs):
        label = "warehouse_cube" if o.cls == "warehouse_cube" else detection_label(o.cls, o.color)
        rows.append(_object_row(o, label, estimates[m[i]] if i in m else None))
    return rows, len(estimates) - len(m)


def _perceive_earlier(
    world: World, settings: Settings, pipelines: Pipelines, det: Detector | None, *, seed: int, count: int
) -> None:
    """`count` scene captures, each perceived (results dropped) before the next, as a task's earlier ones."""
    for _ in range(count):
        earlier = capture_frame(world, settings, pose="capture")
        if settings.perception.pipeline == "warehouse":
            pipelines.warehouse(earlier.frame, earlier.T_base_camera_nominal, settings.perception.warehouse)
        else:
            assert det is not None
            pipelines.robocup(earlier.frame, earlier.T_base_camera_nominal, settings, det, seed=seed)
        prefetch_next_capture(world, settings)


def run_perception(
    settings: Settings,
    *,
    pipelines: Pipelines,
    seed: int | None = None,
    renderer: str = "auto",
    detector: str | None = None,
    earlier_captures: int = 0,
) -> PerceptionReport:
    """Build the scene of `seed`, run the configured pipeline (of `pipelines`) on captured frames, score it.

    Warehouse: one frame from the fixed camera serves calibration and perception. RoboCup: the wrist
    camera first views the marker from `camera.calibration_pose` (for the calibration report, and for
    the extrinsics when `perception.extrinsics` is "aruco"), then the scene from `camera.capture_pose`.
    `detector` overrides `perception.detector.name` (its params then default). `earlier_captures`: scene
    captures taken and perceived before the one measured, as a task's earlier ones are (a world's first two
    renders take ~100 ms each with EGL, its later ones ~15 ms); every capture's noise then comes from the
    world's own stream per capture, as in a task, and the measured frame's is another than without them.
    """
    from twin.world import World  # lazy: pybullet

    seed = settings.seed if seed is None else int(seed)
    pipeline = settings.perception.pipeline
    timings: dict[str, float] = {}
    context = make_context(settings)
    det = make_detector(settings, name=detector, context=context) if pipeline == "robocup" else None
    has_marker = find_marker_plate(settings) is not None
    with World(settings, seed, renderer=renderer, robot=context.robot) as world:  # type: ignore[arg-type]
        cal_report: CalibrationReport | None = None
        if settings.camera.mount == "wrist" and has_marker:
            cap_cal = capture_frame(world, settings, pose="calibration", rng=noise_rng(seed, 1))
            try:
                cal_report = _calibrate_in(world, settings, cap_cal)
            except MarkerNotFound as e:
                log.warning("calibration view: %s", e)
        _perceive_earlier(world, settings, pipelines, det, seed=seed, count=earlier_captures)
        cap = capture_frame(world, settings, pose="capture", rng=None if earlier_captures else noise_rng(seed, 0))
        timings.update(cap.timings_s)
        if settings.camera.mount == "fixed" and has_marker:
            t0 = time.perf_counter()
            try:
                cal_report = _calibrate_in(world, settings, cap)
            except MarkerNotFound as e:
                if settings.perception.extrinsics != "kinematics":
                    raise
                log.warning("calibration: %s", e)
            timings["calibration"] = time.perf_counter() - t0
        T_base_camera = camera_extrinsics(
            settings,
            cap,
            cal_report.T_base_camera if cal_report else None,
            cal_report.q if cal_report else None,
            arm=context.robot.arm,
        )
        truth = world.objects()
        obstacle = None
        if pipeline == "warehouse":
            res = pipelines.warehouse(cap.frame, T_base_camera, settings.perception.warehouse, seed=seed)
            timings.update(res.timings_s)
            estimates, obstacle = _warehouse_estimates(res, settings)
            objs = [o for o in truth if o.cls == "warehouse_cube"]
        else:
            assert det is not None
            res = pipelines.robocup(cap.frame, T_base_camera, settings, with_ground_truth(det, truth), seed=seed)
            timings.update(res.timings_s)
            estimates = _robocup_estimates(res)
            objs = list(truth)
        rows, fp = _scored_rows(objs, estimates)
    return PerceptionReport(
        settings.name,
        seed,
        pipeline,
        (detector or settings.perception.detector.name) if det is not None else None,
        rows,
        fp,
        cal_report.to_dict() if cal_report else None,
        obstacle,
        timings,
        estimates,
    )
