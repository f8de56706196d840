"""The config's typed models: the cell (robot, gripper, world, camera, marker, collision), planner and
detector blocks, and `Settings`, everything a run needs.

Every model is frozen and rejects unknown keys (`ConfigModel`). The task and perception models of the two
reference tasks live with their tasks (`twin.config.robocup`, `twin.config.warehouse`);
`TaskSettings` names the task plugin to run and `PerceptionSettings` the perception pipeline.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    ConfigDict,
    Field,
    PrivateAttr,
    SerializerFunctionWrapHandler,
    field_validator,
    model_serializer,
    model_validator,
)

from twin.config.base import Q6, ConfigModel, Vec3
from twin.config.robocup import RobocupPerceptionSettings, RobocupTaskSettings
from twin.config.warehouse import WarehousePerceptionSettings, WarehouseTaskSettings
from twin.resources import data_files, packaged_path

__all__ = [
    "DEFAULT_PLANNERS",
    "STAGES",
    "STAGE_GROUPS",
    "ArucoSettings",
    "CameraSettings",
    "CollisionSettings",
    "DepthFilterSettings",
    "DepthNoiseSettings",
    "DetectorBlock",
    "FixtureSettings",
    "GripperSettings",
    "LightSettings",
    "ObjectSettings",
    "ObjectSpec",
    "PerceptionSettings",
    "PlannerBlock",
    "PlannerGroups",
    "RobotSettings",
    "Settings",
    "TaskSettings",
    "UnmodelledObstacleSettings",
    "WorldSettings",
]


class RobotSettings(ConfigModel):
    """The arm: which Universal Robots arm (`twin.robot.ur_models`: its DH parameters, IK and datasheet joint speeds),
    its URDF, home posture and joint limits (SPEC: pi rad/s, +-2pi, elbow +-pi)."""

    model: Literal["ur3", "ur3e", "ur5", "ur5e", "ur10", "ur10e", "ur16e"] = "ur5e"
    # the arm's URDF (collision model of primitives, checked against the model's DH at load; its root may sit
    # above the arm's base, and one without a tcp link gets the arm's TCP: `URArm.fit_urdf`); default the one
    # twin ships for the model, urdf/<model>.urdf (`twin.robot.ur_urdf`)
    urdf: str = "urdf/ur5e.urdf"
    home: Q6 = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)
    max_joint_vel: float = Field(math.pi, gt=0)
    max_joint_acc: float = Field(8.0, gt=0)
    max_joint_jerk: float = Field(100.0, gt=0)
    # the joint motors' position gain: the fraction of the position error they correct per physics step
    # (PyBullet's positionGain), so the controller's time constant is 1 / (physics_hz * position_gain):
    # 0.15 at 480 Hz is 14 ms, the same controller as 0.3 at 240 Hz; change the two together
    position_gain: float = Field(0.15, gt=0, le=1)
    # the joint motors' force limits, N m; default the model's (`twin.robot.ur_models`: the UR5e's 150 and 28)
    max_joint_force: Q6 = (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)
    # fault models (off at 0): a sluggish controller follows the commanded joint targets through a
    # first-order lag with this time constant, and a noisy one adds this RMS (rad) to every physics step's
    # target; the planners and the task are not told
    tracking_time_constant_s: float = Field(0.0, ge=0, le=1.0)
    tracking_noise_rad: float = Field(0.0, ge=0, le=0.05)

    @model_validator(mode="before")
    @classmethod
    def _model_defaults(cls, data: Any) -> Any:
        """The URDF and motor forces of the model chosen, where the config does not give its own."""
        if isinstance(data, dict) and data.get("model", "ur5e") != "ur5e":
            from twin.robot.ur_models import UR_MODELS  # lazy: import twin stays light (twin.robot)

            model = UR_MODELS.get(str(data["model"]))
            if model is not None:  # an unknown name is the Literal's error
                data = {"urdf": f"urdf/{model.name}.urdf", "max_joint_force": model.torques, **data}
        return data


class GripperSettings(ConfigModel):
    """Parallel gripper: 0..85 mm stroke, 20..235 N grip force (Robotiq 2F-85)."""

    max_opening_m: float = Field(0.085, gt=0, le=0.085)
    force_n: float = Field(100.0, ge=20, le=235)
    speed_m_s: float = Field(0.1, gt=0, le=0.15)
    # a fault model (off at 1): the fingers squeeze with this times the commanded force (a worn gripper)
    force_scale: float = Field(1.0, ge=0.1, le=2.0)
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


class FixtureSettings(ConfigModel):
    """A static body of the cell, loaded from a URDF at a pose in the world (= robot base) frame."""

    name: str
    urdf: str
    position: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)
    known: bool = True  # in the planners' scene from the start; false: the robot must perceive it


class ObjectSpec(ConfigModel):
    """`count` objects of one class (and colour, for cubes) to scatter in the spawn region."""

    cls: Literal["bottle", "can", "spam", "cube", "marker", "warehouse_cube", "obstacle"] = Field(alias="class")
    color: str | None = None
    count: int = Field(1, ge=0, le=50)
    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)


class ObjectSettings(ConfigModel):
    """Where and how objects are placed: seeded, never overlapping, upright or lying."""

    region_x: tuple[float, float] = (-0.65, -0.30)
    region_y: tuple[float, float] = (-0.30, 0.30)
    min_gap_m: float = Field(0.03, ge=0)
    lying_probability: float = Field(0.0, ge=0, le=1)
    random_yaw: bool = True
    items: list[ObjectSpec] = Field(default_factory=list)
    # fault models (off at [1, 1]): each object's mass and friction are its catalogue values times a factor
    # drawn uniformly from this range, per object, from the scene seed; what the task and the planners are
    # told (the catalogue) does not change
    mass_scale: tuple[float, float] = (1.0, 1.0)
    friction_scale: tuple[float, float] = (1.0, 1.0)

    @field_validator("region_x", "region_y")
    @classmethod
    def _ordered(cls, v: tuple[float, float]) -> tuple[float, float]:
        if v[0] >= v[1]:
            raise ValueError(f"range must be [min, max] with min < max, got {list(v)}")
        return v

    @field_validator("mass_scale", "friction_scale")
    @classmethod
    def _scale_range(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not 0 < v[0] <= v[1]:
            raise ValueError(f"a scale range must be [min, max] with 0 < min <= max, got {list(v)}")
        return v


class UnmodelledObstacleSettings(ConfigModel):
    """A fault model: a box on the table that no config fixture, planning scene or catalogue describes (a
    tool left behind, a cable duct). Centred at a position drawn from the scene seed in `region_x` x
    `region_y` (None: the objects' spawn region), `min_gap_m` (None: the objects' gap) clear of every
    object's footprint and every fixture; only what a camera sees of it can tell anyone it is there."""

    size_m: Vec3 = (0.04, 0.04, 0.15)
    region_x: tuple[float, float] | None = None
    region_y: tuple[float, float] | None = None
    min_gap_m: float | None = Field(None, ge=0)

    @field_validator("size_m")
    @classmethod
    def _positive(cls, v: Vec3) -> Vec3:
        if min(v) <= 0:
            raise ValueError(f"every side must be > 0, got {list(v)}")
        return v


