"""Hook specifications of twin (pluggy project name "twin").

A plugin is any module or object with functions marked `@twin.hookimpl`, registered through the
entry-point group `twin` in its distribution's metadata (built-in plugins use the same group). Each hook
receives the `Registry` and calls `registry.add_*` for every name it provides; nothing is returned, and
a name registered twice raises `DuplicateNameError` at once, so registration order never picks a winner.
Factories are given lazily as "module:Class" strings, so listing names imports no heavy backend.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:
    from twin.registry import Registry

__all__ = ["TwinSpec", "hookimpl", "hookspec"]

hookspec = pluggy.HookspecMarker("twin")
hookimpl = pluggy.HookimplMarker("twin")


class TwinSpec:
    """The hooks twin calls; every plugin may implement any subset."""

    @hookspec
    def twin_register_planners(self, registry: Registry) -> None:
        """Add motion planners with `registry.add_planner(name, "module:Class", receding_horizon=...)`.

        One-shot planners implement `plan(request, scene) -> MotionResult`; receding-horizon planners
        implement `reset(request, scene)` and `step(q) -> Segment | None`. Called once per plugin when
        the registry is built; results of all plugins are combined into one name space.
        """

    @hookspec
    def twin_register_retimers(self, registry: Registry) -> None:
        """Add retimers with `registry.add_retimer(name, "module:Class")`.

        A retimer implements `retime(path (m, 6), limits) -> Trajectory` and turns a geometric joint path
        into a time-parameterised trajectory for path planners. Called once per plugin.
        """

    @hookspec
    def twin_register_detectors(self, registry: Registry) -> None:
        """Add perception detectors with `registry.add_detector(name, "module:Class")`.

        A detector turns an RGB-D frame into detections. Called once per plugin.
        """

    @hookspec
    def twin_register_tasks(self, registry: Registry) -> None:
        """Add tasks with `registry.add_task(name, "module:Class")`.

        A task is what `twin run` runs when a config's `task.kind` names it: built as `cls(params, context)`
        (`params` from the config's `task.params`, validated by the class's `Params` model if it has one),
        then `run(cell) -> list[ObjectOutcome]`, where `cell` (`twin.plugin.Cell`) is the robot, gripper,
        cameras and planners as a real cell would offer them. Called once per plugin.
        """
