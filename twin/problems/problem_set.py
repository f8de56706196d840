"""The problem-set file: motion problems another tool can plan exactly as twin does.

A problem set is one JSON document (`twin-problem-set`, version 1 or 2; JSON Schema shipped as
`twin/data/schemas/problem-set.schema.json`, generated from these models):

* `robot`: the URDF (as the scene config names it) and the arm's joint names, in the order every joint
  vector of the file uses; the TCP frame and the gripper opening the collision model assumes; the link
  pairs the self-collision check skips and the links fixed to the world (not checked against it), so
  another tool checks collisions as twin does (twin itself derives both from the URDF);
* `world`: the collision world as primitives in the robot base frame, grouped into named objects as
  MoveIt's `CollisionObject` groups them (box: full extents; cylinder: radius and length along its z;
  sphere: radius), and the held object, if any (a box in the TCP frame);
* `problems`: start, goal (joint angles; a TCP or flange pose reached exactly, or within a tolerance;
  or a position, the orientation free), time limit and the seed the planner is given; from version 2, a
  problem may carry its own `world` (MotionBenchMaker stores a scene per request), which replaces the
  set's for that problem. A set none of whose problems has one is written as version 1.

Why primitives and not a reference to a twin scene config: a file that needs twin to be read is no
exchange format. Poses are {position [x, y, z] m, orientation [x, y, z, w]} (MoveIt's and PyBullet's
quaternion order). Loading validates the whole file and names the first bad key in one line.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_serializer, model_validator

from twin.config.loader import format_validation
from twin.errors import ConfigError
from twin.transforms import matrix_to_quat, quat_to_matrix

__all__ = [
    "FORMAT",
    "VERSION",
    "VERSIONS",
    "BoxShape",
    "CollisionObject",
    "CylinderShape",
    "HeldObject",
    "JointGoalSpec",
    "PoseGoalSpec",
    "PoseSpec",
    "Problem",
    "ProblemSet",
    "RobotSpec",
    "SphereShape",
    "WorldSpec",
    "json_schema",
    "load_problem_set",
    "problem_set_from_dict",
    "save_problem_set",
]

FORMAT: Literal["twin-problem-set"] = "twin-problem-set"
VERSION: Literal[2] = 2  # the newest version this twin reads and writes
VERSIONS = (1, 2)  # 2: a problem may carry its own world

Vec3 = tuple[float, float, float]
Q6 = tuple[float, float, float, float, float, float]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _finite(values: Any, what: str) -> None:
    if not all(math.isfinite(float(v)) for v in values):
        raise ValueError(f"{what} must be finite numbers")


PositiveLength = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Size3 = tuple[PositiveLength, PositiveLength, PositiveLength]  # full extents, m


class PoseSpec(_Model):
    """A rigid pose: position (m) and unit quaternion x, y, z, w."""

    position: Vec3
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    @model_validator(mode="after")
    def _valid(self) -> PoseSpec:
        _finite((*self.position, *self.orientation), "pose values")
        n = math.sqrt(sum(v * v for v in self.orientation))
        if abs(n - 1.0) > 1e-3:
            raise ValueError(f"orientation must be a unit quaternion [x, y, z, w], its norm is {n:.4g}")
        return self

    def matrix(self) -> np.ndarray:
        """(4, 4) homogeneous transform."""
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(np.asarray(self.orientation, dtype=float))
        T[:3, 3] = self.position
        return T

    @classmethod
    def of(cls, T: np.ndarray) -> PoseSpec:
        q = matrix_to_quat(np.asarray(T, dtype=float)[:3, :3])
        x, y, z = (float(v) for v in T[:3, 3])
        qx, qy, qz, qw = (float(v) for v in q / np.linalg.norm(q))
        return cls(position=(x, y, z), orientation=(qx, qy, qz, qw))


class BoxShape(_Model):
    shape: Literal["box"] = "box"
    size: Size3 = Field(description="full extents along the primitive's x, y, z (m)")
    pose: PoseSpec

    def dims(self) -> tuple[float, ...]:
        """Dimensions in twin's shape convention (twin.robot.urdf_model.Shape)."""
        return tuple(self.size)


