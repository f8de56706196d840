"""Compiled planners: `compiled.rrtconnect`, RRT-Connect wholly in compiled code (numba) on twin's planning
model (the robot's sphere cover against the scene's primitives, `PlanningScene.sphere_model`), then retimed
and judged by the exact FCL scene like every planner (issue 41).

Registered lazily through the entry-point group `twin`: importing this package imports neither numba nor
the search; `twin_compiled.planner` does, when the planner is first created (the compiled code is cached on
disk by numba after its first compilation on a machine).
"""

from __future__ import annotations

from twin.plugin import Registry, hookimpl

__all__ = ["PLANNERS", "twin_register_planners"]

PLANNERS: dict[str, tuple[str, str]] = {
    "compiled.rrtconnect": (
        "twin_compiled.planner:CompiledRRTConnect",
        "RRT-Connect compiled end to end (numba) on the sphere planning model, continuous motion checks; "
        "stops at the first path, shortcut, retimed",
    ),
}


@hookimpl
def twin_register_planners(registry: Registry) -> None:
    """Register the compiled planners (lazily: numba is imported on first use)."""
    for name, (target, description) in PLANNERS.items():
        registry.add_planner(name, target, description=description)
