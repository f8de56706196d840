"""The RoboCup ARM sorting system (seed 002) as a built-in task plugin, in one place: the state machine
(`task`), its pose estimation (`perception`: PCA + ICP), and its settings."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from twin.tasks.robocup.task import (
        BinGeometry,
        RobocupTask,
        bin_for,
        bin_geometries,
        feasible_cube_yaw,
        grip_width,
        read_bin_geometry,
        run_robocup,
    )

__all__ = [
    "BinGeometry",
    "RobocupTask",
    "bin_for",
    "bin_geometries",
    "feasible_cube_yaw",
    "grip_width",
    "read_bin_geometry",
    "run_robocup",
]


def __getattr__(attr: str) -> Any:
    """The task's names, imported on first use: the config schema imports `twin.config.robocup`,
    which must not pull in the task's state machine (and with it the config) while the config loads."""
    if attr in __all__:
        return getattr(importlib.import_module("twin.tasks.robocup.task"), attr)
    raise AttributeError(f"module 'twin.tasks.robocup' has no attribute {attr!r}")