class LightSettings(ConfigModel):
    """The light the camera images are rendered under. Off (no direction, white, no jitter): PyBullet's own
    light, as before. `direction` points from the scene towards the light (world frame, any length); per
    scene seed the direction is tilted by up to `direction_jitter_deg` (uniform over the cone) and each colour
    channel scaled by a factor drawn from [1 - color_jitter, 1 + color_jitter]: lighting that varies from
    scene to scene, for realistic images and datasets (`twin.world.rendering.scene_light`)."""

    direction: tuple[float, float, float] | None = None
    color: tuple[
        Annotated[float, Field(ge=0.0, le=3.0)],
        Annotated[float, Field(ge=0.0, le=3.0)],
        Annotated[float, Field(ge=0.0, le=3.0)],
    ] = (1.0, 1.0, 1.0)
    direction_jitter_deg: float = Field(0.0, ge=0.0, le=80.0)
    color_jitter: float = Field(0.0, ge=0.0, le=0.5)

    @field_validator("direction")
    @classmethod
    def _nonzero(cls, v: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if v is not None and math.hypot(*v) < 1e-9:
            raise ValueError("a light direction must not be zero")
        return v


class WorldSettings(ConfigModel):
    """The PyBullet world: rate, gravity, fixtures and objects.

    The world frame is the robot base frame (UR DH base: with the shoulder pan at 0 the arm reaches
    towards -x), so the table and the work area lie at negative x, in front of the arm's home posture.
    """

    # 480 Hz: at 240 Hz a cube held by friction slipped out of the fingers in fast transfers that hold it at
    # 480 and 960 Hz (10 OMPL planners' warehouse transfers, seeds 0-4: 24 of 50 runs lost a cube at 240 Hz,
    # none at 480 or 960; the same at 480 Hz with the 240 Hz controller's time constant): 240 Hz does not
    # resolve a friction grasp under the arm's accelerations
    physics_hz: float = Field(480.0, gt=0)
    gravity: float = -9.81
    gui: bool = False
    # Objects still for 2 s (|v|^2 + |w|^2 under 1e-5: ~3 mm/s, ~3 mrad/s) sleep: the engine stops
    # integrating them until something touches them, and wakes them then (Bullet's deactivation). A still
    # object costs ~7 us per physics step awake, nearly nothing asleep; what is lost is the slow creep of a
    # lying cylinder or a box on the soft contacts. False: every object is integrated at every step.
    sleep_at_rest: bool = True
    fixtures: list[FixtureSettings] = Field(
        default_factory=lambda: [
            FixtureSettings(name="table", urdf="urdf/table.urdf", position=(-0.30, 0.0, 0.0)),
        ]
    )
    objects: ObjectSettings = Field(default_factory=ObjectSettings)
    # how the objects look to the camera (`twin.object_visuals`): 'flat' = each class one single-colour
    # primitive; 'realistic' = textured meshes (a bottle with shoulder, neck, cap and label; a can with a
    # printed label; a spam tin with lid and label; a marker with cap and clip), one of several looks per object
    # drawn from the scene seed. Collision shapes and physics are the same either way.
    visuals: Literal["flat", "realistic"] = "flat"
    light: LightSettings = Field(default_factory=LightSettings)
    unmodelled_obstacle: UnmodelledObstacleSettings | None = None  # a fault model: off when None

    @model_validator(mode="after")
    def _unique_names(self) -> WorldSettings:
        names = [f.name for f in self.fixtures]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"fixture names must be unique, repeated: {sorted(dup)}")
        return self


