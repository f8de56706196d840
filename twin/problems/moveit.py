"""MoveIt planning scenes and motion plan requests (YAML) as a problem set (`twin problems import-moveit`).

MotionBenchMaker, robowflex and MoveIt users keep scenes as YAML of `moveit_msgs/PlanningScene` and queries
as YAML of `moveit_msgs/MotionPlanRequest`. Both spellings of that YAML are read: ROS's message YAML
(`position: {x: .., y: .., z: ..}`, `type: 1`) and robowflex's (`position: [x, y, z]`, `type: box`, a
missing header meaning frame `world`). Why an importer rather than a planner for MoveIt files: the problem
set is the one format `twin compare` plans, so a MoveIt benchmark becomes a scenario like any other.

Frames (read this): the YAML names ROS frames, and ROS's UR description (`ur_description`, ROS 1 and 2) does
not put `base_link` where twin does. twin's `base_link` is the UR controller's base frame (DH frame 0: with
the shoulder pan at 0 the arm reaches towards -x). ur_description's `base_link` is REP-103 aligned, turned
180 deg about z from that (the arm reaches towards +x), and its frame `base` is the controller's base, so
twin's `base_link`. Joint angles mean the same in both. Hence `frames`:

* `"ur_description"` (default, for files written with ROS's UR models, MotionBenchMaker's included):
  `base_link` is turned 180 deg about z into twin's frame (x, y -> -x, -y); `base` is twin's `base_link`;
* `"twin"` (for files written against twin's own URDF): `base_link` and `base` are twin's `base_link`.

`world` and `""` are `base_link` (a fixed arm's virtual joint is the identity) unless the scene's
`fixed_frame_transforms` place `world`; any frame those transforms connect to the ones above (either
direction, chains too) is accepted; anything else (a camera frame, a robot link) is a one-line error.

Supported, else a one-line ConfigError naming the file, the key path and what is accepted:

* scene: `world.collision_objects` with operation ADD (absent, 0 or "add"), box / sphere / cylinder
  primitives (shape_msgs/SolidPrimitive: type 1/2/3 or "box"/"sphere"/"cylinder"; dimensions BOX [x, y, z]
  full extents, SPHERE [radius], CYLINDER [height, radius]) at `primitive_poses` composed with the
  object's `pose` (MoveIt >= 1.1.6; absent: identity); `robot_state.joint_state` as the default start;
  `fixed_frame_transforms`; `name` (the set's name).
  Rejected: meshes, planes, cones and prisms, REMOVE/APPEND/MOVE, an octomap with data, attached
  collision objects, `link_padding` other than 0 and `link_scale` other than 1, multi-DOF joint states
  (each changes what collides, so ignoring it would make a different problem).
  Ignored with a warning: `allowed_collision_matrix` entries naming world objects (twin checks every
  object against the robot: stricter), subframes, repeated ids (the later ADD replaces, as in MoveIt).
  Ignored silently: the rest of the collision matrix (robot pairs; twin has its own rules),
  `object_colors`, `robot_model_name`, `is_diff`, object `type`.
* request: `start_state.joint_state` (any order, merged over the scene's `robot_state` as MoveIt merges
  a diff) naming the 6 arm joints, twin's finger joints and `ignore_joints` allowed besides; the first
  of `goal_constraints` (the others: a warning) as
  - `joint_constraints` for all 6 arm joints: an exact joint goal. Tolerances up to 1e-3 rad are MoveIt's
    "exact"; larger ones give a warning and the goal at the centre (a stricter problem: every path to
    the centre reaches MoveIt's region);
  - one `position_constraints` whose region is a single sphere (as MoveIt writes a pose goal) for link
    `tool0` (the flange, the same frame in ur_description and twin) or `tcp` (twin's tcp link, whatever a
    MoveIt config's own tcp is), and optionally one `orientation_constraints` for the same link: a pose
    goal (the sphere radius as position tolerance when above 1e-3 m, at most 0.1 m; the orientation
    reached exactly, a warning when the file allowed more than 0.01 rad) or, without an orientation
    constraint or with all three tolerances >= pi, a position goal. A position goal carries the link's
    orientation at the start, which planners that solve IK for it take as the preferred one;
  `allowed_planning_time` (0 or absent: 1 s) unless `time_limit_s` is given.
  Rejected: visibility constraints, goals mixing joint and Cartesian constraints, path and trajectory
  constraints, attached objects and multi-DOF states in the start state.
  Ignored: `group_name`, `planner_id`, `pipeline_id`, `num_planning_attempts`, velocity / acceleration /
  Cartesian speed scaling, `workspace_parameters`, `reference_trajectories`, constraint weights.
"""

from __future__ import annotations

import fnmatch
import logging
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from twin.config import find_config, load_config
from twin.config.loader import read_yaml
from twin.errors import ConfigError
from twin.messages import one_line, short_repr
from twin.problems.problem_set import (
    BoxShape,
    CollisionObject,
    CylinderShape,
    JointGoalSpec,
    PoseGoalSpec,
    PoseSpec,
    Problem,
    ProblemSet,
    SphereShape,
    WorldSpec,
)
from twin.problems.world import robot_spec
from twin.resources import packaged_config
from twin.transforms import pose_from_xyz_rpy

