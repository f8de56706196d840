"""The public API for plugin authors: everything a planner, retimer, detector or task plugin needs, in one
import (`from twin.plugin import ...`), the way pytest plugins import from `pytest` rather than `_pytest`.

Built-in plugins import only from here (a test enforces it); names not listed here are internals that may
change. Heavy modules (FCL, OpenCV) load on first use of a name that needs them.

Contracts are declared, not probed:
- a planner class may declare `goal_kinds` (subset of `GOAL_KINDS`, default all), `robot_models` (the
  `robot.model` arms it plans for, default all: the factory refuses another, a comparison skips the pair) and
  `Params` (a pydantic model validating its parameters); a path planner that takes a retimer subclasses
  `PathPlanner`;
- a planner that stops near its goal rather than on it says how near in `MotionResult.goal_tolerance_m`;
- a planner (or retimer) whose timing cannot keep the request's jerk limit declares `jerk_limited = False`
  (TOPP-RA bounds velocity and acceleration only); `PathPlanner` answers for its retimer;
- a detector that must be handed ground truth declares `needs_ground_truth = True` (only `oracle` does);
- an optional classmethod `unavailable_reason() -> str | None` says why a registered name cannot run here;
- a task is `cls(params, context)` with `run(cell) -> list[ObjectOutcome]`; it senses through the `Cell`
  (camera frames, joint encoders, finger position) and leaves the verdicts to the judge.
"""

from __future__ import annotations

import importlib
import warnings
from typing import TYPE_CHECKING, Any

from twin.errors import (
    ConfigError,
    DependencyMissing,
    DuplicateNameError,
    InvalidRequestError,
    PlanningError,
    PluginError,
    TwinError,
    UnknownNameError,
    WorldError,
)
from twin.hookspecs import hookimpl

