"""twin_croc: a receding-horizon MPC on the field's optimal-control stack, Crocoddyl + mim-solvers (constrained
SQP) with pinocchio (extra `croc`), registered through the `twin` entry-point group.

- `croc` (`twin_croc.planner:CrocPlanner`): the receding-horizon loop `nmpc` uses too (`twin.planning.receding`)
  around a CSQP solve; `mode: seed` (nmpc's formulation) or `whole_arm` (every link against every box of the
  scene).
  The name is registered lazily, so `import twin` never imports Crocoddyl.

Import pinocchio or crocoddyl before mim_solvers: imported first, mim_solvers fails on a missing boost library
(libboost_atomic, which pinocchio's import loads)."""

from __future__ import annotations

from twin.plugin import Registry, hookimpl

__all__ = ["twin_register_planners"]


@hookimpl
def twin_register_planners(registry: Registry) -> None:
    """Register `croc` as a receding-horizon planner."""
    registry.add_planner(
        "croc",
        "twin_croc.planner:CrocPlanner",
        receding_horizon=True,
        extra="croc",
        description=(
            "MPC on Crocoddyl + mim-solvers (CSQP), nmpc's loop: mode seed (nmpc's formulation) or whole_arm"
            " (every link against every box of the scene)"
        ),
    )
