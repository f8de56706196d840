"""Small immutable data types shared by planners, the executor and the comparison runner.

Units: metres, radians, seconds; quaternions x-y-z-w (PyBullet's order); poses are in the robot base frame.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from twin.errors import InvalidRequestError
from twin.transforms import matrix_to_quat, quat_to_matrix, rpy_to_matrix

rpy_matrix = rpy_to_matrix  # the old name of twin.transforms.rpy_to_matrix, kept for importers

__all__ = [
    "EXACT_JOINT_TOLERANCE_RAD",
    "EXACT_ORIENTATION_TOLERANCE_RAD",
    "EXACT_POSITION_TOLERANCE_M",
    "BoxBounds",
    "CalibrationOutcome",
    "Goal",
    "JointGoal",
    "Landmark",
    "Limits",
    "MotionRequest",
    "MotionResult",
    "ObjectOutcome",
    "Pose",
    "PoseGoal",
    "RunSummary",
    "Status",
    "Trajectory",
    "as_q",
    "matrix_to_quat",
    "quat_to_matrix",
    "rpy_matrix",
]


def as_q(q: Any, what: str = "q") -> np.ndarray:
    """A (6,) float array of joint angles, or InvalidRequestError naming `what`."""
    try:
        arr = np.array(q, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InvalidRequestError(f"{what} must be 6 joint angles in rad, got {q!r}") from None
    if arr.shape != (6,):
        raise InvalidRequestError(f"{what} must be 6 joint angles in rad, got {arr.size} values")
    if not np.all(np.isfinite(arr)):
        raise InvalidRequestError(f"{what} must be finite, got {arr.tolist()}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class Pose:
    """A rigid pose: position (3,) m and quaternion (4,) x-y-z-w, in the base frame unless named."""

    position: np.ndarray
    quat_xyzw: np.ndarray

    @classmethod
    def from_matrix(cls, T: np.ndarray) -> Pose:
        T = np.asarray(T, dtype=float)
        return cls(T[:3, 3].copy(), matrix_to_quat(T[:3, :3]))

    @classmethod
    def from_xyz_rpy(cls, xyz: Any, rpy: Any) -> Pose:
        """Position and fixed-axis roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll))."""
        R = rpy_to_matrix(rpy)
        return cls(np.array(xyz, dtype=float), matrix_to_quat(R))

    def matrix(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(np.asarray(self.quat_xyzw, dtype=float))
        T[:3, 3] = self.position
        return T


# how close "reached" is when a goal does not say: exact for practical purposes (planners that end on an
# IK solution or on the goal joints are ~1e-12 off; 10 um / 0.1 mrad leave room for float round-off only)
EXACT_JOINT_TOLERANCE_RAD = 1e-4
EXACT_POSITION_TOLERANCE_M = 1e-5
EXACT_ORIENTATION_TOLERANCE_RAD = 1e-4


def _check_tolerance(value: float | None, what: str, *, optional: bool = False) -> None:
    if value is None and optional:
        return
    if value is None or not (math.isfinite(value) and value > 0):
        raise InvalidRequestError(f"{what} must be a positive number{' or None' if optional else ''}, got {value!r}")


@dataclass(frozen=True)
class JointGoal:
    """Reach these joint angles, (6,) rad: every joint within `tolerance_rad` at the end."""

    q: np.ndarray
    tolerance_rad: float = EXACT_JOINT_TOLERANCE_RAD

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", as_q(self.q, "goal"))
        _check_tolerance(self.tolerance_rad, "JointGoal.tolerance_rad")

    @property
    def kind(self) -> str:
        """'joint' (see `twin.planning.GOAL_KINDS`)."""
        return "joint"


@dataclass(frozen=True)
class PoseGoal:
    """Reach this pose of `frame` ('tcp' or 'flange') in the base frame.

    Reached means: the frame's origin within `position_tolerance_m` of the pose's position and, unless
    `orientation_tolerance_rad` is None (orientation free: a position goal), its rotation within that
    angle of the pose's rotation. Every planner is judged by these numbers (`twin.planning`)."""

    pose: Pose
    frame: str = "tcp"
    position_tolerance_m: float = EXACT_POSITION_TOLERANCE_M
    orientation_tolerance_rad: float | None = EXACT_ORIENTATION_TOLERANCE_RAD

    def __post_init__(self) -> None:
        _check_tolerance(self.position_tolerance_m, "PoseGoal.position_tolerance_m")
        _check_tolerance(self.orientation_tolerance_rad, "PoseGoal.orientation_tolerance_rad", optional=True)

    @property
    def kind(self) -> str:
        """'pose', or 'position' when the orientation is free (see `twin.planning.GOAL_KINDS`)."""
        return "position" if self.orientation_tolerance_rad is None else "pose"