# name -> module it lives in; imported on first access
_LAZY: dict[str, str] = {
    # registry and context
    "Registry": "twin.registry",
    "PluginContext": "twin.registry",
    "Kind": "twin.registry",
    # requests, results, trajectories
    "Pose": "twin.types",
    "JointGoal": "twin.types",
    "Landmark": "twin.types",
    "PoseGoal": "twin.types",
    "Goal": "twin.types",
    "Limits": "twin.types",
    "MotionRequest": "twin.types",
    "MotionResult": "twin.types",
    "Status": "twin.types",
    "Trajectory": "twin.types",
    "BoxBounds": "twin.types",
    "as_q": "twin.types",
    "EXACT_JOINT_TOLERANCE_RAD": "twin.types",
    "EXACT_POSITION_TOLERANCE_M": "twin.types",
    "EXACT_ORIENTATION_TOLERANCE_RAD": "twin.types",
    # transforms
    "rpy_matrix": "twin.types",
    "rpy_to_matrix": "twin.transforms",
    "matrix_to_rpy": "twin.transforms",
    "quat_to_matrix": "twin.transforms",
    "quats_to_matrices": "twin.transforms",
    "matrix_to_quat": "twin.transforms",
    "pose_from_xyz_rpy": "twin.transforms",
    "urdf_rgba": "twin.robot.urdf_model",
    # planner contracts and the checks every planner's output gets
    "Segment": "twin.planning",
    "PathPlanner": "twin.planning",
    "OneShotPlanner": "twin.planning",
    "RecedingHorizonPlanner": "twin.planning",
    "Retimer": "twin.planning",
    "SceneView": "twin.planning",
    "GOAL_KINDS": "twin.planning",
    "densify": "twin.planning",
    "densify_path": "twin.planning",
    "first_collision": "twin.planning",
    "colliding_pair": "twin.planning",
    # what every path planner does around its search (twin.planning.paths)
    "PathPlannerParams": "twin.planning.paths",
    "QueryEnds": "twin.planning.paths",
    "query_ends": "twin.planning.paths",
    "add_time": "twin.planning.paths",
    "goal_set": "twin.planning.paths",
    "padded_scene": "twin.planning.paths",
    "path_length": "twin.planning.paths",
    "sampling_bounds": "twin.planning.paths",
    "start_failure": "twin.planning.paths",
    "timed_and_checked": "twin.planning.paths",
    "trajectory_check_points": "twin.planning.paths",
    "warm_up_checks": "twin.planning.paths",
    "warm_up_retimer": "twin.planning.paths",
    "goal_miss": "twin.planning",
    "jerk_limited": "twin.planning",
    "limits_from_settings": "twin.planning",
    "make_context": "twin.planning",
    "make_planner": "twin.planning",
    # the receding-horizon MPC loop the MPC planners share (nmpc, croc): subclass `RecedingHorizonMPC` with a
    # `_solve`; its parameters, proxy spheres, plan checks, self rows and initial guess
    "RecedingHorizonMPC": "twin.planning.receding",
    "Solved": "twin.planning.receding",
    "RecedingParams": "twin.planning.receding_params",
    "Weights": "twin.planning.receding_params",
    "DEFAULT_ARM_SPHERES": "twin.planning.receding_params",
    "DEFAULT_WHOLE_ARM_TOOL_SPHERES": "twin.planning.receding_params",
    "TCP_FRAME": "twin.planning.proxy_spheres",
    "CHECK_TOL_M": "twin.planning.proxy_spheres",
    "DISTANCE_EPS2": "twin.planning.proxy_spheres",
    "CHORD_EPS2": "twin.planning.proxy_spheres",
    "Box": "twin.planning.proxy_spheres",
    "robot_spheres": "twin.planning.proxy_spheres",
    "with_object": "twin.planning.proxy_spheres",
    "sphere_positions": "twin.planning.proxy_spheres",
    "subdivide": "twin.planning.proxy_spheres",
    "box_gaps": "twin.planning.proxy_spheres",
    "SelfRows": "twin.planning.selfrows",
    "link_groups": "twin.planning.selfrows",
    "self_pairs": "twin.planning.selfrows",
    "pair_gaps": "twin.planning.selfrows",
    "self_rows": "twin.planning.selfrows",
    "self_violation": "twin.planning.selfrows",
    "guess_slack": "twin.planning.guess",
    # kinematics
    "URArm": "twin.robot.kinematics",
    "Robot": "twin.robot",
    "DHParameters": "twin.robot.kinematics",
    "wrap_to_pi": "twin.robot.kinematics",
    # the collision world
    "PlanningScene": "twin.collision",
    "FixtureSpec": "twin.collision",
    "SphereModel": "twin.collision",
    "leave_cover": "twin.collision.planning_model",
    # the planning model's compiled kernels, for compiled planners (numba: call them from njit code)
    "sphere_evaluate": "twin.collision.sphere_kernel",
    "first_touch_on_motion": "twin.collision.sphere_kernel",
    "first_flagged_motion": "twin.collision.sphere_kernel",
    "KERNEL_FINGERPRINT": "twin.collision.sphere_kernel",
    "no_runtime_njit": "twin.collision.sphere_kernel",
    # settings
    "Settings": "twin.config",
    "load_config": "twin.config",
    # perception, for detectors
    "RGBDFrame": "twin.camera",
    "Detection": "twin.perception.detection",
    "Detector": "twin.perception.detection",
    "SceneCloud": "twin.perception.detection",
    "scene_cloud": "twin.perception.detection",
    "CLASSES": "twin.perception.detection",
    "cluster_points": "twin.perception.segmentation",
    "Cluster": "twin.perception.segmentation",
    # where a run's time goes: time a stage of your plugin into the run's breakdown
    "stage": "twin.timing",
    "footprint": "twin.perception.segmentation",
    "color_distance": "twin.perception.colors",
    "palette": "twin.perception.colors",
    "OBJECT_TEMPLATES": "twin.scene_layout",
    # tasks: the cell a task drives, and the judge of its outcome (physics ground truth)
    "Cell": "twin.tasks.cell",
    "StageFailed": "twin.tasks.stage_failure",
    "GripStatus": "twin.tasks.grasping",
    "GraspCheck": "twin.tasks.grasping",
    "top_down": "twin.tasks.grasping",
    "ObjectOutcome": "twin.types",
    "Verdict": "twin.tasks.judge",
    "judge_in_zone": "twin.tasks.judge",
    "judge_in_bin": "twin.tasks.judge",
}

