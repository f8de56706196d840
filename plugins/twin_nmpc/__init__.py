"""Built-in NMPC planner (seeds 000/001), registered through the `twin` entry-point group.

- `nmpc` (`twin_nmpc.planner:NMPCPlanner`): receding-horizon NMPC over CasADi/IPOPT. Needs the `nmpc`
  extra (casadi); the name is registered lazily, so `import twin` never imports CasADi.
"""

from __future__ import annotations

from twin.plugin import Registry, hookimpl

__all__ = ["twin_register_planners"]


@hookimpl
def twin_register_planners(registry: Registry) -> None:
    """Register `nmpc` as a receding-horizon planner."""
    registry.add_planner(
        "nmpc",
        "twin_nmpc.planner:NMPCPlanner",
        receding_horizon=True,
        extra="nmpc",
        description=(
            "warehouse NMPC (CasADi/IPOPT): 30 x 0.08 s horizon, proxy spheres over the obstacle box, "
            "first k steps executed"
        ),
    )