if TYPE_CHECKING:
    from twin.collision import PlanningScene

__all__ = ["MOVEIT_ROBOTS", "MoveItRobot", "problem_set_from_moveit", "problem_set_from_moveit_dir"]

log = logging.getLogger("twin")

FrameConvention = Literal["ur_description", "twin"]
Source = str | Path | Mapping[str, Any]

# tolerances up to these are MoveIt's way of writing "reach it": what twin's exact goals mean
_EXACT_JOINT_RAD = 1e-3  # MoveIt writes epsilon (robowflex), 1e-4 (MoveGroup's default) or 1e-3
_EXACT_POSITION_M = 1e-3  # MoveIt's default pose-goal sphere radius
_EXACT_ORIENTATION_RAD = 1e-2  # MoveIt's default pose-goal orientation tolerance
_MAX_POSITION_TOLERANCE_M = 0.1  # what a problem set's position goal allows

_PRIMITIVES = {1: "box", 2: "sphere", 3: "cylinder", 4: "cone", 5: "prism"}  # shape_msgs/SolidPrimitive
_DIMENSIONS = {"box": (3, "[x, y, z]"), "sphere": (1, "[radius]"), "cylinder": (2, "[height, radius]")}
_OPERATIONS = {0: "add", 1: "remove", 2: "append", 3: "move"}  # moveit_msgs/CollisionObject
# the robot links a Cartesian goal may name -> PoseGoalSpec.frame (tool0 is the flange in twin's URDF and in
# ur_description alike; ur_description's `flange` link is turned against it, so it is not accepted)
_GOAL_LINKS: dict[str, Literal["tcp", "flange"]] = {"tool0": "flange", "tcp": "tcp"}

# the fields of the messages read here (moveit_msgs, ROS 1 Noetic and ROS 2): another key is a typo or a
# newer MoveIt's field, reported with a warning
_SCENE_KEYS = {
    "name",
    "robot_state",
    "robot_model_name",
    "fixed_frame_transforms",
    "allowed_collision_matrix",
    "link_padding",
    "link_scale",
    "object_colors",
    "world",
    "is_diff",
}
_OBJECT_KEYS = {
    "header",
    "pose",
    "id",
    "type",
    "primitives",
    "primitive_poses",
    "meshes",
    "mesh_poses",
    "planes",
    "plane_poses",
    "subframe_names",
    "subframe_poses",
    "operation",
}
_REQUEST_KEYS = {
    "workspace_parameters",
    "start_state",
    "goal_constraints",
    "path_constraints",
    "trajectory_constraints",
    "reference_trajectories",
    "pipeline_id",
    "planner_id",
    "group_name",
    "num_planning_attempts",
    "allowed_planning_time",
    "max_velocity_scaling_factor",
    "max_acceleration_scaling_factor",
    "cartesian_speed_limited_link",
    "cartesian_speed_end_effector_link",
    "max_cartesian_speed",
}


class _At:
    """A value of a YAML document and where it is (file and key path): every mistake becomes one line
    naming both, e.g. `scene.yaml: world.collision_objects.2.primitives.0.type: ...`."""

    __slots__ = ("path", "source", "value")

    def __init__(self, value: Any, source: str, path: tuple[str | int, ...] = ()):
        self.value = value
        self.source = source
        self.path = path

    def __str__(self) -> str:
        where = ".".join(str(p) for p in self.path) or "(top level)"
        return f"{self.source}: {where}"

    def error(self, message: str) -> ConfigError:
        return ConfigError(one_line(f"{self}: {message}", 600))

    @property
    def missing(self) -> bool:
        return self.value is None

    def __getitem__(self, key: str) -> _At:
        """The child `key` of a mapping (value None when absent)."""
        return _At(self.mapping().get(key), self.source, (*self.path, key))

    def empty(self) -> bool:
        """Absent, null or an empty list / mapping / text: what a message field at its default looks like."""
        return self.value is None or (isinstance(self.value, (list, dict, str)) and not self.value)

    def mapping(self, *, known: set[str] | None = None) -> dict[str, Any]:
        """The mapping (absent: empty); `known`: warn about other keys."""
        if self.value is None:
            return {}
        if not isinstance(self.value, dict):
            raise self.error(f"must be a mapping, got {_kind(self.value)}")
        if known is not None:
            unknown = sorted(str(k) for k in self.value if k not in known)
            if unknown:
                log.warning("%s: unknown keys %s ignored (not fields of the MoveIt message)", self, unknown)
        return self.value

    def items(self) -> list[_At]:
        """The elements of a list (absent: none)."""
        if self.value is None:
            return []
        if not isinstance(self.value, list):
            raise self.error(f"must be a list, got {_kind(self.value)}")
        return [_At(v, self.source, (*self.path, i)) for i, v in enumerate(self.value)]

    def number(self, default: float | None = None) -> float:
        v = self.value
        if v is None and default is not None:
            return default
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.error(f"must be a number, got {_kind(v)}")
        if not math.isfinite(v):
            raise self.error(f"must be a finite number, got {v}")
        return float(v)

    def text(self, default: str = "") -> str:
        if self.value is None:
            return default
        if not isinstance(self.value, str):
            raise self.error(f"must be text, got {_kind(self.value)}")
        return self.value

    def vector(self, fields: str) -> tuple[float, ...]:
        """A geometry_msgs vector as ROS writes it ({x: .., y: ..}, absent fields 0) or as robowflex
        writes it ([x, y, ..]); absent: zeros."""
        if isinstance(self.value, list):
            if len(self.value) != len(fields):
                raise self.error(f"must be {len(fields)} numbers [{', '.join(fields)}], got {len(self.value)}")
            return tuple(v.number() for v in self.items())
        self.mapping()
        return tuple(self[f].number(0.0) for f in fields)