class CylinderShape(_Model):
    shape: Literal["cylinder"] = "cylinder"
    radius: float = Field(gt=0, allow_inf_nan=False)
    length: float = Field(gt=0, allow_inf_nan=False, description="along the primitive's z (m)")
    pose: PoseSpec

    def dims(self) -> tuple[float, ...]:
        return (self.radius, self.length)


class SphereShape(_Model):
    shape: Literal["sphere"] = "sphere"
    radius: float = Field(gt=0, allow_inf_nan=False)
    pose: PoseSpec

    def dims(self) -> tuple[float, ...]:
        return (self.radius,)


Primitive = Annotated[BoxShape | CylinderShape | SphereShape, Field(discriminator="shape")]


class CollisionObject(_Model):
    """A named obstacle made of primitives (poses in the world frame)."""

    name: str = Field(min_length=1)
    primitives: list[Primitive] = Field(min_length=1)


class HeldObject(_Model):
    """A box the gripper holds: it moves with the TCP and is checked against the world and the arm."""

    name: str = Field(min_length=1)
    size: Size3
    pose_in_tcp: PoseSpec


class WorldSpec(_Model):
    """The collision world. `perceived_boxes` names the objects (each one box) that a perception step
    reports in twin's cell rather than fixtures it knows: planners that model obstacles as boxes (nmpc)
    see those, as they do in a task; every planner's collision checks see every object."""

    frame: str = Field("base_link", description="the frame every pose of the world and goals is in")
    objects: list[CollisionObject] = Field(default_factory=list)
    held_object: HeldObject | None = None
    perceived_boxes: list[str] = Field(
        default_factory=list, description="objects (one box each) reported as obstacle boxes, not known fixtures"
    )

    @model_validator(mode="after")
    def _unique(self) -> WorldSpec:
        names = [o.name for o in self.objects]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"object names must be unique, repeated: {dup}")
        by_name = {o.name: o for o in self.objects}
        for n in self.perceived_boxes:
            o = by_name.get(n)
            if o is None or len(o.primitives) != 1 or o.primitives[0].shape != "box":
                raise ValueError(f"perceived_boxes: {n!r} is not an object made of one box")
        return self


class RobotSpec(_Model):
    urdf: str = Field(description="the robot URDF as the scene config names it (e.g. urdf/ur5e_gripper.urdf)")
    joint_names: list[str] = Field(min_length=1, description="the arm joints, in the order of every joint vector")
    tcp_frame: str = "tcp"
    gripper_opening_m: float | None = Field(None, ge=0, description="finger opening the collision model assumes")
    allowed_self_collisions: list[tuple[str, str]] = Field(
        default_factory=list, description="link pairs never checked against each other (an SRDF's disable_collisions)"
    )
    static_links: list[str] = Field(
        default_factory=list, description="links fixed to the world frame: never checked against the world objects"
    )


class JointGoalSpec(_Model):
    kind: Literal["joint"] = "joint"
    joints: list[float]


class PoseGoalSpec(_Model):
    """`pose`: the frame reaches the pose (within `position_tolerance_m` when given, else exactly);
    `position`: the frame's origin within `position_tolerance_m` of the pose's position, orientation free."""

    kind: Literal["pose", "position"]
    pose: PoseSpec
    frame: Literal["tcp", "flange"] = "tcp"
    position_tolerance_m: float | None = Field(None, gt=0, le=0.1)

    @model_validator(mode="after")
    def _tolerance(self) -> PoseGoalSpec:
        if self.kind == "position" and self.position_tolerance_m is None:
            raise ValueError("a position goal needs position_tolerance_m")
        return self


Goal = Annotated[JointGoalSpec | PoseGoalSpec, Field(discriminator="kind")]


