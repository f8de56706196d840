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
    "load_config",
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


def _read_yaml(path: Path, seen: tuple[Path, ...] = ()) -> dict[str, Any]:
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
        data = _merge(_read_yaml(path.parent / parent, seen + (path,)), data)
    return data


def _apply_override(data: dict[str, Any], override: str) -> None:
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
    data = _read_yaml(p)
    for o in overrides:
        _apply_override(data, o)
    return settings_from_dict(data, source=str(p))