def _kind(v: Any) -> str:
    return "nothing" if v is None else f"{type(v).__name__} {short_repr(v, 40)}"


def _read(src: Source, what: str) -> _At:
    """A scene or request document: a mapping given directly or a YAML file (one line for a missing file,
    bad YAML, a document that is not a mapping: read_yaml)."""
    if isinstance(src, Mapping):
        return _At(dict(src), f"<{what}>")
    p = Path(src)
    if not p.is_file():
        raise ConfigError(f"MoveIt {what} file {p} {'is not a file' if p.exists() else 'does not exist'}")
    return _At(read_yaml(p.resolve()), str(p))


# ---- poses and frames ----------------------------------------------------------------------------
def _pose(at: _At) -> np.ndarray:
    """(4, 4) of a geometry_msgs/Pose; absent: identity. An all-zero quaternion (a message's default) is
    the identity, as MoveIt reads it; a quaternion within 1 % of unit length is normalised (files round)."""
    at.mapping()
    return _rigid(at["position"].vector("xyz"), at["orientation"])


def _transform(at: _At) -> np.ndarray:
    """(4, 4) of a geometry_msgs/Transform (translation, rotation)."""
    at.mapping()
    return _rigid(at["translation"].vector("xyz"), at["rotation"])


def _rigid(position: tuple[float, ...], orientation: _At) -> np.ndarray:
    """(4, 4) of a position and a geometry_msgs/Quaternion (see `_pose`)."""
    q = np.array(orientation.vector("xyzw")) if not orientation.missing else np.array([0.0, 0.0, 0.0, 1.0])
    n = float(np.linalg.norm(q))
    if n == 0.0:
        q, n = np.array([0.0, 0.0, 0.0, 1.0]), 1.0
    if abs(n - 1.0) > 1e-2:
        raise orientation.error(f"must be a unit quaternion [x, y, z, w], its norm is {n:.4g}")
    x, y, z = position
    qx, qy, qz, qw = (float(v) for v in q / n)
    return PoseSpec(position=(x, y, z), orientation=(qx, qy, qz, qw)).matrix()


def _frame_name(at: _At) -> str:
    """A frame id as MoveIt compares them: without ROS 1's leading '/'; empty is the planning frame."""
    return at.text().strip().lstrip("/") or "world"


class _Frames:
    """Each frame the scene may name, as its (4, 4) pose in twin's base frame (see the module docstring)."""

    def __init__(self, scene: _At, convention: FrameConvention, world_base_link: np.ndarray | None = None):
        edges: dict[str, list[tuple[str, np.ndarray, _At]]] = {}

        def connect(a: str, b: str, T_ab: np.ndarray, at: _At) -> None:
            edges.setdefault(a, []).append((b, T_ab, at))
            edges.setdefault(b, []).append((a, np.linalg.inv(T_ab), at))

        turn = np.diag([-1.0, -1.0, 1.0, 1.0]) if convention == "ur_description" else np.eye(4)
        connect("base_link", "base", turn, scene)  # ur_description: base = base_link turned 180 deg about z
        for t in scene["fixed_frame_transforms"].items():
            t.mapping()
            parent, child = _frame_name(t["header"]["frame_id"]), _frame_name(t["child_frame_id"])
            T = _transform(t["transform"])
            if parent == child:
                if not np.allclose(T, np.eye(4), atol=1e-6):
                    raise t.error(f"transforms frame {parent!r} to itself by a non-identity")
                continue
            connect(parent, child, T, t)
        if "world" not in edges:  # a fixed arm: MoveIt's virtual joint world -> base_link (identity unless told)
            connect("world", "base_link", np.eye(4) if world_base_link is None else world_base_link, scene)
        self.known: dict[str, np.ndarray] = {"base": np.eye(4)}
        todo = ["base"]
        while todo:  # breadth first from twin's base frame; a second route to a frame must agree
            a = todo.pop(0)
            for b, T_ab, at in edges.get(a, []):
                T = self.known[a] @ T_ab
                if b not in self.known:
                    self.known[b] = T
                    todo.append(b)
                elif not np.allclose(self.known[b], T, atol=1e-6):
                    raise at.error(f"places frame {b!r} where other transforms of the scene do not")

    def pose(self, frame_id: _At) -> np.ndarray:
        """(4, 4) pose of the frame `frame_id` names in twin's base frame; ConfigError for another frame."""
        name = _frame_name(frame_id)
        if name not in self.known:
            known = ", ".join(sorted(self.known))
            raise frame_id.error(
                f"unknown frame {name!r}: poses must be in the robot base frame (known here: {known}; "
                "fixed_frame_transforms of the scene may add more)"
            )
        return self.known[name]