# Spelled out (not `*_LAZY`) so linters and type checkers see the exports; a test keeps it equal to the
# eager names plus _LAZY.
__all__ = [
    "CHECK_TOL_M",
    "CHORD_EPS2",
    "CLASSES",
    "DEFAULT_ARM_SPHERES",
    "DEFAULT_WHOLE_ARM_TOOL_SPHERES",
    "DISTANCE_EPS2",
    "EXACT_JOINT_TOLERANCE_RAD",
    "EXACT_ORIENTATION_TOLERANCE_RAD",
    "EXACT_POSITION_TOLERANCE_M",
    "GOAL_KINDS",
    "KERNEL_FINGERPRINT",
    "OBJECT_TEMPLATES",
    "TCP_FRAME",
    "Box",
    "BoxBounds",
    "Cell",
    "Cluster",
    "ConfigError",
    "DHParameters",
    "DependencyMissing",
    "Detection",
    "Detector",
    "DuplicateNameError",
    "FixtureSpec",
    "Goal",
    "GraspCheck",
    "GripStatus",
    "InvalidRequestError",
    "JointGoal",
    "Kind",
    "Landmark",
    "Limits",
    "MotionRequest",
    "MotionResult",
    "ObjectOutcome",
    "OneShotPlanner",
    "PathPlanner",
    "PathPlannerParams",
    "PlanningError",
    "PlanningScene",
    "PluginContext",
    "PluginError",
    "Pose",
    "PoseGoal",
    "QueryEnds",
    "RGBDFrame",
    "RecedingHorizonMPC",
    "RecedingHorizonPlanner",
    "RecedingParams",
    "Registry",
    "Retimer",
    "Robot",
    "SceneCloud",
    "SceneView",
    "Segment",
    "SelfRows",
    "Settings",
    "Solved",
    "SphereModel",
    "StageFailed",
    "Status",
    "Trajectory",
    "TwinError",
    "URArm",
    "UnknownNameError",
    "Verdict",
    "Weights",
    "WorldError",
    "add_time",
    "as_q",
    "box_gaps",
    "cluster_points",
    "colliding_pair",
    "color_distance",
    "densify",
    "densify_path",
    "first_collision",
    "first_flagged_motion",
    "first_touch_on_motion",
    "footprint",
    "goal_miss",
    "goal_set",
    "guess_slack",
    "hookimpl",
    "jerk_limited",
    "judge_in_bin",
    "judge_in_zone",
    "leave_cover",
    "limits_from_settings",
    "link_groups",
    "load_config",
    "make_context",
    "make_planner",
    "matrix_to_quat",
    "matrix_to_rpy",
    "no_runtime_njit",
    "padded_scene",
    "pair_gaps",
    "palette",
    "path_length",
    "pose_from_xyz_rpy",
    "quat_to_matrix",
    "quats_to_matrices",
    "query_ends",
    "robot_spheres",
    "rpy_matrix",
    "rpy_to_matrix",
    "sampling_bounds",
    "scene_cloud",
    "self_pairs",
    "self_rows",
    "self_violation",
    "sphere_evaluate",
    "sphere_positions",
    "stage",
    "start_failure",
    "subdivide",
    "timed_and_checked",
    "top_down",
    "trajectory_check_points",
    "urdf_rgba",
    "warm_up_checks",
    "warm_up_retimer",
    "with_object",
    "wrap_to_pi",
]

