"""The OMPL side of one sampling run: the state space with the scene's validity checks, the start and goal
states, the seeded planner object, and the planner's path read back as an array.

Why here, apart from the planner class: this is everything that speaks OMPL's Python bindings (2.0.1) when a
problem is set up; `twin_ompl.planner` decides what to plan and `twin_ompl.postprocess` what to do with the
path. The sampling bounds (`joint_range`) are every path planner's (`twin.plugin.sampling_bounds`).

Seeding: OMPL's global seed generator is re-seeded (`ou.RNG.setSeed`) with the request's seed before the
state space is built, so every random generator of the run starts from it: the one the state space draws
in `SpaceInformation.setup()` (the random projection KPIECE1, BKPIECE1 and LBKPIECE1 grid the space by),
the planner's, and the path simplifier's created after it. Seeded any later, the projection came from
wherever earlier requests in the process had left the seed sequence, and the same request planned twice
gave two paths. The seed is process-global: do not plan with OMPL from two threads at once.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import ompl.base as ob
import ompl.geometric as og
import ompl.util as ou

from twin_ompl.validity import CheckCounter, SceneMotionValidator, state_validity_checker

if TYPE_CHECKING:
    from twin.plugin import PlanningScene, SphereModel

__all__ = [
    "geometric_path",
    "repair_bounds",
    "seed_ompl",
    "simple_setup",
    "space_information",
    "states",
]

ou.setLogLevel(ou.LogLevel.LOG_WARN)

# a repair plans one grazing segment again inside the segment's own box widened by this much per joint: the
# detour around a graze is local, and a small box keeps batch planners (FMT*, BFMT*), whose edges span
# their whole sampling box, from checking long edges at the fine resolution
_REPAIR_MARGIN_RAD = 0.3


def repair_bounds(a: np.ndarray, b: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """(6, 2) sampling bounds for replanning the segment a -> b: its box widened by _REPAIR_MARGIN_RAD,
    inside `bounds`."""
    lo = np.maximum(np.minimum(a, b) - _REPAIR_MARGIN_RAD, bounds[:, 0])
    hi = np.minimum(np.maximum(a, b) + _REPAIR_MARGIN_RAD, bounds[:, 1])
    return np.stack([lo, hi], axis=1)


def space_information(
    bounds: np.ndarray, scene: PlanningScene | SphereModel, resolution_rad: float, counter: CheckCounter, seed: int
) -> tuple[Any, SceneMotionValidator]:
    """OMPL SpaceInformation over RealVectorStateSpace(6) inside `bounds` (6, 2), with the scene's state
    validity checker and batched motion validator (states `resolution_rad` apart), set up; and the validator.
    OMPL is re-seeded with `seed` first: setting the space up draws its random default projection."""
    seed_ompl(seed)
    space = ob.RealVectorStateSpace(6)
    rb = ob.RealVectorBounds(6)
    for j in range(6):
        rb.setLow(j, float(bounds[j, 0]))
        rb.setHigh(j, float(bounds[j, 1]))
    space.setBounds(rb)
    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(state_validity_checker(scene, counter))
    mv = SceneMotionValidator(si, scene, resolution_rad, counter)
    si.setMotionValidator(mv)
    si.setup()
    return si, mv


def seed_ompl(seed: int) -> None:
    """Re-seed OMPL's seed generator (seed 0 is OMPL's 'random'; avoid it). Its 'already started'
    complaint is expected here: re-seeding still restarts the sequence of seeds for new generators."""
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LogLevel.LOG_NONE)
    try:
        ou.RNG.setSeed(int(seed) % 2_147_483_647 + 1)
    finally:
        ou.setLogLevel(level)


def simple_setup(
    si: Any, start: np.ndarray, goals: np.ndarray, ompl_class: str, setters: Sequence[tuple[str, Any]]
) -> Any:
    """A set-up `og.SimpleSetup`: start state, goal (one state, or a goal set of the rows of `goals` (k, 6)),
    and a new `og.<ompl_class>` planner with the (setter, value) pairs applied. Its random generators
    continue the sequence `space_information` seeded."""
    ss = og.SimpleSetup(si)
    st = si.allocState()
    st[0:6] = start.tolist()
    ss.setStartState(st)
    if goals.shape[0] == 1:
        g = si.allocState()
        g[0:6] = goals[0].tolist()
        goal: Any = ob.GoalState(si)
        goal.setState(g)
    else:
        goal = ob.GoalStates(si)
        for q in goals:
            g = si.allocState()
            g[0:6] = q.tolist()
            goal.addState(g)
    ss.setGoal(goal)
    planner = getattr(og, ompl_class)(si)
    for setter, value in setters:
        getattr(planner, setter)(value)
    ss.setPlanner(planner)
    ss.setup()
    return ss


def geometric_path(si: Any, waypoints: np.ndarray) -> Any:
    """An `og.PathGeometric` through the rows of `waypoints` (m, 6)."""
    out = []
    for q in waypoints:
        st = si.allocState()
        st[0:6] = q.tolist()
        out.append(st)
    return og.PathGeometric(si, out)


def states(path: Any) -> np.ndarray:
    """(m, 6) the states of an OMPL geometric path."""
    return np.array([path.getState(i)[0:6] for i in range(path.getStateCount())], dtype=float)