# ---- the scene -----------------------------------------------------------------------------------
def _primitive_type(at: _At) -> str:
    v = at.value
    if isinstance(v, str):
        name = v.strip().lower()
        if name.isdigit():
            v = int(name)
        elif name in _PRIMITIVES.values():
            return name
        else:
            raise at.error(f"unknown primitive type {v!r} (shape_msgs/SolidPrimitive: box, sphere, cylinder, cone)")
    if isinstance(v, bool) or not isinstance(v, int):
        raise at.error(f"must be a primitive type (1 box, 2 sphere, 3 cylinder or their names), got {_kind(v)}")
    if v not in _PRIMITIVES:
        raise at.error(f"unknown primitive type {v} (shape_msgs/SolidPrimitive: 1 box, 2 sphere, 3 cylinder, 4 cone)")
    return _PRIMITIVES[v]


def _primitive(at: _At, T: np.ndarray) -> BoxShape | CylinderShape | SphereShape:
    """One SolidPrimitive at pose T (base frame)."""
    at.mapping()
    kind = _primitive_type(at["type"])
    if kind not in _DIMENSIONS:
        raise at["type"].error(f"unsupported primitive {kind!r} (allowed: box, sphere, cylinder)")
    dims_at = at["dimensions"]
    dims = [d.number() for d in dims_at.items()]
    count, meaning = _DIMENSIONS[kind]
    if len(dims) != count or not all(d > 0 for d in dims):
        raise dims_at.error(f"a {kind} needs {count} positive dimensions {meaning}, got {dims}")
    pose = PoseSpec.of(T)
    if kind == "box":
        return BoxShape(size=(dims[0], dims[1], dims[2]), pose=pose)
    if kind == "sphere":
        return SphereShape(radius=dims[0], pose=pose)
    return CylinderShape(length=dims[0], radius=dims[1], pose=pose)  # CYLINDER_HEIGHT=0, CYLINDER_RADIUS=1


def _operation(at: _At) -> str:
    v = at.value
    if v is None:
        return "add"
    if isinstance(v, str) and v.strip().lower() in _OPERATIONS.values():
        return v.strip().lower()
    if isinstance(v, int) and not isinstance(v, bool) and v in _OPERATIONS:
        return _OPERATIONS[v]
    raise at.error(
        f"unknown operation {short_repr(v)} (moveit_msgs/CollisionObject: 0 add, 1 remove, 2 append, 3 move)"
    )


def _collision_object(at: _At, frames: _Frames) -> CollisionObject | None:
    """A CollisionObject (operation ADD) as twin's object; None when it has no shapes."""
    at.mapping(known=_OBJECT_KEYS)
    name = at["id"].text()
    if not name:
        raise at["id"].error("every collision object needs an id")
    op = _operation(at["operation"])
    if op != "add":
        raise at["operation"].error(
            f"operation {op!r} is not supported: a scene file must ADD its objects (operation 0 or absent)"
        )
    for key in ("meshes", "planes"):
        if not at[key].empty():
            raise at[key].error(f"{key} are not supported (allowed: box, sphere, cylinder primitives)")
    if not at["subframe_poses"].empty():
        log.warning("%s: subframes ignored (twin's goals name robot links only)", at["subframe_poses"])
    prims, poses = at["primitives"].items(), at["primitive_poses"].items()
    if len(prims) != len(poses):
        raise at["primitive_poses"].error(f"{len(poses)} poses for {len(prims)} primitives (one pose each)")
    if not prims:
        log.warning("%s: collision object %r has no shapes: skipped", at, name)
        return None
    T_obj = frames.pose(at["header"]["frame_id"]) @ _pose(at["pose"])
    shapes = [_primitive(p, T_obj @ _pose(pp)) for p, pp in zip(prims, poses, strict=True)]
    return CollisionObject(name=name, primitives=shapes)


def _reject_attached(state: _At) -> None:
    if not state["attached_collision_objects"].empty():
        raise state["attached_collision_objects"].error(
            "attached collision objects are not supported (a held object changes what collides)"
        )
    mdof = state["multi_dof_joint_state"]
    if not mdof["joint_names"].empty():
        raise mdof.error("multi-DOF joints are not supported (twin's arm stands on a fixed base)")


