"""The warehouse sorting system (seeds 000/001) as a built-in task plugin, in one place: the task
(`task`), its cube detector (`perception`: RANSAC plane + DBSCAN), and its settings."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from twin.tasks.warehouse.task import WarehouseTask, run_warehouse

__all__ = [
    "WarehouseTask",
    "run_warehouse",
]


def __getattr__(attr: str) -> Any:
    """The task's names, imported on first use: the config schema imports `twin.config.warehouse`,
    which must not pull in the task's state machine (and with it the config) while the config loads."""
    if attr in __all__:
        return getattr(importlib.import_module("twin.tasks.warehouse.task"), attr)
    raise AttributeError(f"module 'twin.tasks.warehouse' has no attribute {attr!r}")