class Problem(_Model):
    id: str = Field(min_length=1)
    start: list[float]
    goal: Goal
    time_limit_s: float = Field(1.0, gt=0, allow_inf_nan=False)
    seed: int = Field(0, ge=0)
    world: WorldSpec | None = Field(
        None, description="version 2: this problem's own collision world, replacing the set's (None: the set's)"
    )

    @model_serializer(mode="wrap")
    def _without_own_world(self, handler: Any) -> Any:
        """A problem without its own world is written as version 1 wrote it (no `world` key), so its file,
        and the run ids hashed from it, stay what they were."""
        data = handler(self)
        if isinstance(data, dict) and data.get("world") is None:
            data.pop("world", None)
        return data

    @model_validator(mode="after")
    def _finite_values(self) -> Problem:
        _finite(self.start, "start")
        if isinstance(self.goal, JointGoalSpec):
            _finite(self.goal.joints, "goal joints")
        return self


class ProblemSet(_Model):
    format: Literal["twin-problem-set"] = FORMAT
    version: Literal[1, 2] = 1
    name: str = "problems"
    description: str = ""
    source: dict[str, Any] = Field(default_factory=dict, description="where the problems came from (free form)")
    robot: RobotSpec
    world: WorldSpec = Field(default_factory=WorldSpec)
    problems: list[Problem] = Field(min_length=1)

    @model_validator(mode="after")
    def _consistent(self) -> ProblemSet:
        n = len(self.robot.joint_names)
        ids = [p.id for p in self.problems]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"problem ids must be unique, repeated: {dup[:5]}")
        for i, p in enumerate(self.problems):
            if len(p.start) != n:
                raise ValueError(f"problems.{i}.start has {len(p.start)} values; the robot has {n} joints")
            if isinstance(p.goal, JointGoalSpec) and len(p.goal.joints) != n:
                raise ValueError(f"problems.{i}.goal.joints has {len(p.goal.joints)} values; the robot has {n} joints")
            if p.world is not None and self.version < 2:
                raise ValueError(f"problems.{i}.world: a problem's own world needs version 2")
        return self

    def world_of(self, index: int) -> WorldSpec:
        """The collision world problem `index` is planned in: its own, else the set's."""
        own = self.problems[index].world
        return own if own is not None else self.world


def json_schema() -> dict[str, Any]:
    """The JSON Schema of a problem-set file (what `twin/data/schemas/problem-set.schema.json` holds)."""
    schema = ProblemSet.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["$id"] = "https://github.com/twin-robotics/twin/schemas/problem-set-2.schema.json"
    schema["title"] = "twin problem set, versions 1 and 2"
    return schema


def problem_set_from_dict(data: Any, *, source: str = "<dict>") -> ProblemSet:
    """Validate a parsed problem-set document; ConfigError naming the first bad key otherwise."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a problem set is a JSON object, got {type(data).__name__}")
    fmt, ver = data.get("format"), data.get("version")
    if fmt != FORMAT:
        raise ConfigError(f"{source}: not a problem set (format {fmt!r}; expected {FORMAT!r})")
    if ver not in VERSIONS:
        raise ConfigError(
            f"{source}: problem-set version {ver!r} is not supported; this twin reads versions "
            + ", ".join(str(v) for v in VERSIONS)
        )
    try:
        return ProblemSet.model_validate(data)
    except ValidationError as err:
        raise ConfigError(format_validation(source, err)) from None


def load_problem_set(path: str | Path) -> ProblemSet:
    """Read and validate a problem-set file; ConfigError with one line for a missing, unreadable or
    invalid file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"problem set {p} does not exist") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"cannot read problem set {p}: {e}") from None
    try:
        data = json.loads(text)
    except ValueError as e:
        raise ConfigError(f"{p}: not valid JSON: {e}") from None
    return problem_set_from_dict(data, source=str(p))


def save_problem_set(ps: ProblemSet, path: str | Path) -> Path:
    """Write `ps` as indented JSON; ConfigError when the file cannot be written."""
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(ps.model_dump(mode="json"), indent=1) + "\n", encoding="utf-8")
    except OSError as e:
        raise ConfigError(f"cannot write the problem set {p}: {e.strerror}") from None
    return p