def _world(scene: _At, frames: _Frames, root: str) -> WorldSpec:
    scene.mapping(known=_SCENE_KEYS)
    world = scene["world"]
    world.mapping()
    octomap = world["octomap"]["octomap"]
    if not octomap["data"].empty():
        raise octomap["data"].error("an octomap is not supported (allowed: box, sphere, cylinder primitives)")
    for key, field, default in (("link_padding", "padding", 0.0), ("link_scale", "scale", 1.0)):
        for item in scene[key].items():
            if item[field].number(default) != default:
                raise item[field].error(
                    f"{key} of link {item['link_name'].text()!r} is {item[field].value}: not supported "
                    f"(twin pads every link by its config's collision.padding_m; allowed: {default})"
                )
    objects: dict[str, CollisionObject] = {}
    for at in world["collision_objects"].items():
        obj = _collision_object(at, frames)
        if obj is None:
            continue
        if obj.name in objects:
            log.warning("%s: a second object %r replaces the first (MoveIt's ADD)", at, obj.name)
        objects[obj.name] = obj
    acm = scene["allowed_collision_matrix"]
    named = {n.text() for key in ("entry_names", "default_entry_names") for n in acm[key].items()}
    allowed = sorted(named & set(objects))
    if allowed:
        log.warning(
            "%s: entries for the objects %s ignored: twin checks every object against the whole robot", acm, allowed
        )
    # a MoveIt world is what perception or an operator put there: every box is an obstacle box to twin's
    # box-model planners (nmpc) as well as to the collision checks
    boxes = [o.name for o in objects.values() if len(o.primitives) == 1 and o.primitives[0].shape == "box"]
    return WorldSpec(frame=root, objects=list(objects.values()), perceived_boxes=boxes)


# ---- robot states and goals ----------------------------------------------------------------------
class _Robot:
    """The arm the problems are for: which joint names a file may use, the joints' limits, link poses."""

    def __init__(self, urdf: str, scene: PlanningScene, ignore: Iterable[str]):
        self.urdf = urdf
        self.scene = scene
        self.model = scene.model
        self.arm = list(self.model.arm_joints)
        self.others = set(self.model.gripper_joints)  # twin's own fingers: set by the gripper opening
        self.ignore = tuple(ignore)

    def joints(self, pairs: Sequence[tuple[_At, _At]], where: _At) -> dict[str, tuple[float, _At]]:
        """{arm joint: (value, its place)} of (name, value) pairs; twin's fingers and `ignore_joints` are
        dropped, a joint named twice or a joint of another robot is a ConfigError."""
        out: dict[str, tuple[float, _At]] = {}
        seen: set[str] = set()
        unknown = []
        for name_at, value_at in pairs:
            n = name_at.text()
            if n in seen:
                raise name_at.error(f"joint {n!r} is named twice")
            seen.add(n)
            if n in self.arm:
                out[n] = (value_at.number(), value_at)
            elif n not in self.others and not any(fnmatch.fnmatchcase(n, pat) for pat in self.ignore):
                unknown.append(n)
        if unknown:
            raise where.error(
                f"joints {unknown} are not joints of {self.urdf} (arm: {', '.join(self.arm)}): a request for "
                "another robot? (another model's gripper joints can be skipped: --ignore-joints, or ignore_joints=)"
            )
        return out

    def state(self, state: _At) -> dict[str, tuple[float, _At]]:
        """The arm joints a RobotState gives (perhaps only some: a diff)."""
        state.mapping()
        _reject_attached(state)
        js = state["joint_state"]
        js.mapping()
        names, values = js["name"].items(), js["position"].items()
        if len(names) != len(values):
            raise js.error(f"{len(names)} joint names with {len(values)} positions")
        return self.joints(list(zip(names, values, strict=True)), js)

    def vector(self, values: Mapping[str, tuple[float, _At]], where: _At, what: str) -> list[float]:
        """The arm's joint vector (its order) from {joint: (value, where)}, each within its URDF limits."""
        missing = [n for n in self.arm if n not in values]
        if missing:
            raise where.error(f"no {what} position for joints {missing} (all of {', '.join(self.arm)} are needed)")
        for n in self.arm:
            v, at = values[n]
            j = self.model.joints[n]
            if not j.lower - 1e-9 <= v <= j.upper + 1e-9:
                raise at.error(f"{n} = {v:g} is outside its limits [{j.lower:g}, {j.upper:g}] in {self.urdf}")
        return [values[n][0] for n in self.arm]


def _joint_goal(constraints: _At, robot: _Robot) -> JointGoalSpec:
    pairs, tolerance = [], 0.0
    for c in constraints.items():
        c.mapping()
        pairs.append((c["joint_name"], c["position"]))
        tolerance = max(tolerance, c["tolerance_above"].number(0.0), c["tolerance_below"].number(0.0))
    goal = robot.vector(robot.joints(pairs, constraints), constraints, "goal")
    if tolerance > _EXACT_JOINT_RAD:
        log.warning(
            "%s: tolerances up to %.3g rad: twin plans to the centre of the goal region (an exact joint goal)",
            constraints,
            tolerance,
        )
    return JointGoalSpec(joints=goal)


