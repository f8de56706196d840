"""Perception as the task layer calls it: frame + camera pose in, base-frame scene model out.

Nothing here reads simulator ground truth, except that a detector which declares
`needs_ground_truth = True` (the labelled `oracle`) is handed what the caller passes as `ground_truth`.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from twin.config import Settings
from twin.errors import ConfigError
from twin.perception.capture import Capture, wrist_camera_offset
from twin.perception.detection import Detector
from twin.planning import make_context
from twin.registry import PluginContext
from twin.robot.kinematics import URArm

__all__ = ["camera_extrinsics", "make_detector"]

log = logging.getLogger("twin")


def make_detector(
    settings: Settings,
    *,
    name: str | None = None,
    params: dict[str, Any] | None = None,
    context: PluginContext | None = None,
) -> Detector:
    """The detector plugin named in `settings.perception.detector` (or `name`/`params`), instantiated in the
    run's plugin `context` (None: one made for `settings`, with its own robot)."""
    if context is None:
        context = make_context(settings)
    block = settings.perception.detector
    reg = context.registry
    return reg.detector(name or block.name, block.params if params is None and name is None else params, context)


def camera_extrinsics(
    settings: Settings,
    capture: Capture,
    T_base_camera_aruco: np.ndarray | None,
    q_aruco: np.ndarray | None = None,
    *,
    arm: URArm,
) -> np.ndarray:
    """The camera pose perception uses for `capture`, per `perception.extrinsics`.

    fixed + auto/aruco: the ArUco estimate. wrist + auto/kinematics: forward kinematics of the measured
    joints times the configured hand-eye offset (seed 002 used TF). wrist + aruco: the hand-eye offset
    estimated from the ArUco view at `q_aruco`, carried to the capture pose by forward kinematics.
    fixed + kinematics: the configured mount pose (nominal, no estimation). `arm`: the run's arm (a wrist
    camera's forward kinematics).
    """
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
    T_tool0_camera = np.linalg.inv(arm.fk(q_aruco, "flange")) @ T_base_camera_aruco
    log.debug(
        "hand-eye from ArUco differs from the configured offset by %.4f m",
        float(np.linalg.norm(T_tool0_camera[:3, 3] - wrist_camera_offset(settings)[:3, 3])),
    )
    return arm.fk(capture.q, "flange") @ T_tool0_camera
