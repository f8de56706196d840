"""Perception as the task layer calls it: frame + camera pose in, base-frame scene model out.

Nothing here reads simulator ground truth, except that a detector which declares
`needs_ground_truth = True` (the labelled `oracle`) is handed what the caller passes as `ground_truth`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from twin.camera import RGBDFrame
from twin.config import Settings
from twin.perception.capture import Capture, wrist_camera_offset
from twin.perception.detection import Detection, Detector, needs_ground_truth, scene_cloud
from twin.perception.robocup import ObjectEstimate, estimate_object

__all__ = ["RobocupResult", "make_detector", "perceive_robocup", "camera_extrinsics"]

log = logging.getLogger("twin")


@dataclass(frozen=True)
class RobocupResult:
    """Estimates (base frame) for every detection that kept enough points, the detections themselves,
    and seconds per stage: cloud (back-projection), plane (table), detect (the whole detector, with its
    own stages such as dbscan when it reports them), pca and icp (summed over objects)."""

    objects: tuple[ObjectEstimate, ...]
    detections: tuple[Detection, ...]
    timings_s: dict[str, float] = field(default_factory=dict)


def make_detector(settings: Settings, *, name: str | None = None, params: dict[str, Any] | None = None) -> Detector:
    """The detector plugin named in `settings.perception.detector` (or `name`/`params`), instantiated."""
    from twin.kinematics import UR5e
    from twin.registry import PluginContext, default_registry

    block = settings.perception.detector
    reg = default_registry()
    ctx = PluginContext(settings=settings, kinematics=UR5e(), registry=reg)
    return reg.detector(name or block.name, block.params if params is None and name is None else params, ctx)


def perceive_robocup(
    frame: RGBDFrame,
    T_base_camera: np.ndarray,
    settings: Settings,
    detector: Detector,
    *,
    ground_truth: Any = None,
    seed: int = 0,
) -> RobocupResult:
    """Detect, then estimate pose and grasp per detection (seed 002 pipeline)."""
    params = settings.perception.robocup
    timings: dict[str, float] = {}
    cloud = scene_cloud(frame, T_base_camera, params, seed=seed)
    timings.update(cloud.timings_s)
    t0 = time.perf_counter()
    gt = ground_truth if needs_ground_truth(detector) else None
    detections = detector.detect(frame, T_base_camera, cloud=cloud, ground_truth=gt)
    timings["detect"] = time.perf_counter() - t0
    timings.update(getattr(detector, "last_timings_s", {}))  # e.g. the geometric detector's "dbscan"
    estimates = []
    timings["pca"] = timings["icp"] = 0.0
    for det in detections:
        est = estimate_object(det, cloud, params)
        if est is None:
            continue
        estimates.append(est)
        for k in ("pca", "icp"):
            timings[k] += est.timings_s.get(k, 0.0)
    log.debug("robocup: %d detections, %d estimates", len(detections), len(estimates))
    return RobocupResult(tuple(estimates), tuple(detections), timings)


def camera_extrinsics(settings: Settings, capture: Capture, T_base_camera_aruco: np.ndarray | None, q_aruco: np.ndarray | None = None) -> np.ndarray:
    """The camera pose perception uses for `capture`, per `perception.extrinsics`.

    fixed + auto/aruco: the ArUco estimate. wrist + auto/kinematics: forward kinematics of the measured
    joints times the configured hand-eye offset (seed 002 used TF). wrist + aruco: the hand-eye offset
    estimated from the ArUco view at `q_aruco`, carried to the capture pose by forward kinematics.
    fixed + kinematics: the configured mount pose (nominal, no estimation).
    """
    from twin.errors import ConfigError
    from twin.kinematics import UR5e

    mode = settings.perception.extrinsics
    if mode == "auto":
        mode = "aruco" if capture.mount == "fixed" else "kinematics"
    if mode == "kinematics":
        return capture.T_base_camera_nominal
    if T_base_camera_aruco is None:
        raise ConfigError("perception.extrinsics needs the ArUco calibration, but the scene has no marker plate")
    if capture.mount == "fixed":
        return T_base_camera_aruco
    if q_aruco is None:
        raise ConfigError("a wrist camera calibrated by ArUco needs the joint angles of the calibration view")
    kin = UR5e()
    T_tool0_camera = np.linalg.inv(kin.fk(q_aruco, "flange")) @ T_base_camera_aruco
    log.debug("hand-eye from ArUco differs from the configured offset by %.4f m",
              float(np.linalg.norm(T_tool0_camera[:3, 3] - wrist_camera_offset(settings)[:3, 3])))
    return kin.fk(capture.q, "flange") @ T_tool0_camera