def _pose_goal(goal: _At, frames: _Frames, robot: _Robot, start: Sequence[float]) -> PoseGoalSpec:
    """A MoveIt pose goal (one sphere position constraint, at most one orientation constraint). A position
    goal carries the link's orientation at the start: planners that solve IK for it prefer that one."""
    pcs, ocs = goal["position_constraints"].items(), goal["orientation_constraints"].items()
    if len(pcs) != 1 or len(ocs) > 1:
        raise goal.error(
            f"{len(pcs)} position and {len(ocs)} orientation constraints: a Cartesian goal must be one position "
            "constraint (a sphere, as MoveIt writes pose goals) and at most one orientation constraint"
        )
    pc = pcs[0]
    pc.mapping()
    link = pc["link_name"].text()
    if link not in _GOAL_LINKS:
        raise pc["link_name"].error(f"goal link {link!r} is not supported (allowed: {', '.join(_GOAL_LINKS)})")
    if any(pc["target_point_offset"].vector("xyz")):
        raise pc["target_point_offset"].error("a target point offset is not supported (give the link's origin)")
    region = pc["constraint_region"]
    region.mapping()
    if not region["meshes"].empty():
        raise region["meshes"].error("a mesh goal region is not supported (allowed: one sphere)")
    prims, poses = region["primitives"].items(), region["primitive_poses"].items()
    if len(prims) != 1 or len(poses) != 1:
        raise region.error(f"{len(prims)} primitives with {len(poses)} poses: the goal region must be one sphere")
    prims[0].mapping()
    if _primitive_type(prims[0]["type"]) != "sphere":
        raise prims[0]["type"].error("the goal region must be a sphere (as MoveIt writes pose goals)")
    radius_at = prims[0]["dimensions"]
    radii = [d.number() for d in radius_at.items()]
    if len(radii) != 1 or radii[0] <= 0:
        raise radius_at.error(f"a sphere needs one positive dimension [radius], got {radii}")
    position = (frames.pose(pc["header"]["frame_id"]) @ _pose(poses[0]))[:3, 3]
    T = robot.scene.link_poses(np.asarray(start, dtype=float))[link]
    T[:3, 3] = position
    free = True
    if ocs:
        oc = ocs[0]
        oc.mapping()
        if oc["link_name"].text() != link:
            raise oc["link_name"].error(
                f"the orientation constraint must be for the same link as the position ({link!r})"
            )
        R = frames.pose(oc["header"]["frame_id"])[:3, :3] @ _rigid((0.0, 0.0, 0.0), oc["orientation"])[:3, :3]
        T[:3, :3] = R
        tol = [abs(oc[f"absolute_{a}_axis_tolerance"].number(0.0)) for a in "xyz"]
        free = min(tol) >= math.pi
        if not free and max(tol) > _EXACT_ORIENTATION_RAD:
            log.warning("%s: orientation tolerances %s rad: twin reaches the orientation exactly", oc, tol)
    r = radii[0]
    if r > _MAX_POSITION_TOLERANCE_M:
        log.warning("%s: a %.3g m goal sphere: twin reaches it within %.3g m", radius_at, r, _MAX_POSITION_TOLERANCE_M)
        r = _MAX_POSITION_TOLERANCE_M
    if free:
        return PoseGoalSpec(kind="position", pose=PoseSpec.of(T), frame=_GOAL_LINKS[link], position_tolerance_m=r)
    tolerance = r if r > _EXACT_POSITION_M else None
    return PoseGoalSpec(kind="pose", pose=PoseSpec.of(T), frame=_GOAL_LINKS[link], position_tolerance_m=tolerance)


def _goal(request: _At, robot: _Robot, frames: _Frames, start: Sequence[float]) -> JointGoalSpec | PoseGoalSpec:
    goals = request["goal_constraints"].items()
    if not goals:
        raise request["goal_constraints"].error("missing or empty: a motion plan request needs a goal")
    if len(goals) > 1:
        log.warning("%s: %d goal regions; the first is used", request["goal_constraints"], len(goals))
    goal = goals[0]
    goal.mapping()
    if not goal["visibility_constraints"].empty():
        raise goal["visibility_constraints"].error("visibility constraints are not supported")
    joints = goal["joint_constraints"]
    cartesian = not (goal["position_constraints"].empty() and goal["orientation_constraints"].empty())
    if joints.empty() and not cartesian:
        raise goal.error("an empty goal (give joint_constraints, or a position constraint)")
    if not joints.empty() and cartesian:
        raise goal.error("a goal of joint and Cartesian constraints together is not supported")
    return _pose_goal(goal, frames, robot, start) if cartesian else _joint_goal(joints, robot)


def _reject_path_constraints(request: _At) -> None:
    path = request["path_constraints"]
    path.mapping()
    for key in ("joint_constraints", "position_constraints", "orientation_constraints", "visibility_constraints"):
        if not path[key].empty():
            raise path[key].error("path constraints are not supported (twin plans unconstrained paths)")
    trajectory = request["trajectory_constraints"]
    trajectory.mapping()
    if not trajectory["constraints"].empty():
        raise trajectory["constraints"].error("trajectory constraints are not supported")