class ArucoSettings(ConfigModel):
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


class DepthNoiseSettings(ConfigModel):
    """D435i-like depth noise: RMS = z^2 * subpixel / (focal_px * baseline_m), plus dropouts.

    Defaults give ~1 mm at 0.5 m, ~4 mm at 1 m, ~15 mm at 2 m (Intel's model for the D435i). Dropouts
    are invalid pixels (depth 0): a random fraction everywhere and a larger one at depth edges, where a
    stereo camera loses the match. `rgb_noise_std` is Gaussian pixel noise on the colour image (0..255).
    """

    enabled: bool = True
    scale: float = Field(
        1.0,
        ge=0,
        description="multiplies the depth noise RMS (a fault-model knob: 2 is a sensor twice as noisy as this"
        " model's best case, as on matte, textureless objects)",
    )
    static_fraction: float = Field(
        0.0,
        ge=0,
        le=1,
        description="share of the depth noise variance that is the same in every frame of one capture (a stereo"
        " matcher's error is partly fixed by the scene's texture): averaging frames cannot remove it",
    )
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
    # a fault model (off at 1, 1, 1): per-channel gain on the colour image, for a light of another colour
    # or a camera's white balance off (warm light: [1.2, 1.0, 0.8]); equal gains are a brighter or dimmer light
    color_gain: tuple[
        Annotated[float, Field(ge=0.2, le=3.0)],
        Annotated[float, Field(ge=0.2, le=3.0)],
        Annotated[float, Field(ge=0.2, le=3.0)],
    ] = (1.0, 1.0, 1.0)