Goal = JointGoal | PoseGoal


@dataclass(frozen=True)
class Limits:
    """Joint limits for time parameterisation, per joint (6,): rad/s, rad/s^2, rad/s^3; optional TCP m/s."""

    max_joint_vel: np.ndarray
    max_joint_acc: np.ndarray
    max_joint_jerk: np.ndarray
    max_tcp_speed: float | None = None

    @classmethod
    def uniform(cls, vel: float, acc: float, jerk: float, tcp_speed: float | None = None) -> Limits:
        return cls(np.full(6, float(vel)), np.full(6, float(acc)), np.full(6, float(jerk)), tcp_speed)

    def __post_init__(self) -> None:
        for name in ("max_joint_vel", "max_joint_acc", "max_joint_jerk"):
            v = np.broadcast_to(np.asarray(getattr(self, name), dtype=float), (6,)).copy()
            if not np.all(v > 0):
                raise InvalidRequestError(f"{name} must be positive, got {v.tolist()}")
            object.__setattr__(self, name, v)
        if self.max_tcp_speed is not None and self.max_tcp_speed <= 0:
            raise InvalidRequestError(f"max_tcp_speed must be positive or None, got {self.max_tcp_speed}")


@dataclass(frozen=True)
class MotionRequest:
    """One motion query: from `start` (6,) rad to `goal`, under `limits`, within `time_limit_s` of planning."""

    start: np.ndarray
    goal: Goal
    limits: Limits
    time_limit_s: float = 1.0
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", as_q(self.start, "start"))
        if not isinstance(self.goal, (JointGoal, PoseGoal)):
            raise InvalidRequestError(f"goal must be a JointGoal or PoseGoal, got {type(self.goal).__name__}")
        if self.time_limit_s <= 0:
            raise InvalidRequestError(f"time_limit_s must be positive, got {self.time_limit_s}")


class Status(enum.Enum):
    """How a planning request ended. Only SUCCESS carries a trajectory."""

    SUCCESS = "success"
    NO_SOLUTION = "no_solution"  # the planner searched and found nothing
    TIMEOUT = "timeout"  # the time limit ran out
    INVALID_START = "invalid_start"  # the start is in collision or outside the limits
    INVALID_GOAL = "invalid_goal"  # the goal is in collision, unreachable or has no IK
    COLLISION = "collision"  # the only trajectory found collides (never returned as success)
    IK_FAILED = "ik_failed"  # a waypoint had no acceptable IK solution
    LIMIT_VIOLATION = "limit_violation"  # time parameterisation could not keep the limits
    EXECUTION_STOPPED = "execution_stopped"  # executing it, the arm touched something unexpected and stopped