# ---- the set -------------------------------------------------------------------------------------
def _config_ref(config: str | Path) -> tuple[str, Path]:
    """(what `source.config` records, the config file): a shipped config by its name, so the set plans
    anywhere; another by its absolute path."""
    path = find_config(config).resolve()
    shipped = packaged_config(path.name)
    return (path.name if shipped is not None and shipped.resolve() == path else str(path)), path


@dataclass(frozen=True)
class MoveItRobot:
    """How a family of MoveIt files names and places the arm: config overrides that make twin's cell that
    arm (`robot.model=ur5`), the joints of its gripper to ignore, and where its `base_link` stands in the
    scenes' `world` frame (x, y, z, roll, pitch, yaw; None: at the origin)."""

    overrides: tuple[str, ...] = ()
    ignore_joints: tuple[str, ...] = ()
    base_link_in_world: tuple[float, float, float, float, float, float] | None = None


# MotionBenchMaker's robots (its URDFs: the scenes' `world` is the URDF root `offset_link`, and its
# `offset_joint` places `base_link`; ur5_spherized.urdf in vamp-planner's resources/ur5)
MOVEIT_ROBOTS: dict[str, MoveItRobot] = {
    "ur5": MoveItRobot(("robot.model=ur5",), ("robotiq_85_*",), (0.0, 0.0, 0.9144, 0.0, 0.0, 1.57)),
}


def problem_set_from_moveit(
    scene: Source,
    requests: Sequence[Source],
    *,
    config: str | Path = "robocup",
    name: str | None = None,
    time_limit_s: float | None = None,
    seed: int = 0,
    frames: FrameConvention = "ur_description",
    ignore_joints: Iterable[str] = (),
    robot: str | None = None,
) -> ProblemSet:
    """The problems of MoveIt motion plan requests in a MoveIt planning scene, for the robot of the twin
    `config` (a path or a shipped config's name; `twin compare` plans the set in that config's cell).

    `scene`, `requests`: YAML files of moveit_msgs/PlanningScene and MotionPlanRequest, or their parsed
    mappings. `name`: of the set and the prefix of problem ids `<name>#<i>` (default: the scene's `name`,
    else its file stem). `time_limit_s`: every problem's (default: each request's allowed_planning_time,
    1 s when 0). `seed`: every problem's. `frames`: what `base_link` means in the files (module docstring):
    ROS's ur_description (default) or twin's URDF. `ignore_joints`: names or glob patterns of joints the
    files may name besides the arm's (e.g. "robotiq_85_*", a gripper of another robot model). `robot`: a
    `MOVEIT_ROBOTS` name (MotionBenchMaker's "ur5"): its arm, gripper joints and base placement.

    Raises ConfigError (one line: file, key path, what is accepted) for anything it cannot read exactly.
    """
    _check_options(frames, time_limit_s, seed)
    if isinstance(requests, (str, Path, Mapping)):
        raise ConfigError("requests must be a list of MotionPlanRequest files or mappings")
    if not requests:
        raise ConfigError("no motion plan requests given (at least one MotionPlanRequest YAML is needed)")
    reader = _Reader(config, frames, ignore_joints, robot)
    scene_at = _read(scene, "scene")
    world, problems, set_name = reader.problems(scene, scene_at, requests, name, time_limit_s, seed)
    scene_ref = str(scene) if not isinstance(scene, Mapping) else "<scene>"
    return ProblemSet(
        name=set_name,
        description=(
            f"{len(problems)} MoveIt motion plan request(s) in the planning scene {scene_ref} "
            f"({len(world.objects)} objects; frames as in {frames})"
        ),
        source={
            **reader.source(),
            "moveit": {
                "scene": scene_ref,
                "requests": [
                    str(r) if not isinstance(r, Mapping) else f"<request {i}>" for i, r in enumerate(requests)
                ],
                "frames": frames,
                "robot_model_name": scene_at["robot_model_name"].text(),
            },
        },
        robot=reader.robot_spec,
        world=world,
        problems=problems,
    )


