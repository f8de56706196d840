"""Validated configuration: YAML files loaded into typed pydantic models.

A file may name another with `extends: other.yaml` (a path relative to the file); the two are merged
key by key, the extending file winning. `--set a.b=value` overrides (parsed as YAML scalars) apply last.
Unknown keys are rejected with the file and the dotted path of the key.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from twin.errors import ConfigError

__all__ = [
    "PROJECT_ROOT",
    "ArucoSettings",
    "CameraSettings",
    "CollisionSettings",
    "DepthNoiseSettings",
    "DetectorBlock",
    "FixtureSettings",
    "GraspEntry",
    "GripperSettings",
    "IcpSettings",
    "ObjectSettings",
    "ObjectSpec",
    "PerceptionSettings",
    "PlannerBlock",
    "RobocupPerceptionSettings",
    "RobocupTaskSettings",
    "RobotSettings",
    "Settings",
    "TaskSettings",
    "WarehousePerceptionSettings",
    "WarehouseTaskSettings",
    "WorldSettings",
    "apply_override",
    "load_config",
    "one_line",
    "read_yaml",
    "settings_from_dict",
    "short_repr",
]

PROJECT_ROOT = Path(__file__).resolve().parent.parent

Vec3 = tuple[float, float, float]
Q6 = tuple[float, float, float, float, float, float]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class RobotSettings(_Model):
    """The arm: its URDF, home posture and joint limits (SPEC: pi rad/s, +-2pi, elbow +-pi)."""

    urdf: str = "urdf/ur5e.urdf"
    home: Q6 = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)
    max_joint_vel: float = Field(math.pi, gt=0)
    max_joint_acc: float = Field(8.0, gt=0)
    max_joint_jerk: float = Field(100.0, gt=0)
    position_gain: float = Field(0.3, gt=0, le=1)
    max_joint_force: Q6 = (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)


class GripperSettings(_Model):
    """Parallel gripper: 0..85 mm stroke, 20..235 N grip force (Robotiq 2F-85)."""

    max_opening_m: float = Field(0.085, gt=0, le=0.085)
    force_n: float = Field(100.0, ge=20, le=235)
    speed_m_s: float = Field(0.1, gt=0, le=0.15)
    finger_friction: float = Field(1.5, gt=0)
    # "Object detected", as the 2F-85 reports it: the fingers stopped closing above this opening. Closed on
    # nothing, the force-limited pads meet at 0 mm (the joint limits) and contact softness leaves well under
    # 1 mm; the thinnest object (the marker) is 21 mm. 5 mm sits clear of both.
    object_min_opening_m: float = Field(0.005, gt=0, le=0.02)
    # How much wider than the width the task expects between the fingers (from the perceived class and
    # orientation) the stopped opening may be: a box squeezed a few degrees off its face (spam 5 deg off:
    # +9 mm) and template vs real size. Wider than that, something else (or more) is between the fingers.
    width_over_tolerance_m: float = Field(0.012, gt=0, le=0.05)
    # How much narrower: the pads sink into what they squeeze. On a rigid object a real 2F-85 sinks < 1 mm;
    # PyBullet's soft contacts let the 100 N pads sink 0.2-2 mm into the cans, cubes and spam, and up to
    # 13 mm into the 15 g marker (which tilts and is pinched), which is still a grasp that holds.
    width_under_tolerance_m: float = Field(0.015, gt=0, le=0.05)
    # Slip / drop: the opening fell this far below the one sensed at the grasp (and below the narrowest the
    # object can be held at). An object that leaves lets the fingers close to 0 within a fraction of a
    # second; one that stays moves them by about a millimetre under the lift's and transfer's accelerations.
    slip_tolerance_m: float = Field(0.008, gt=0, le=0.02)


class FixtureSettings(_Model):
    """A static body of the cell, loaded from a URDF at a pose in the world (= robot base) frame."""

    name: str
    urdf: str
    position: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)
    known: bool = True  # in the planners' scene from the start; false: the robot must perceive it


class ObjectSpec(_Model):
    """`count` objects of one class (and colour, for cubes) to scatter in the spawn region."""

    cls: Literal["bottle", "can", "spam", "cube", "marker", "warehouse_cube", "obstacle"] = Field(alias="class")
    color: str | None = None
    count: int = Field(1, ge=0, le=50)
    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)


class ObjectSettings(_Model):
    """Where and how objects are placed: seeded, never overlapping, upright or lying."""

    region_x: tuple[float, float] = (-0.65, -0.30)
    region_y: tuple[float, float] = (-0.30, 0.30)
    min_gap_m: float = Field(0.03, ge=0)
    lying_probability: float = Field(0.0, ge=0, le=1)
    random_yaw: bool = True
    items: list[ObjectSpec] = Field(default_factory=list)

    @field_validator("region_x", "region_y")
    @classmethod
    def _ordered(cls, v: tuple[float, float]) -> tuple[float, float]:
        if v[0] >= v[1]:
            raise ValueError(f"range must be [min, max] with min < max, got {list(v)}")
        return v


class WorldSettings(_Model):
    """The PyBullet world: rate, gravity, fixtures and objects.

    The world frame is the robot base frame (UR DH base: with the shoulder pan at 0 the arm reaches
    towards -x), so the table and the work area lie at negative x, in front of the arm's home posture.
    """

    physics_hz: float = Field(240.0, gt=0)
    gravity: float = -9.81
    gui: bool = False
    fixtures: list[FixtureSettings] = Field(
        default_factory=lambda: [
            FixtureSettings(name="table", urdf="urdf/table.urdf", position=(-0.30, 0.0, 0.0)),
        ]
    )
    objects: ObjectSettings = Field(default_factory=ObjectSettings)

    @model_validator(mode="after")
    def _unique_names(self) -> "WorldSettings":
        names = [f.name for f in self.fixtures]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"fixture names must be unique, repeated: {sorted(dup)}")
        return self


class ArucoSettings(_Model):
    """The marker on the robot base plate (dictionary name from cv2.aruco, e.g. DICT_4X4_50)."""

    dictionary: str = "DICT_4X4_50"
    id: int = Field(0, ge=0)
    size_m: float = Field(0.10, gt=0)
    # camera-to-base estimation: "pnp" is the seed's solvePnP(IPPE_SQUARE) on the corners; "pnp+plane"
    # takes the marker's plane from the depth image (the table), which removes the tilt/range error of a
    # small marker seen far and obliquely (~3 cm at the warehouse camera); `refine_grid` adds the marker's
    # interior grid corners to PnP when its cells are at least 5 px
    method: Literal["pnp+plane", "pnp"] = "pnp+plane"
    refine_grid: bool = True


class DepthNoiseSettings(_Model):
    """D435i-like depth noise: RMS = z^2 * subpixel / (focal_px * baseline_m), plus dropouts.

    Defaults give ~1 mm at 0.5 m, ~4 mm at 1 m, ~15 mm at 2 m (Intel's model for the D435i). Dropouts
    are invalid pixels (depth 0): a random fraction everywhere and a larger one at depth edges, where a
    stereo camera loses the match. `rgb_noise_std` is Gaussian pixel noise on the colour image (0..255).
    """

    enabled: bool = True
    subpixel: float = Field(0.08, ge=0)
    baseline_m: float = Field(0.05, gt=0)
    focal_px: float = Field(424.0, gt=0)
    dropout_fraction: float = Field(0.002, ge=0, le=1)
    edge_dropout_fraction: float = Field(0.3, ge=0, le=1)
    edge_threshold_m: float = Field(0.03, gt=0)
    min_range_m: float = Field(0.17, ge=0)
    max_range_m: float = Field(10.0, gt=0)
    depth_unit_m: float = Field(0.001, ge=0)
    rgb_noise_std: float = Field(2.0, ge=0)


class CameraSettings(_Model):
    """RGB-D camera: D435i-like intrinsics at 640x480.

    A fixed mount looks from `position` at `target` (base frame); a wrist mount sits at `wrist_offset_m`
    in the tool0 frame and looks along tool0's z axis.
    """

    mount: Literal["fixed", "wrist"] = "fixed"
    width: int = Field(640, ge=16, le=1920)
    height: int = Field(480, ge=16, le=1080)
    fx: float = Field(612.0, gt=0)
    fy: float = Field(611.0, gt=0)
    near_m: float = Field(0.05, gt=0)
    far_m: float = Field(4.0, gt=0)
    position: Vec3 = (-1.25, 0.0, 0.55)
    target: Vec3 = (-0.30, 0.0, 0.0)
    wrist_offset_m: Vec3 = (0.0, 0.075, 0.02)
    noise: DepthNoiseSettings = Field(default_factory=DepthNoiseSettings)
    # wrist mount: joint angles where the camera looks straight down from ~0.72 m above the table centre
    # (image x along base +y), and the settling pause before a frame is taken there (seed 002: 3 s)
    capture_pose: Q6 = (-0.2518, -1.2366, 0.4574, -0.7916, -1.5708, -0.2518)
    settle_s: float = Field(3.0, ge=0)
    # wrist mount: joint angles where the camera sees the base marker for `twin calibrate` (None: capture_pose)
    calibration_pose: Q6 | None = None

    @model_validator(mode="after")
    def _near_far(self) -> "CameraSettings":
        if self.near_m >= self.far_m:
            raise ValueError(f"near_m ({self.near_m}) must be less than far_m ({self.far_m})")
        return self


class CollisionSettings(_Model):
    """FCL planning scene options."""

    padding_m: float = Field(0.0, ge=0, le=0.1)
    check_resolution_rad: float = Field(0.01, gt=0, le=0.1)
    check_resolution_m: float = Field(0.01, gt=0, le=0.05)


class PlannerBlock(_Model):
    """A plugin chosen by name with its own parameters, validated by that plugin's model."""

    name: str
    params: dict[str, Any] = Field(default_factory=dict)
    retimer: str | None = None
    retimer_params: dict[str, Any] = Field(default_factory=dict)


class DetectorBlock(_Model):
    """A detector plugin chosen by name, with its own parameters (validated by the plugin's model)."""

    name: str = "geometric"
    params: dict[str, Any] = Field(default_factory=dict)


class WarehousePerceptionSettings(_Model):
    """Seeds 000/001 `cube_detector`: depth thresholds, RANSAC plane, DBSCAN, labels by mean colour.

    `voxel_m` > 0 downsamples before DBSCAN (full-resolution DBSCAN takes seconds); `dbscan_min_points`
    is the full-resolution value and is scaled by the downsampling ratio. Point counts (obstacle, cubes)
    are counted in the full-resolution cloud. `roi_min`/`roi_max` (base frame) drop points of the robot
    (its base at the origin, the gripper hanging above the table) and anything off the table; the work
    area lies at negative x. `centroid`: "resting" takes x, y from the cluster's footprint (the smallest
    rectangle around it seen from above) and z half way between its top face and the table (unbiased for
    boxes on the table); "mean" is the seed's plain mean of the visible points (~2 cm off: towards the
    camera and upwards, as only the top and front faces are seen).
    """

    min_depth_m: float = Field(0.25, ge=0)
    max_depth_m: float = Field(1.5, gt=0)
    plane_threshold_m: float = Field(0.02, gt=0)
    plane_iterations: int = Field(500, ge=10)
    dbscan_eps_m: float = Field(0.015, gt=0)
    dbscan_min_points: int = Field(40, ge=1)
    voxel_m: float = Field(0.004, ge=0)
    obstacle_min_points: int = Field(10000, ge=1)
    obstacle_color: str = "blue"
    labels: list[str] = Field(default_factory=lambda: ["black", "red", "blue", "green"])
    cube_min_points: int = Field(150, ge=1)
    cube_max_extent_m: float = Field(0.09, gt=0)
    roi_min: Vec3 = (-1.0, -0.8, -0.05)
    roi_max: Vec3 = (-0.10, 0.8, 0.30)
    box_extension_y_m: float = Field(0.5, ge=0)
    centroid: Literal["resting", "mean"] = "resting"


class IcpSettings(_Model):
    """Seed 002 ICP template refinement (MATLAB pcregistericp parameters)."""

    template_points: int = Field(2048, ge=100)
    denoise_neighbors: int = Field(10, ge=1)
    denoise_std_ratio: float = Field(1.5, gt=0)
    voxel_m: float = Field(0.003, ge=0)
    voxel_above_points: int = Field(500, ge=1)
    max_iterations: int = Field(60, ge=1)
    tolerance: tuple[float, float] = (1e-4, 1e-6)  # translation (m), rotation (rad) change to stop
    inlier_ratio: float = Field(0.7, gt=0, le=1)
    min_points: int = Field(20, ge=3)
    accept_rmse_m: float = Field(0.025, gt=0)


class GraspEntry(_Model):
    """One row of the grasp lookup: tcp height above the table (m) and gripper opening before closing (m)."""

    z_grasp_m: float = Field(ge=0)
    w_grip_m: float = Field(gt=0, le=0.085)


def _default_grasp_table() -> dict[str, GraspEntry]:
    rows = {
        "bottle_vertical": (0.150, 0.085), "bottle_horizontal": (0.034, 0.085),
        "can_vertical": (0.070, 0.085), "can_horizontal": (0.033, 0.085),
        "spam_vertical": (0.050, 0.085), "spam_horizontal": (0.035, 0.085),
        "cube_vertical": (0.0375, 0.085), "cube_horizontal": (0.0375, 0.085),
        "marker_vertical": (0.090, 0.040), "marker_horizontal": (0.016, 0.040),
    }
    return {k: GraspEntry(z_grasp_m=z, w_grip_m=w) for k, (z, w) in rows.items()}


class RobocupPerceptionSettings(_Model):
    """Seed 002 pose estimation: table removal, PCA orientation rules, ICP, the grasp lookup.

    PCA rules in order: alpha1 < alpha1_vertical_deg -> vertical; e > elongation_horizontal and alpha1 >
    alpha1_horizontal_deg -> horizontal; alpha3 < alpha3_vertical_deg -> vertical; else horizontal.
    Classes in `force_vertical` skip the rules (seed: spam). `height_check` (not in the seed) then compares
    the object's top height above the table with its upright and lying heights and takes the nearer one
    when they differ by more than `height_check_min_diff_m` (this fixes the seed's lying-can failure),
    and calls a class whose two heights are alike (the cube: the same shape either way) vertical.
    `grasp` keys are `<class>_<vertical|horizontal>`; entries given in a config replace the defaults key
    by key.
    """

    min_depth_m: float = Field(0.20, ge=0)
    max_depth_m: float = Field(1.5, gt=0)
    table_threshold_m: float = Field(0.008, gt=0)
    alpha1_vertical_deg: float = Field(30.0, gt=0, lt=90)
    elongation_horizontal: float = Field(3.0, gt=1)
    alpha1_horizontal_deg: float = Field(45.0, gt=0, lt=90)
    alpha3_vertical_deg: float = Field(30.0, gt=0, lt=90)
    force_vertical: list[str] = Field(default_factory=lambda: ["spam"])
    height_check: bool = True
    height_check_min_diff_m: float = Field(0.015, ge=0)
    icp: IcpSettings = Field(default_factory=IcpSettings)
    grasp: dict[str, GraspEntry] = Field(default_factory=_default_grasp_table)

    @field_validator("grasp", mode="before")
    @classmethod
    def _merge_grasp(cls, v: Any) -> Any:
        if not isinstance(v, dict):
            return v
        merged: dict[str, Any] = dict(_default_grasp_table())
        merged.update(v)
        for key in merged:
            c, _, o = key.rpartition("_")
            if not c or o not in ("vertical", "horizontal"):
                raise ValueError(f"grasp key {key!r} must look like <class>_vertical or <class>_horizontal")
        return merged


class PerceptionSettings(_Model):
    """What `twin perceive` runs: the warehouse pipeline (seeds 000/001) or the RoboCup one (seed 002).

    `extrinsics`: how the camera-to-base transform is obtained; "auto" uses the ArUco marker for a fixed
    camera and forward kinematics of the measured joints plus `camera.wrist_offset_m` for a wrist camera.
    """

    pipeline: Literal["robocup", "warehouse"] = "robocup"
    extrinsics: Literal["auto", "aruco", "kinematics"] = "auto"
    detector: DetectorBlock = Field(default_factory=DetectorBlock)
    warehouse: WarehousePerceptionSettings = Field(default_factory=WarehousePerceptionSettings)
    robocup: RobocupPerceptionSettings = Field(default_factory=RobocupPerceptionSettings)


class RobocupTaskSettings(_Model):
    """The seed-002 state machine: where each class goes and how the grasp is approached."""

    # class (or class_colour, e.g. cube_red) -> the fixture name of its bin; the seed's log: spam -> green,
    # red cube -> blue. Unlisted classes go to `default_bin`.
    bins: dict[str, str] = Field(
        default_factory=lambda: {"bottle": "bin_green", "can": "bin_green", "marker": "bin_green", "spam": "bin_green", "cube": "bin_blue"}
    )
    default_bin: str = "bin_green"
    hover_m: float = Field(0.20, gt=0, le=0.5)  # pre-grasp hover above the grasp point
    place_clearance_m: float = Field(0.10, ge=0, le=0.5)  # object bottom above the bin walls when released
    retries: int = Field(1, ge=0, le=5)  # a failed object is retried this often from a fresh perception
    # The run captures at most (retries + 2) x (the most objects seen on the table in one capture) + 3 frames,
    # and never more than this: a detector that sees phantom objects cannot keep the robot busy for ever.
    max_captures: int = Field(40, ge=1, le=500)
    # Per class, a gentler grip than gripper.force_n / speed_m_s, within the 2F-85's 20-235 N and 20-150 mm/s.
    # The 15 g marker, hit at 100 mm/s and squeezed at 100 N, squirts out of PyBullet's soft contacts (the
    # pads sink through it); closed at 20 mm/s with 20 N it is held at about 19 of its 21 mm.
    grip_force_n: dict[str, Annotated[float, Field(ge=20.0, le=235.0)]] = Field(default_factory=lambda: {"marker": 20.0})
    grip_speed_m_s: dict[str, Annotated[float, Field(ge=0.02, le=0.15)]] = Field(default_factory=lambda: {"marker": 0.02})


class WarehouseTaskSettings(_Model):
    """The seed-000/001 task: fixed drop location per colour on the robot's side of the obstacle."""

    drop_zones: dict[str, Vec3] = Field(
        default_factory=lambda: {
            "black": (-0.28, -0.30, 0.0),
            "red": (-0.28, -0.16, 0.0),
            "blue": (-0.28, 0.18, 0.0),
            "green": (-0.28, 0.32, 0.0),
        }
    )
    drop_radius_m: float = Field(0.06, gt=0)  # success: the cube rests within this xy distance of its zone
    hover_m: float = Field(0.25, gt=0, le=0.5)  # above the obstacle top: MoveJ there is a straight joint path
    release_height_m: float = Field(0.02, ge=0, le=0.5)  # cube bottom above the table when released
    retries: int = Field(1, ge=0, le=5)


class TaskSettings(_Model):
    """Which reference system `twin run` runs, and its parameters."""

    kind: Literal["robocup", "warehouse"] = "robocup"
    robocup: RobocupTaskSettings = Field(default_factory=RobocupTaskSettings)
    warehouse: WarehouseTaskSettings = Field(default_factory=WarehouseTaskSettings)
    settle_s: float = Field(0.5, ge=0, le=5)  # pause after gripper actions (seed 002: 0.5-0.8 s)
    max_sim_time_s: float = Field(900.0, gt=0)  # a run stops (objects left are failed) after this
    # the transfer ends above the place point and the place move finishes it: it needs the position within
    # this distance (the seed-000 NMPC stops within 3 cm), the orientation is free
    transfer_tolerance_m: float = Field(0.03, gt=0, le=0.1)


class Settings(_Model):
    """Everything a run needs, validated on load."""

    name: str = "twin"
    seed: int = 0
    robot: RobotSettings = Field(default_factory=RobotSettings)
    gripper: GripperSettings = Field(default_factory=GripperSettings)
    world: WorldSettings = Field(default_factory=WorldSettings)
    aruco: ArucoSettings = Field(default_factory=ArucoSettings)
    camera: CameraSettings = Field(default_factory=CameraSettings)
    collision: CollisionSettings = Field(default_factory=CollisionSettings)
    planners: dict[str, PlannerBlock] = Field(default_factory=dict)
    task: TaskSettings = Field(default_factory=TaskSettings)
    perception: PerceptionSettings = Field(default_factory=PerceptionSettings)

    def resolve(self, path: str) -> Path:
        """A path from the config, relative paths taken from the project root."""
        p = Path(path)
        return p if p.is_absolute() else PROJECT_ROOT / p


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


# A config is a handful of levels deep (perception.robocup.grasp.<key>.z_grasp_m; a detector's exclude boxes)
# and a few hundred values; far beyond that it is a mistake or an attack (YAML aliases can make a small
# file expand to millions of nodes, and pydantic would walk every one)
_MAX_DEPTH = 32
_MAX_NODES = 100_000
_MAX_INT = 2**63 - 1  # beyond int64 a seed or an id breaks numpy, PyBullet or OpenCV instead of failing here


def one_line(text: object, limit: int = 300) -> str:
    """`text` on one line (every line break and run of white space becomes one space), cut to `limit`
    characters: error messages quote user input, and a user mistake must print as ONE line."""
    out = " ".join(str(text).split())
    return out if len(out) <= limit else out[: limit - 3] + "..."


def short_repr(value: object, limit: int = 60) -> str:
    """repr of a user's value for an error message: one line, at most `limit` characters."""
    try:
        r = repr(value)
    except Exception:  # noqa: BLE001 - a message must never fail
        r = f"<{type(value).__name__}>"
    return one_line(r, limit)


def _dotted(loc: Iterable[object]) -> str:
    """'a.b.0.c' for a path of keys; a key that is not a plain printable word is shown as its repr."""
    parts = []
    for p in loc:
        text = str(p)
        parts.append(text if text and text.isprintable() and not any(c.isspace() for c in text) else short_repr(p, 40))
    return ".".join(parts)


def _check_tree(data: Any, source: str) -> None:
    """Reject what the models would accept but nothing downstream can use: NaN/inf, integers beyond int64,
    keys that are not text (a validator would meet an int where it expects a name), nesting deeper than
    _MAX_DEPTH, more than _MAX_NODES values (aliases counted every time they are used)."""
    nodes = 0
    stack: list[tuple[Any, tuple[object, ...]]] = [(data, ())]
    while stack:
        node, path = stack.pop()
        nodes += 1
        if nodes > _MAX_NODES:
            raise ConfigError(f"{source}: the config has more than {_MAX_NODES} values (YAML aliases count each time they are used)")
        if len(path) > _MAX_DEPTH:
            raise ConfigError(f"{source}: {_dotted(path[:_MAX_DEPTH])}...: nested deeper than {_MAX_DEPTH} levels")
        if isinstance(node, bool):
            continue
        if isinstance(node, float) and not math.isfinite(node):
            raise ConfigError(f"{source}: {_dotted(path) or '(top level)'}: must be a finite number, got {node}")
        if isinstance(node, int) and abs(node) > _MAX_INT:
            raise ConfigError(f"{source}: {_dotted(path) or '(top level)'}: integer {short_repr(node, 30)} is too large (at most 2**63-1)")
        if isinstance(node, dict):
            for k in node:
                if not isinstance(k, str):  # every mapping of a config is keyed by names (YAML allows `1:`, `null:`)
                    raise ConfigError(
                        f"{source}: {_dotted(path) or '(top level)'}: key {short_repr(k, 30)} must be a name (text), "
                        f"got {type(k).__name__}"
                    )
            stack.extend((v, path + (k,)) for k, v in node.items())
        elif isinstance(node, (list, tuple)):
            stack.extend((v, path + (i,)) for i, v in enumerate(node))


def _yaml_error(path: Path, e: yaml.YAMLError, text: str) -> ConfigError:
    """One line for a YAML error: file, line and column, PyYAML's problem (its message spans several lines)."""
    mark = getattr(e, "problem_mark", None) or getattr(e, "context_mark", None)
    line = col = None
    if mark is not None:
        line, col = mark.line + 1, mark.column + 1
    problem = getattr(e, "problem", None)
    if isinstance(e, yaml.reader.ReaderError):  # a control character; no mark, a position in the text
        pos = int(e.position)
        line, col = text.count("\n", 0, pos) + 1, pos - (text.rfind("\n", 0, pos) + 1) + 1
        problem = f"unacceptable character #x{e.character:04x} ({e.reason})" if isinstance(e.character, int) else e.reason
    context = getattr(e, "context", None)
    what = f"{problem} ({context})" if problem and context else problem or context or e
    where = f" at line {line}, column {col}" if line is not None else ""
    return ConfigError(f"{path}: not valid YAML{where}: {one_line(what)}")


def _read_text(path: Path) -> str:
    """The file as text: UTF-8 (a BOM is allowed); a binary or otherwise encoded file is a ConfigError."""
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ConfigError(f"cannot read config {path}: {e.strerror or e}") from None
    if b"\x00" in raw:
        raise ConfigError(f"{path}: a binary file (it contains NUL bytes), not a YAML config")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not UTF-8 text (byte 0x{raw[e.start]:02x} at offset {e.start}); save it as UTF-8") from None


def read_yaml(path: str | Path, seen: tuple[Path, ...] = ()) -> dict[str, Any]:
    """The mapping of a YAML config with its `extends` chain merged in (not validated yet).

    Every problem with the file itself (missing, unreadable, binary, not UTF-8, not YAML, empty, not a
    mapping, an `extends` cycle) is a ConfigError with a one-line message naming the file.
    """
    try:
        path = Path(path).resolve()
        is_file = path.is_file()
    except (OSError, ValueError) as e:  # e.g. an embedded NUL byte or a name too long for the system
        raise ConfigError(f"config file path {short_repr(str(path), 200)} is not usable: {one_line(e)}") from None
    if path in seen:
        raise ConfigError(f"{path}: `extends` forms a cycle through {' -> '.join(map(str, seen))}")
    if not is_file:
        raise ConfigError(f"config file not found: {path}")
    text = _read_text(path)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise _yaml_error(path, e, text) from None
    except RecursionError:
        raise ConfigError(f"{path}: nested too deeply for the YAML parser") from None
    if data is None:
        raise ConfigError(f"{path}: the config is empty")
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a mapping of keys, got {type(data).__name__}")
    _check_tree(data, str(path))
    parent = data.pop("extends", None)
    if parent is not None:
        if not isinstance(parent, str) or not parent:
            raise ConfigError(f"{path}: `extends` must be a file path, got {short_repr(parent)}")
        data = _merge(read_yaml(path.parent / parent, seen + (path,)), data)
    return data


def apply_override(data: dict[str, Any], override: str) -> None:
    """Apply one `key.path=value` override in place; the value is parsed as a YAML scalar (or flow
    collection), so `--set seed=3` gives an int and `--set x=[1,2]` a list; unparsable text stays a string."""
    if "=" not in override:
        raise ConfigError(f"override {short_repr(override)} must look like key.path=value")
    key, raw = override.split("=", 1)
    parts = [p.strip() for p in key.strip().split(".")]
    if not all(parts):
        raise ConfigError(f"override {short_repr(override)}: empty key in dotted path {short_repr(key)}")
    try:
        value = yaml.safe_load(raw)
    except yaml.YAMLError:
        value = raw
    except RecursionError:
        raise ConfigError(f"override {short_repr(override)}: the value is nested too deeply") from None
    node = data
    for i, p in enumerate(parts[:-1]):
        nxt = node.get(p)
        if nxt is None:
            nxt = node[p] = {}
        if not isinstance(nxt, dict):
            raise ConfigError(f"override {short_repr(override)}: {'.'.join(parts[: i + 1])!r} is a value, not a section")
        node = nxt
    node[parts[-1]] = value


def _format_validation(source: str, err: ValidationError) -> str:
    """One line for a pydantic error: the dotted path of the first bad key and what is wrong with it."""
    errors = err.errors()
    e = errors[0]
    loc = _dotted(e["loc"]) or "(top level)"
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    if e["type"] == "extra_forbidden":
        return one_line(f"{source}: unknown key {loc!r}{more}", 500)
    scalar = isinstance(e.get("input"), (str, int, float)) and e["type"] != "missing"
    got = f" (got {short_repr(e['input'])})" if scalar else ""
    return one_line(f"{source}: {loc}: {e['msg']}{got}{more}", 500)


# cv2.aruco's predefined dictionaries that are not named DICT_<n>X<n>_<markers>, and their marker counts
_ARUCO_SIZES = {
    "DICT_ARUCO_ORIGINAL": 1024, "DICT_APRILTAG_16H5": 30, "DICT_APRILTAG_25H9": 35, "DICT_APRILTAG_36H10": 2320,
    "DICT_APRILTAG_36H11": 587, "DICT_ARUCO_MIP_36H12": 250,
}


def _check_settings(settings: Settings, source: str) -> None:
    """Checks across what the models validate field by field, found by fuzzing (tests/test_config_fuzz.py):
    values the models accept but the world cannot use, caught here with the dotted key instead."""
    if settings.seed < 0:  # numpy's generators (object layout, noise) take non-negative seeds only
        raise ConfigError(f"{source}: seed: must be a non-negative integer, got {settings.seed}")
    name, marker = settings.aruco.dictionary, settings.aruco.id
    m = re.fullmatch(r"DICT_(\d)X\1_(\d+)", name)
    size = int(m.group(2)) if m else _ARUCO_SIZES.get(name.upper())
    if size is not None and marker >= size:  # OpenCV would fail when the marker image is drawn
        raise ConfigError(f"{source}: aruco.id: {name} has markers 0..{size - 1}, got {marker}")


def settings_from_dict(data: dict[str, Any], *, source: str = "<dict>") -> Settings:
    """Validate a plain mapping into Settings; raise ConfigError naming the dotted path on failure."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: the top level must be a mapping of keys, got {type(data).__name__}")
    _check_tree(data, source)
    try:
        settings = Settings.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format_validation(source, err)) from None
    except RecursionError:
        raise ConfigError(f"{source}: nested too deeply to validate") from None
    _check_settings(settings, source)
    return settings


def _check_files(settings: Settings, source: str) -> None:
    """Every URDF the config names must be a regular file: a directory, a device (/dev/zero never ends)
    or a missing file would otherwise fail deep inside the scene or the world, or not at all."""
    named = [("robot.urdf", settings.robot.urdf)] + [(f"world.fixtures.{i}.urdf", f.urdf) for i, f in enumerate(settings.world.fixtures)]
    for where, name in named:
        try:
            resolved = settings.resolve(name)
            ok = resolved.is_file()
        except (OSError, ValueError) as e:  # an embedded NUL byte, a name too long for the system
            raise ConfigError(f"{source}: {where}: unusable path {short_repr(name)} ({one_line(e)})") from None
        if not ok:
            what = "is not a file" if resolved.exists() else "not found"
            raise ConfigError(f"{source}: {where}: {short_repr(name)} {what} (resolved to {short_repr(str(resolved), 200)})")


def load_config(path: str | Path, overrides: Iterable[str] = ()) -> Settings:
    """Load a YAML config (following `extends`), apply `a.b=value` overrides, validate.

    Raises ConfigError, with one line naming the file and the dotted key, for a missing, unreadable,
    binary, non-UTF-8, empty or invalid YAML file, an unknown key, a bad value, or a URDF that is not a file.
    """
    p = Path(path)
    data = read_yaml(p)
    for o in overrides:
        apply_override(data, o)
    settings = settings_from_dict(data, source=str(p))
    _check_files(settings, str(p))
    return settings