class ExtrinsicErrorSettings(ConfigModel):
    """A camera that is not mounted where the config says (a fault model; off by default).

    The fixed camera's pose, or the wrist camera's hand-eye transform, is off by a translation of
    `translation_m` along, and a rotation of `rotation_deg` about, directions drawn from the scene seed (in
    the camera frame). Rendering uses the real pose; perception is not told: what it assumes is the config's
    pose, unless an ArUco calibration measures the real one (a fixed camera with `perception.extrinsics`
    auto or aruco).
    """

    translation_m: float = Field(0.0, ge=0, le=0.2)
    rotation_deg: float = Field(0.0, ge=0, le=20.0)


class MountToleranceSettings(ConfigModel):
    """How far the configured camera pose (a fixed camera's `position`/`target`, a wrist camera's
    `wrist_offset_m`) is trusted to be from the real mount, as a mechanical tolerance: a translation of at most
    `translation_m` and a rotation of at most `rotation_deg`. Not a fault model (nothing is moved by it): it is
    the error bound a run reports when it cannot measure the mount (the marker not seen in any view)."""

    translation_m: float = Field(0.01, ge=0, le=0.2)
    rotation_deg: float = Field(1.0, ge=0, le=20.0)


class CameraSettings(ConfigModel):
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
    extrinsic_error: ExtrinsicErrorSettings = Field(default_factory=ExtrinsicErrorSettings)
    mount_tolerance: MountToleranceSettings = Field(default_factory=MountToleranceSettings)
    # wrist mount: joint angles where the camera looks straight down from ~0.72 m above the table centre
    # (image x along base +y), and the settling pause before a frame is taken there (seed 002: 3 s)
    capture_pose: Q6 = (-0.2518, -1.2366, 0.4574, -0.7916, -1.5708, -0.2518)
    settle_s: float = Field(3.0, ge=0)
    # a fault model (off at 0): the frame perception gets was taken this long before it arrives, while the
    # joint angles read with it are current (at most the settling pause: the frame is from within it)
    latency_s: float = Field(0.0, ge=0, le=1.0)
    # wrist mount: joint angles where the camera sees the base marker for `twin calibrate` (None: capture_pose)
    calibration_pose: Q6 | None = None

    @model_validator(mode="after")
    def _near_far(self) -> CameraSettings:
        if self.near_m >= self.far_m:
            raise ValueError(f"near_m ({self.near_m}) must be less than far_m ({self.far_m})")
        return self


class CollisionSettings(ConfigModel):
    """FCL planning scene options."""

    padding_m: float = Field(0.0, ge=0, le=0.1)
    check_resolution_rad: float = Field(0.01, gt=0, le=0.1)
    check_resolution_m: float = Field(0.01, gt=0, le=0.05)
    sphere_filter: bool = Field(
        True,
        description=(
            "clear configurations with the robot's conservative sphere model before FCL (same answers, "
            "several times cheaper; off: FCL checks every configuration)"
        ),
    )


class PlannerBlock(ConfigModel):
    """A plugin chosen by name with its own parameters, validated by that plugin's model."""

    name: str
    params: dict[str, Any] = Field(default_factory=dict)
    retimer: str | None = None
    retimer_params: dict[str, Any] = Field(default_factory=dict)


# stage -> (its planner group, the kind of goal it asks for). A transfer ends above the place point and the
# place move finishes it, so it asks for a position within `task.transfer_tolerance_m` with the orientation
# free; every other stage for an exact goal.
STAGES: dict[str, tuple[str, str]] = {
    "capture": ("movej", "joint"),
    "align": ("movej", "joint"),
    "hover": ("movej", "pose"),
    "home": ("movej", "joint"),
    "descent": ("movel", "pose"),
    "ascent": ("movel", "pose"),
    "place": ("movel", "pose"),
    "transfer": ("transfer", "position"),
}
STAGE_GROUPS = {stage: group for stage, (group, _) in STAGES.items()}
DEFAULT_PLANNERS = {"movej": "ruckig.movej", "movel": "toppra.movel", "transfer": "ruckig.movej"}