def problem_set_from_moveit_dir(
    directory: str | Path,
    *,
    config: str | Path = "robocup",
    name: str | None = None,
    time_limit_s: float | None = None,
    seed: int = 0,
    frames: FrameConvention = "ur_description",
    ignore_joints: Iterable[str] = (),
    robot: str | None = None,
) -> ProblemSet:
    """A directory of MotionBenchMaker pairs (`sceneNNNN.yaml` with `requestNNNN.yaml`, a scene per
    request) as one problem set of version 2: problem `<name>#NNNN` in its own scene's world. The options
    are `problem_set_from_moveit`'s; `name` defaults to the directory's name. A scene without its request
    (or the other way round) is a one-line error naming it."""
    _check_options(frames, time_limit_s, seed)
    root = Path(directory)
    if not root.is_dir():
        raise ConfigError(f"{root} is not a directory of MotionBenchMaker scene/request pairs")
    scenes = {m.group(1): p for p in root.glob("scene*.yaml") if (m := re.fullmatch(r"scene(\d+)\.yaml", p.name))}
    requests = {m.group(1): p for p in root.glob("request*.yaml") if (m := re.fullmatch(r"request(\d+)\.yaml", p.name))}
    if not scenes:
        raise ConfigError(
            f"{root}: no sceneNNNN.yaml files (MotionBenchMaker's layout: sceneNNNN.yaml + requestNNNN.yaml)"
        )
    lonely = sorted(set(scenes) ^ set(requests))
    if lonely:
        k = lonely[0]
        have, missing = (
            (f"scene{k}.yaml", f"request{k}.yaml") if k in scenes else (f"request{k}.yaml", f"scene{k}.yaml")
        )
        raise ConfigError(f"{root}: {have} has no {missing}")
    set_name = name or root.name
    reader = _Reader(config, frames, ignore_joints, robot)
    problems: list[Problem] = []
    n_objects = 0
    for k in sorted(scenes, key=int):
        scene_at = _read(scenes[k], "scene")
        world, found, _ = reader.problems(scenes[k], scene_at, [requests[k]], set_name, time_limit_s, seed)
        n_objects += len(world.objects)
        problems += [p.model_copy(update={"id": f"{set_name}#{k}", "world": world}) for p in found]
    return ProblemSet(
        version=2,
        name=set_name,
        description=(
            f"{len(problems)} MotionBenchMaker problems from {root}, each in its own scene "
            f"({n_objects / len(problems):.1f} objects on average; frames as in {frames})"
        ),
        source={**reader.source(), "moveit": {"directory": str(root), "frames": frames, "robot": robot}},
        robot=reader.robot_spec,
        problems=problems,
    )


def _check_options(frames: str, time_limit_s: float | None, seed: int) -> None:
    if frames not in ("ur_description", "twin"):
        raise ConfigError(f"frames must be 'ur_description' or 'twin', got {frames!r}")
    if time_limit_s is not None and not (math.isfinite(time_limit_s) and time_limit_s > 0):
        raise ConfigError(f"time_limit_s must be a positive number of seconds, got {time_limit_s}")
    if seed < 0:
        raise ConfigError(f"seed must be >= 0, got {seed}")


class _Reader:
    """The robot cell MoveIt files are read for (the config, a `MOVEIT_ROBOTS` preset), and their requests
    as problems in it."""

    def __init__(self, config: str | Path, frames: FrameConvention, ignore_joints: Iterable[str], robot: str | None):
        from twin.collision import PlanningScene  # lazy: fcl

        preset = MOVEIT_ROBOTS.get(robot) if robot is not None else MoveItRobot()
        if preset is None:
            raise ConfigError(f"unknown MoveIt robot {robot!r}; known: {', '.join(MOVEIT_ROBOTS)}")
        self.frames, self.preset = frames, preset
        self.config_ref, config_path = _config_ref(config)
        settings = load_config(config_path, list(preset.overrides))
        cell = PlanningScene.from_settings(settings)  # the robot's collision model: what RobotSpec states
        self.robot = _Robot(settings.robot.urdf, cell, (*ignore_joints, *preset.ignore_joints))
        self.robot_spec = robot_spec(cell, settings)
        pose = preset.base_link_in_world
        self.world_base_link = None if pose is None else pose_from_xyz_rpy(pose[:3], pose[3:])

    def source(self) -> dict[str, Any]:
        out: dict[str, Any] = {"config": self.config_ref}
        if self.preset.overrides:
            out["overrides"] = list(self.preset.overrides)
        return out

    def problems(
        self,
        scene: Source,
        scene_at: _At,
        requests: Sequence[Source],
        name: str | None,
        time_limit_s: float | None,
        seed: int,
    ) -> tuple[WorldSpec, list[Problem], str]:
        """(the scene's world, its requests as problems `<name>#<i>`, the set's name)."""
        scene_at.mapping()
        frame_tree = _Frames(scene_at, self.frames, self.world_base_link)
        world = _world(scene_at, frame_tree, self.robot.model.root)
        default_start = self.robot.state(scene_at["robot_state"])
        set_name = (
            name or scene_at["name"].text().strip() or (Path(scene).stem if not isinstance(scene, Mapping) else "")
        )
        set_name = set_name or "moveit"
        problems = []
        for i, src in enumerate(requests):
            request = _read(src, f"request {i}")
            request.mapping(known=_REQUEST_KEYS)
            _reject_path_constraints(request)
            start = self.robot.vector(
                {**default_start, **self.robot.state(request["start_state"])}, request["start_state"], "start"
            )
            allowed = request["allowed_planning_time"].number(0.0)
            if allowed < 0:
                raise request["allowed_planning_time"].error(f"must be >= 0 s, got {allowed}")
            problems.append(
                Problem(
                    id=f"{set_name}#{i}",
                    start=start,
                    goal=_goal(request, self.robot, frame_tree, start),
                    time_limit_s=time_limit_s or allowed or 1.0,
                    seed=seed,
                )
            )
        return world, problems, set_name
