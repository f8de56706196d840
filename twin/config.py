"""Validated configuration: YAML files loaded into typed pydantic models.

A file may name another with `extends: other.yaml` (a path relative to the file); the two are merged
key by key, the extending file winning. `--set a.b=value` overrides (parsed as YAML scalars) apply last.
Unknown keys are rejected with the file and the dotted path of the key.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from twin.errors import ConfigError

__all__ = [
    "Settings",
    "RobotSettings",
    "GripperSettings",
    "FixtureSettings",
    "ObjectSpec",
    "ObjectSettings",
    "WorldSettings",
    "ArucoSettings",
    "CameraSettings",
    "CollisionSettings",
    "PlannerBlock",
    "TaskSettings",
    "RobocupTaskSettings",
    "WarehouseTaskSettings",
    "DepthNoiseSettings",
    "DetectorBlock",
    "WarehousePerceptionSettings",
    "IcpSettings",
    "GraspEntry",
    "RobocupPerceptionSettings",
    "PerceptionSettings",
    "load_config",
    "read_yaml",
    "apply_override",
    "settings_from_dict",
    "PROJECT_ROOT",
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


def read_yaml(path: Path, seen: tuple[Path, ...] = ()) -> dict[str, Any]:
    path = path.resolve()
    if path in seen:
        raise ConfigError(f"{path}: `extends` forms a cycle through {' -> '.join(map(str, seen))}")
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark else ""
        raise ConfigError(f"{path}:{where} is not valid YAML ({getattr(e, 'problem', e)})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a mapping of keys, got {type(data).__name__}")
    parent = data.pop("extends", None)
    if parent is not None:
        if not isinstance(parent, str):
            raise ConfigError(f"{path}: `extends` must be a file path, got {parent!r}")
        data = _merge(read_yaml(path.parent / parent, seen + (path,)), data)
    return data


def apply_override(data: dict[str, Any], override: str) -> None:
    if "=" not in override:
        raise ConfigError(f"override {override!r} must look like key.path=value")
    key, raw = override.split("=", 1)
    parts = [p for p in key.strip().split(".")]
    if not all(parts):
        raise ConfigError(f"override {override!r}: empty key in dotted path {key!r}")
    try:
        value = yaml.safe_load(raw)
    except yaml.YAMLError:
        value = raw
    node = data
    for p in parts[:-1]:
        nxt = node.get(p)
        if nxt is None:
            nxt = node[p] = {}
        if not isinstance(nxt, dict):
            raise ConfigError(f"override {override!r}: {p!r} is a value, not a section")
        node = nxt
    node[parts[-1]] = value


def _format_validation(source: str, err: ValidationError) -> str:
    e = err.errors()[0]
    loc = ".".join(str(p) for p in e["loc"]) or "(top level)"
    more = f" (and {len(err.errors()) - 1} more)" if len(err.errors()) > 1 else ""
    if e["type"] == "extra_forbidden":
        return f"{source}: unknown key {loc!r}{more}"
    return f"{source}: {loc}: {e['msg']}{more}"


def settings_from_dict(data: dict[str, Any], *, source: str = "<dict>") -> Settings:
    """Validate a plain mapping into Settings; raise ConfigError naming the dotted path on failure."""
    try:
        return Settings.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format_validation(source, err)) from None


def load_config(path: str | Path, overrides: Iterable[str] = ()) -> Settings:
    """Load a YAML config (following `extends`), apply `a.b=value` overrides, validate.

    Raises ConfigError for a missing file, bad YAML, an unknown key (with its dotted path) or a bad value.
    """
    p = Path(path)
    data = read_yaml(p)
    for o in overrides:
        apply_override(data, o)
    return settings_from_dict(data, source=str(p))
