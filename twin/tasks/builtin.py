"""twin's own task plugins, registered through the entry-point group `twin` exactly as a third party's."""

from __future__ import annotations

from typing import TYPE_CHECKING

from twin.hookspecs import hookimpl

if TYPE_CHECKING:
    from twin.registry import Registry


@hookimpl
def twin_register_tasks(registry: Registry) -> None:
    registry.add_task(
        "robocup",
        "twin.tasks.robocup:RobocupTask",
        description="RoboCup ARM sorting (seed 002): wrist camera, PCA + ICP, MoveJ/MoveL, 8 classes into 2 bins",
    )
    registry.add_task(
        "warehouse",
        "twin.tasks.warehouse:WarehouseTask",
        description="warehouse sorting (seeds 000/001): fixed camera, ArUco, DBSCAN, transfer over the obstacle",
    )
