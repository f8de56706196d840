"""The robot of a config, built once per run and handed down (`PluginContext.robot`).

Why: the arm's DH kinematics, its URDF and the gripper's geometry are one thing, fixed by `settings.robot`.
Built in every consumer, a run parsed the same URDF three times and made 25 arms (one per camera frame
among them). mink's `Configuration` and MPlib's `ArticulatedModel` show the shape: the model is made once
and the same object goes to the world, the planning scene, perception, the planners and the task.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from twin.errors import ConfigError
from twin.robot.gripper import gripper_boxes, gripper_stroke_m
from twin.robot.kinematics import URArm
from twin.robot.sphere_cover import cover
from twin.robot.urdf_model import RobotModel

if TYPE_CHECKING:
    from twin.config import Settings

__all__ = ["Robot"]


@dataclass(frozen=True, eq=False)
class Robot:
    """One arm with its gripper: `arm` (DH, joint limits, IK), `urdf_model` (the URDF as read: links, joints,
    collision shapes), `model` (that model in the arm's base frame with the arm's TCP, `URArm.fit_urdf`;
    checked against the DH kinematics when built), `urdf` as configured and `urdf_path` resolved, the
    gripper's geometry (`max_opening_m`, `gripper_boxes`) and the sphere cover of its shapes
    (`sphere_cover`). Immutable: a planning scene or world copies what it changes."""

    arm: URArm
    urdf: str
    urdf_path: Path
    urdf_model: RobotModel
    model: RobotModel
    _boxes: dict[float, list[tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict, repr=False)

    @classmethod
    def from_settings(cls, settings: Settings) -> Robot:
        """The robot of `settings.robot`: the arm of `robot.model`, the URDF of `robot.urdf` (read once).
        ConfigError when the URDF's arm is not that arm (the planners plan with the DH kinematics: the
        collision model must be the same arm)."""
        arm = URArm(model=settings.robot.model)
        urdf_path = Path(settings.resolve(settings.robot.urdf))
        urdf_model = RobotModel.from_urdf(urdf_path)
        model = arm.fit_urdf(urdf_model)
        wrong = arm.urdf_mismatch(model)
        if wrong is not None:
            raise ConfigError(
                f"robot.urdf {settings.robot.urdf} is not the arm of robot.model {settings.robot.model}: {wrong}"
            )
        return cls(arm, settings.robot.urdf, urdf_path, urdf_model, model)

    @property
    def name(self) -> str:
        """The arm's `robot.model` name (`ur5e`, `ur10e`, ...)."""
        return self.arm.model

    @functools.cached_property
    def urdf_base(self) -> np.ndarray:
        """(4, 4) pose of the URDF's root link in the arm's base frame (`URArm.urdf_base`): where the
        physics loads the URDF so that the arm's base is the world origin."""
        return self.arm.urdf_base(self.urdf_model)

    @functools.cached_property
    def max_opening_m(self) -> float:
        """The gripper's stroke: its largest total finger opening, m (0 for a URDF without finger joints)."""
        return gripper_stroke_m(self.model)

    @functools.cached_property
    def sphere_cover(self) -> tuple[np.ndarray, ...]:
        """The conservative sphere cover of each collision shape of `model`, in `model.shapes()` order: (k, 4)
        spheres (x, y, z, r) in the shape's frame (`twin.robot.sphere_cover.cover`). ConfigError for a mesh."""
        covers = []
        for shape in self.model.shapes():
            if shape.kind == "mesh":
                where = self.model.source  # the words the planning scene has for it (`primitive_shapes`)
                raise ConfigError(f"{where}: link {shape.link!r} uses a mesh; the planning scene needs primitives")
            covers.append(cover(shape.kind, shape.size))
        return tuple(covers)

    def gripper_boxes(self, opening_m: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """(lo (3,), hi (3,)) in the tcp frame of every collision shape of the gripper at a finger opening
        (`twin.robot.gripper.gripper_boxes`), computed once per opening."""
        key = float(opening_m)
        if key not in self._boxes:
            self._boxes[key] = gripper_boxes(self.urdf_model, key, where=self.urdf)
        return [(lo.copy(), hi.copy()) for lo, hi in self._boxes[key]]