@dataclass(frozen=True)
class Trajectory:
    """A time-parameterised joint trajectory: t (n,) s from 0; q, qd, qdd (n, 6)."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float)
        n = t.shape[0]
        for name in ("q", "qd", "qdd"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != (n, 6):
                raise InvalidRequestError(f"Trajectory.{name} must have shape ({n}, 6), got {a.shape}")
            object.__setattr__(self, name, a)
        if n < 1 or np.any(np.diff(t) <= 0):
            raise InvalidRequestError("Trajectory.t must be non-empty and strictly increasing")
        object.__setattr__(self, "t", t)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def sample(self, t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, qd, qdd at time(s) t: cubic Hermite on q (from q and qd), linear on qd and qdd; clamped at the ends."""
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        ts = np.clip(ts, self.t[0], self.t[-1])
        if self.t.shape[0] == 1:
            n = ts.shape[0]
            out = (
                np.repeat(self.q[:1], n, axis=0),
                np.repeat(self.qd[:1], n, axis=0),
                np.repeat(self.qdd[:1], n, axis=0),
            )
        else:
            i = np.clip(np.searchsorted(self.t, ts, side="right") - 1, 0, self.t.shape[0] - 2)
            h = (self.t[i + 1] - self.t[i])[:, None]
            s = (ts[:, None] - self.t[i][:, None]) / h
            q0, q1, v0, v1 = self.q[i], self.q[i + 1], self.qd[i], self.qd[i + 1]
            h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
            q = h00 * q0 + h10 * h * v0 + h01 * q1 + h11 * h * v1
            qd = v0 + s * (v1 - v0)
            qdd = self.qdd[i] + s * (self.qdd[i + 1] - self.qdd[i])
            out = q, qd, qdd
        if np.ndim(t) == 0:
            return out[0][0], out[1][0], out[2][0]
        return out

    def resampled(self, dt: float) -> Trajectory:
        """The same motion sampled every `dt` seconds (last sample at the end time)."""
        ts = np.arange(self.t[0], self.t[-1], dt)
        ts = np.append(ts, self.t[-1]) if ts.size == 0 or ts[-1] < self.t[-1] - 1e-12 else ts
        q, qd, qdd = self.sample(ts)
        return Trajectory(ts, q, qd, qdd)


@dataclass(frozen=True)
class MotionResult:
    """What a planner returns: a status with a reason; a trajectory only on SUCCESS."""

    status: Status
    reason: str = ""
    trajectory: Trajectory | None = None
    planning_time_s: float = 0.0
    # (m, 6) geometric waypoints before time parameterisation, if any; on a refusal (collision, joint limits) the
    # joints of the refused motion when the planner or the judge had one (never executed: for seeing why)
    path: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)
    # A planner that stops near a goal rather than on it (NMPC) says how near it aimed (m); None: exact.
    goal_tolerance_m: float | None = None

    @property
    def success(self) -> bool:
        return self.status is Status.SUCCESS

    def __post_init__(self) -> None:
        if self.status is Status.SUCCESS and self.trajectory is None:
            raise InvalidRequestError("a successful MotionResult needs a trajectory")


