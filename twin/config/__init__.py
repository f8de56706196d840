"""Validated configuration: YAML files loaded into typed pydantic models.

`twin.config.schema` holds the models of the cell and `Settings` (the two reference tasks' own models are
`twin.config.robocup` and `twin.config.warehouse`: below the tasks, so the config never imports a task),
`twin.config.loader` reads files (`extends`, `--set`
overrides, config names, one-line errors worded by `twin.messages`). Import from here: every name below
stays importable from `twin.config` whichever module defines it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from twin.config.loader import (
    apply_override,
    find_config,
    load_config,
    read_yaml,
    settings_from_dict,
    swap_planner,
    with_planner,
)
from twin.config.robocup import GraspEntry, IcpSettings, RobocupPerceptionSettings, RobocupTaskSettings
from twin.config.schema import (
    DEFAULT_PLANNERS,
    STAGE_GROUPS,
    STAGES,
    ArucoSettings,
    CameraSettings,
    CollisionSettings,
    DepthFilterSettings,
    DepthNoiseSettings,
    DetectorBlock,
    ExtrinsicErrorSettings,
    FixtureSettings,
    GripperSettings,
    LightSettings,
    MountToleranceSettings,
    ObjectSettings,
    ObjectSpec,
    PerceptionSettings,
    PlannerBlock,
    PlannerGroups,
    RobotSettings,
    Settings,
    TaskSettings,
    UnmodelledObstacleSettings,
    WorldSettings,
)
from twin.config.warehouse import WarehousePerceptionSettings, WarehouseTaskSettings
from twin.messages import one_line, short_repr

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
    "ExtrinsicErrorSettings",
    "FixtureSettings",
    "GraspEntry",
    "GripperSettings",
    "IcpSettings",
    "LightSettings",
    "MountToleranceSettings",
    "ObjectSettings",
    "ObjectSpec",
    "PerceptionSettings",
    "PlannerBlock",
    "PlannerGroups",
    "RobocupPerceptionSettings",
    "RobocupTaskSettings",
    "RobotSettings",
    "Settings",
    "TaskSettings",
    "UnmodelledObstacleSettings",
    "WarehousePerceptionSettings",
    "WarehouseTaskSettings",
    "WorldSettings",
    "apply_override",
    "find_config",
    "load_config",
    "one_line",
    "read_yaml",
    "settings_from_dict",
    "short_repr",
    "swap_planner",
    "with_planner",
]


def __getattr__(name: str) -> Any:
    # Deprecated: the checkout's root directory. It means nothing in an installed package (configs and
    # URDFs are package data now: `load_config("robocup")`, `twin.resources.packaged_path("urdf/...")`);
    # kept while bench/ and tests/ still use it.
    if name == "PROJECT_ROOT":
        import warnings

        warnings.warn(
            "twin.config.PROJECT_ROOT is deprecated: load shipped configs by name (load_config('robocup')) "
            "and shipped files with twin.resources.packaged_path('urdf/ur5e.urdf')",
            DeprecationWarning,
            stacklevel=2,
        )
        return Path(__file__).resolve().parent.parent.parent
    raise AttributeError(f"module 'twin.config' has no attribute {name!r}")
