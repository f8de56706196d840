"""twin: a PyBullet digital twin of a UR5e sorting cell, for comparing motion planners side by side.

Importing twin is cheap and has no side effects: heavy modules (pybullet, fcl, planners) load on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from twin.config import Settings, load_config
from twin.errors import (
    ConfigError,
    DependencyMissing,
    DuplicateNameError,
    InvalidRequestError,
    PlanningError,
    TwinError,
    UnknownNameError,
    WorldError,
)
from twin.hookspecs import hookimpl

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "DependencyMissing",
    "DuplicateNameError",
    "InvalidRequestError",
    "PlanningError",
    "PlanningScene",
    "Robot",
    "Settings",
    "TwinError",
    "URArm",
    "UnknownNameError",
    "World",
    "WorldError",
    "hookimpl",
    "load_config",
    "plan",
]

_LAZY = {
    "World": "twin.world",
    "PlanningScene": "twin.collision",
    "URArm": "twin.robot.kinematics",
    "Robot": "twin.robot",
    "plan": "twin.planning",
}

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.planning import plan
    from twin.robot import Robot
    from twin.robot.kinematics import URArm
    from twin.world import World


def __getattr__(name: str) -> Any:
    if name == "UR5e":  # deprecated: it was any arm of robot.model, not only a UR5e
        import warnings

        warnings.warn(
            "twin.UR5e is deprecated: it was any arm of robot.model; use twin.URArm", DeprecationWarning, stacklevel=2
        )
        name = "URArm"
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'twin' has no attribute {name!r}")
    return getattr(importlib.import_module(mod), name)