@dataclass(frozen=True)
class BoxBounds:
    """An axis-aligned box in the base frame, metres."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float
    z_min: float
    z_max: float

    def __post_init__(self) -> None:
        if not (self.x_min <= self.x_max and self.y_min <= self.y_max and self.z_min <= self.z_max):
            raise InvalidRequestError(f"BoxBounds needs min <= max on every axis, got {self}")

    @property
    def lo(self) -> np.ndarray:
        return np.array([self.x_min, self.y_min, self.z_min])

    @property
    def hi(self) -> np.ndarray:
        return np.array([self.x_max, self.y_max, self.z_max])

    def extended_y(self, margin_m: float) -> BoxBounds:
        """The box grown by `margin_m` in +y and -y (the warehouse system's trick to force going over)."""
        return BoxBounds(self.x_min, self.x_max, self.y_min - margin_m, self.y_max + margin_m, self.z_min, self.z_max)


@dataclass(frozen=True)
class Landmark:
    """A place a task puts things that no body marks (a drop zone on the table): a task plugin's optional
    `landmarks()` lists them, and pictures of a run (`twin scene --snapshot`, `--record`) draw each as a
    circle of `radius_m` on the table at `position` (base frame), labelled `name`."""

    name: str
    position: tuple[float, float, float]
    radius_m: float


@dataclass(frozen=True)
class ObjectOutcome:
    """What happened to one object in a task run (judged by physics ground truth at the end)."""

    id: str
    cls: str
    color: str | None
    target_bin: str
    placed: bool
    error: str | None = None  # why it was not placed (None when placed)
    cycle_time_s: float = 0.0  # simulated time spent on this object
    pose_error_m: float | None = None  # perceived vs true centroid, xy
    failure: str | None = None  # the failure's name (a twin.failures.FAILURES key) when the task knew it
    # the stage that failed ("transfer", "descent", "perception", ...; None when placed) and the planner that
    # planned it (the stage's planner block name; None when no motion failed, e.g. a grasp not sensed)
    stage: str | None = None
    planner: str | None = None


@dataclass(frozen=True)
class CalibrationOutcome:
    """How a run knew where its camera was: the run summary's `calibration` entry.

    `status`: "measured" (the base marker calibrated it), "fallback" (a calibration was asked for and the
    marker was not found in any view, or in one of a fixed camera's captures: the configured pose was used,
    levelled on the table plane where one is seen) or "configured" (none asked for: the configured pose is the
    model). `views`: marker views taken.
    `reprojection_px`: the used estimate's marker reprojection RMS. `error_bound_m`: what a point on the
    table, seen from the capture pose, may be misplaced by through the camera pose used (fallback: from
    the mount tolerance, see `twin.perception.mount`). `reason`: why it is not "measured".
    """

    status: str  # "measured" | "fallback" | "configured"
    views: int = 0
    reprojection_px: float | None = None
    error_bound_m: float | None = None
    reason: str = ""

    def to_json(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "views": self.views,
            "reprojection_px": self.reprojection_px,
            "error_bound_m": self.error_bound_m,
            "reason": self.reason,
        }


@dataclass(frozen=True)
class RunSummary:
    """One `twin run`: per-object outcomes and totals; `to_json()` is the --json file's content."""

    config: str
    seed: int
    planner: str
    objects: tuple[ObjectOutcome, ...]
    sim_time_s: float
    wall_time_s: float
    metrics: dict[str, Any] = field(default_factory=dict)  # planner metrics gathered over the run
    # wall seconds per stage (twin.timing): physics, rendering, perception.<step>, planning.<planner>,
    # execution, world_build, other; they sum to wall_time_s
    timings: dict[str, float] = field(default_factory=dict)
    # what ran: each stage group's planner ('movej', 'movel', 'transfer') as a block with every parameter the
    # plugin ran with (its validated params, defaults included: two runs of one planner in different modes differ)
    planners: dict[str, dict[str, Any]] = field(default_factory=dict)
    # every exception a planner plugin raised ("stage: plugin raised ..."), the stage failing with it
    plugin_errors: tuple[str, ...] = ()
    # how the run knew its camera pose (None: the task did not say; `run_task` fills "configured" then)
    calibration: CalibrationOutcome | None = None

    @property
    def success_rate(self) -> float:
        return sum(o.placed for o in self.objects) / len(self.objects) if self.objects else 0.0

    def to_json(self) -> dict[str, Any]:
        return {
            "config": self.config,
            "seed": self.seed,
            "planner": self.planner,
            "planners": self.planners,
            "plugin_errors": list(self.plugin_errors),
            "objects": [
                {
                    "id": o.id,
                    "class": o.cls,
                    "color": o.color,
                    "target_bin": o.target_bin,
                    "placed": o.placed,
                    "error": o.error,
                    "failure": o.failure,
                    "stage": o.stage,
                    "planner": o.planner,
                    "cycle_time_s": o.cycle_time_s,
                    "pose_error_m": o.pose_error_m,
                }
                for o in self.objects
            ],
            "success_rate": self.success_rate,
            "sim_time_s": self.sim_time_s,
            "wall_time_s": self.wall_time_s,
            "timings": self.timings,
            "metrics": self.metrics,
            "calibration": None if self.calibration is None else self.calibration.to_json(),
        }