class PlannerGroups(ConfigModel):
    """The planner of each group of a task's motion stages (`STAGES`). A group left out gets its default
    (`DEFAULT_PLANNERS`); any other key is refused with a did-you-mean (a misspelt group would otherwise
    leave the default running silently). `with_planner` swaps one group's block."""

    movej: PlannerBlock | None = Field(
        None, description="joint moves: to the capture pose, the base alignment, the pre-grasp hover, home"
    )
    movel: PlannerBlock | None = Field(
        None, description="straight tcp lines: the descent to a grasp, the ascent, the placing move"
    )
    transfer: PlannerBlock | None = Field(
        None, description="carrying the held object to its bin: the planner a comparison compares"
    )

    @model_serializer(mode="wrap")
    def _given_only(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """Only the groups a config gives: a dump (and the run ids hashed from it) is what it was when
        `planners` was a mapping of the groups given."""
        return {k: v for k, v in handler(self).items() if v is not None}

    def get(self, group: str) -> PlannerBlock | None:
        """The block of `group` ('movej', 'movel', 'transfer'); None when the config leaves it to the default."""
        if group not in type(self).model_fields:
            raise KeyError(f"no planner group {group!r}; the groups are {', '.join(type(self).model_fields)}")
        block: PlannerBlock | None = getattr(self, group)
        return block

    def block(self, group: str) -> PlannerBlock:
        """The block that plans `group`'s stages: the config's, else the group's default planner."""
        given = self.get(group)
        return given if given is not None else PlannerBlock(name=DEFAULT_PLANNERS[group])

    def given(self) -> dict[str, PlannerBlock]:
        """group -> block, for the groups the config gives."""
        return {g: b for g in type(self).model_fields if (b := getattr(self, g)) is not None}


class DetectorBlock(ConfigModel):
    """A detector plugin chosen by name, with its own parameters (validated by the plugin's model)."""

    name: str = "geometric"
    params: dict[str, Any] = Field(default_factory=dict)


class DepthFilterSettings(ConfigModel):
    """Depth post-processing before perception (`twin.perception.depth_filter`), as the RealSense SDK's
    temporal and spatial filters do it.

    `temporal_frames`: frames from the end of the settling pause (30 fps) averaged per pixel; 1 is the
    single frame the reference systems took. A pixel valid in fewer than `min_valid_fraction` of them is a
    hole. `spatial`: an edge-preserving filter over `spatial_radius_px`, its range sigma
    `spatial_range_sigmas` times the noise measured in the frame.
    """

    temporal_frames: int = Field(8, ge=1, le=90)
    min_valid_fraction: float = Field(0.5, gt=0, le=1)
    spatial: bool = True
    spatial_radius_px: int = Field(3, ge=1, le=7)
    spatial_range_sigmas: float = Field(2.0, gt=0, le=10)


# what `perception.preset: seed` changes from the defaults: the reference systems' single raw frame and fixed
# thresholds (keys a config sets itself win)
_SEED_PERCEPTION: dict[str, dict[str, Any]] = {
    "depth_filter": {"temporal_frames": 1, "spatial": False},
    "robocup": {"table_threshold_sigmas": None, "white_balance": False},
}


class PerceptionSettings(ConfigModel):
    """What `twin perceive` runs: the warehouse pipeline (seeds 000/001) or the RoboCup one (seed 002).

    `preset`: "robust" (default) filters the depth and sets thresholds from the noise it measures;
    "seed" is the reference systems' single raw frame and fixed thresholds (what a config sets itself
    still wins). `extrinsics`: how the camera-to-base transform is obtained; "auto" uses the ArUco marker for a fixed
    camera and forward kinematics of the measured joints plus `camera.wrist_offset_m` for a wrist camera.
    """

    pipeline: Literal["robocup", "warehouse"] = "robocup"
    preset: Literal["robust", "seed"] = "robust"
    extrinsics: Literal["auto", "aruco", "kinematics"] = "auto"
    detector: DetectorBlock = Field(default_factory=DetectorBlock)
    depth_filter: DepthFilterSettings = Field(default_factory=DepthFilterSettings)
    warehouse: WarehousePerceptionSettings = Field(default_factory=WarehousePerceptionSettings)
    robocup: RobocupPerceptionSettings = Field(default_factory=RobocupPerceptionSettings)

    @model_validator(mode="before")
    @classmethod
    def _preset(cls, data: Any) -> Any:
        if not isinstance(data, dict) or data.get("preset") != "seed":
            return data
        out = dict(data)
        for section, values in _SEED_PERCEPTION.items():
            given = out.get(section)
            if given is not None and not isinstance(given, dict):
                continue  # a model instance or a wrong type: validated as it is
            out[section] = {**values, **(given or {})}
        return out


class TaskSettings(ConfigModel):
    """Which task `twin run` runs (a registered task plugin's name; `twin planners` lists them), and its
    parameters: the built-in tasks' own sections `robocup` / `warehouse`, a third-party task's `params`
    (validated by the task class's `Params` model when the task is made)."""

    kind: str = Field("robocup", pattern=r"^[a-z0-9_]+(\.[a-z0-9_]+)*$")
    params: dict[str, Any] = Field(default_factory=dict)
    robocup: RobocupTaskSettings = Field(default_factory=RobocupTaskSettings)
    warehouse: WarehouseTaskSettings = Field(default_factory=WarehouseTaskSettings)
    settle_s: float = Field(0.5, ge=0, le=5)  # pause after gripper actions (seed 002: 0.5-0.8 s)
    max_sim_time_s: float = Field(900.0, gt=0)  # a run stops (objects left are failed) after this
    # the transfer ends above the place point and the place move finishes it: it needs the position within
    # this distance (the seed-000 NMPC stops within 3 cm), the orientation is free
    transfer_tolerance_m: float = Field(0.03, gt=0, le=0.1)


class Settings(ConfigModel):
    """Everything a run needs, validated on load."""

    name: str = "twin"
    seed: int = 0
    robot: RobotSettings = Field(default_factory=RobotSettings)
    gripper: GripperSettings = Field(default_factory=GripperSettings)
    world: WorldSettings = Field(default_factory=WorldSettings)
    aruco: ArucoSettings = Field(default_factory=ArucoSettings)
    camera: CameraSettings = Field(default_factory=CameraSettings)
    collision: CollisionSettings = Field(default_factory=CollisionSettings)
    planners: PlannerGroups = Field(default_factory=PlannerGroups)
    task: TaskSettings = Field(default_factory=TaskSettings)
    perception: PerceptionSettings = Field(default_factory=PerceptionSettings)

    # The directories of the config file and of the files it extends (nearest first); set by the loader.
    # Not a field: it is where the config came from, not what it says (dumps and run ids leave it out).
    _config_dirs: tuple[Path, ...] = PrivateAttr(default=())

    @property
    def config_dirs(self) -> tuple[Path, ...]:
        """Directories that relative paths in this config are looked up in first: the config file's own,
        then those of the files it `extends`; empty for settings not loaded from a file."""
        return self._config_dirs

    def with_config_dirs(self, dirs: tuple[Path, ...] | list[Path]) -> Settings:
        """A copy whose relative paths are looked up in `dirs` first (see `resolve`)."""
        out = self.model_copy()
        out._config_dirs = tuple(Path(d) for d in dirs)
        return out

    def resolve(self, path: str) -> Path:
        """The file a path in this config names (a URDF): an absolute path as it is; a relative one in the
        config file's directory (then those of the files it extends) when it exists there, else in the
        data twin ships (`urdf/ur5e.urdf`), so it works from any working directory and any install.

        A path found nowhere resolves to where it was looked for first, for the error message.
        """
        p = Path(path)
        if p.is_absolute():
            return p
        for d in self._config_dirs:
            if (d / p).exists():
                return d / p
        shipped = packaged_path(path)
        if shipped is not None:
            return shipped
        return self._config_dirs[0] / p if self._config_dirs else Path(str(data_files())) / p