if TYPE_CHECKING:
    from twin.camera import RGBDFrame
    from twin.collision import FixtureSpec, PlanningScene, SphereModel
    from twin.collision.planning_model import leave_cover
    from twin.collision.sphere_kernel import (
        KERNEL_FINGERPRINT,
        first_flagged_motion,
        first_touch_on_motion,
        no_runtime_njit,
        sphere_evaluate,
    )
    from twin.config import Settings, load_config
    from twin.perception.colors import color_distance, palette
    from twin.perception.detection import CLASSES, Detection, Detector, SceneCloud, scene_cloud
    from twin.perception.segmentation import Cluster, cluster_points, footprint
    from twin.planning import (
        GOAL_KINDS,
        OneShotPlanner,
        PathPlanner,
        RecedingHorizonPlanner,
        Retimer,
        SceneView,
        Segment,
        colliding_pair,
        densify,
        densify_path,
        first_collision,
        goal_miss,
        jerk_limited,
        limits_from_settings,
        make_context,
        make_planner,
    )
    from twin.planning.guess import guess_slack
    from twin.planning.paths import (
        PathPlannerParams,
        QueryEnds,
        add_time,
        goal_set,
        padded_scene,
        path_length,
        query_ends,
        sampling_bounds,
        start_failure,
        timed_and_checked,
        trajectory_check_points,
        warm_up_checks,
        warm_up_retimer,
    )
    from twin.planning.proxy_spheres import (
        CHECK_TOL_M,
        CHORD_EPS2,
        DISTANCE_EPS2,
        TCP_FRAME,
        Box,
        box_gaps,
        robot_spheres,
        sphere_positions,
        subdivide,
        with_object,
    )
    from twin.planning.receding import RecedingHorizonMPC, Solved
    from twin.planning.receding_params import (
        DEFAULT_ARM_SPHERES,
        DEFAULT_WHOLE_ARM_TOOL_SPHERES,
        RecedingParams,
        Weights,
    )
    from twin.planning.selfrows import SelfRows, link_groups, pair_gaps, self_pairs, self_rows, self_violation
    from twin.registry import Kind, PluginContext, Registry
    from twin.robot import Robot
    from twin.robot.kinematics import DHParameters, URArm, wrap_to_pi
    from twin.robot.urdf_model import urdf_rgba
    from twin.scene_layout import OBJECT_TEMPLATES
    from twin.tasks.cell import Cell
    from twin.tasks.grasping import GraspCheck, GripStatus, top_down
    from twin.tasks.judge import Verdict, judge_in_bin, judge_in_zone
    from twin.tasks.stage_failure import StageFailed
    from twin.timing import stage
    from twin.transforms import (
        matrix_to_quat,
        matrix_to_rpy,
        pose_from_xyz_rpy,
        quat_to_matrix,
        quats_to_matrices,
        rpy_to_matrix,
    )
    from twin.types import (
        EXACT_JOINT_TOLERANCE_RAD,
        EXACT_ORIENTATION_TOLERANCE_RAD,
        EXACT_POSITION_TOLERANCE_M,
        BoxBounds,
        Goal,
        JointGoal,
        Landmark,
        Limits,
        MotionRequest,
        MotionResult,
        ObjectOutcome,
        Pose,
        PoseGoal,
        Status,
        Trajectory,
        as_q,
        rpy_matrix,
    )


# Deprecated names, still resolved for third-party plugins: name -> (the name now, why)
_DEPRECATED = {
    "UR5e": ("URArm", "twin.plugin.UR5e is deprecated: it was any arm of robot.model, not only a UR5e; use URArm"),
}


def __getattr__(name: str) -> Any:
    if name in _DEPRECATED:
        new, why = _DEPRECATED[name]
        warnings.warn(why, DeprecationWarning, stacklevel=2)
        return __getattr__(new)
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'twin.plugin' has no attribute {name!r}")
    value = getattr(importlib.import_module(mod), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
