"""Work budgets: an anytime OMPL search that ends at the same point on every machine.

Why: RRT*, Informed RRT*, PRM*, BIT* and AORRTC improve their path for as long as they may run. Bounded by
the wall clock alone, how far they get (and so the path, or whether they find one) depends on the CPU they
are given: the same request and seed gave 1325 then 1480 trajectory samples (BIT*), success then timeout
(Informed RRT*) on a loaded machine. A budget that counts work ends the search where the same seed always
ends it. Two counts, either one ends it (parameters `max_state_checks`, `max_iterations`):

- state checks (`CheckCounter.checks`): configurations checked for collision, the states the planner samples
  plus the states along the motions it checks; the bulk of its cost;
- iterations (`CheckCounter.iterations`): how often the planner asked its termination condition, about once
  per iteration of RRT*'s, BIT*'s or AORRTC's loop. It bounds a search that stops checking states: AORRTC,
  once its path is near its cost bound, can reject samples for the rest of the time limit without checking
  one (1.2-1.6 million iterations a second).

Once the state checks are spent, the validity checker refuses every further state and motion
(`CheckCounter.check_limit`): a loop that never asks its termination condition ends too, at the same point
(AORRTC's connect loop in OMPL 2.0.1 can advance forever on some queries). The request's time limit stays a
hard cap on top (`ob.plannerOrTerminationCondition`): a machine too slow to spend the budget in time gets the
best path so far, or a timeout, as it would without a budget.

A search that stops at its first path (a repair of a grazing segment, `stop_at_first_solution`) ends by that
path, not by the clock: OMPL's anytime planners publish their path to the problem definition only when
solve() returns, so the exact-solution condition never ends their solve; they stop at their first path
when their optimisation objective is satisfied by any cost (`stop_at_first_path`). Without it, BIT*
repairing one segment of a robocup query ran to the request's deadline every time (~80k state checks in
0.9 s of a 1 s limit, with 0.05 s to spare), where a slower machine got less far or no path at all; with
it, the repair ends at its first path after ~3k checks.

The condition is a Python callable (`ob.PlannerTerminationCondition(fn)`) that the planner calls from the
thread that called solve(). OMPL's PRM and PRM* also hand their condition to a helper thread that looks for
a solution while the roadmap grows; with bindings that hold the GIL in solve(), a Python callable there
deadlocks. And PRM's solve() is not repeatable even when it stops at its first path: it switches between
growing and expanding its roadmap by the clock (0.4 s, then 0.2 s), and the helper thread finds the path
wherever the roadmap has got when it looks (the same request gave 2220 then 2964 state checks on a loaded
machine, and now and then another path). So PRM and PRM* are driven from here (`search_roadmap`): the
same grow / expand turns, counted in state checks, and the shortest path through the roadmap, the query
PRM itself answers.
"""

from __future__ import annotations

import math
import time
from types import TracebackType
from typing import Any

import numpy as np
import ompl.base as ob
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from twin_ompl.validity import CheckCounter

__all__ = ["EXPAND_CHECKS", "FIRST_PATH_CHECKS", "Budget", "roadmap_path", "search_roadmap", "stop_at_first_path"]

# PRM's solve() grows its roadmap for 2 x 0.2 s, then expands it for 0.2 s, and again; `search_roadmap`
# takes the same turns in state checks: 0.2 s of PRM* on the reference queries is ~12k checks here
EXPAND_CHECKS = 12_000
# how often a search that stops at its first path asks the roadmap for one: after FIRST_PATH_CHECKS state
# checks, and then each time the checks have grown by a quarter (PRM's first path on a blocked reference
# query takes ~1-3k checks: ~10 asks; reading the roadmap back costs 2-5 ms each)
FIRST_PATH_CHECKS = 200


class Budget:
    """The work one search may do from now on, counted on `counter`: `max_state_checks` more state checks
    and `max_iterations` more termination-condition queries (None: unbounded). Used as a context manager,
    it makes the validity checker refuse every state and motion once the checks are spent."""

    def __init__(self, counter: CheckCounter, max_state_checks: int | None, max_iterations: int | None):
        self.counter = counter
        self.max_state_checks = max_state_checks
        self.max_iterations = max_iterations
        self.check_end = counter.checks + max_state_checks if max_state_checks is not None else math.inf
        self.iteration_end = counter.iterations + max_iterations if max_iterations is not None else math.inf

    @property
    def spent(self) -> bool:
        c = self.counter
        return c.checks >= self.check_end or c.iterations >= self.iteration_end

    def describe(self) -> str:
        """'25000 state checks, 100000 iterations' (the limits), for failure reasons."""
        parts = []
        if self.max_state_checks is not None:
            parts.append(f"{self.max_state_checks} state checks")
        if self.max_iterations is not None:
            parts.append(f"{self.max_iterations} iterations")
        return ", ".join(parts) or "no limit"

    def condition(self, check_end: float = math.inf) -> Any:
        """A termination condition that counts one iteration each time it is asked and is true once the
        budget is spent (or, for one turn of a longer search, once the checks reach `check_end`)."""
        c = self.counter
        checks_end, iterations_end = min(self.check_end, check_end), self.iteration_end

        def spent() -> bool:
            c.iterations += 1
            return c.states + c.configs >= checks_end or c.iterations >= iterations_end

        return ob.PlannerTerminationCondition(spent)

    def __enter__(self) -> Budget:
        self.counter.check_limit = self.check_end
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, tb: TracebackType | None) -> None:
        self.counter.check_limit = math.inf


def stop_at_first_path(ss: Any) -> None:
    """Make the planner of the set-up SimpleSetup `ss` stop at its first exact path: its optimisation
    objective (an anytime planner's; the others have none and stop there anyway) is satisfied by any cost,
    which RRT*, Informed RRT*, BIT* and AORRTC test inside their loop (see the module docstring)."""
    pdef = ss.getProblemDefinition()
    if pdef.hasOptimizationObjective():
        pdef.getOptimizationObjective().setCostThreshold(ob.Cost(math.inf))


def search_roadmap(ss: Any, si: Any, budget: Budget, deadline: float, *, first_path: bool) -> np.ndarray | None:
    """The search of a PRM-family planner under `budget` and the wall-clock `deadline` (perf_counter
    seconds): the shortest path (m, 6) through its roadmap from the start to the goal, or None.

    `ss` is a set-up SimpleSetup whose planner is PRM or PRM*. Its solve(), with a condition that is already
    true, adds the start and the goal as milestones (and returns before any helper thread asks the
    condition); then the roadmap grows and expands by turns, 2 * EXPAND_CHECKS and EXPAND_CHECKS state checks
    each, as PRM's solve() does by the clock, until the budget is spent or the deadline passes. With
    `first_path` (PRM, a repair, PRM* told to stop at its first path) the roadmap is asked for a path after
    FIRST_PATH_CHECKS state checks and whenever they have grown by a quarter since, and the first one ends
    the search (PRM's helper thread asks every millisecond, wherever the roadmap has got by then)."""
    planner = ss.getPlanner()
    ss.solve(ob.timedPlannerTerminationCondition(0.0))
    counter = budget.counter
    grow, idle = True, 0
    checks0 = counter.checks
    phase_end = checks0 + 2 * EXPAND_CHECKS
    while not budget.spent and idle < 2:
        if first_path:
            found = roadmap_path(planner, si)
            if found is not None:
                return found
        remaining = deadline - time.perf_counter()
        if remaining <= 0:
            break
        before = counter.checks
        ask_at = before + max(FIRST_PATH_CHECKS, (before - checks0) // 4)
        turn_end = min(phase_end, ask_at) if first_path else phase_end
        ptc = ob.plannerOrTerminationCondition(
            budget.condition(turn_end), ob.timedPlannerTerminationCondition(remaining)
        )
        if grow:
            planner.growRoadmapPtc(ptc)
        else:
            planner.expandRoadmapPtc(ptc)
        idle = idle + 1 if counter.checks == before else 0  # neither kind of turn adds anything: stop
        if counter.checks >= phase_end or idle:
            grow = not grow
            phase_end = counter.checks + (2 if grow else 1) * EXPAND_CHECKS
    return roadmap_path(planner, si)


def roadmap_path(planner: Any, si: Any) -> np.ndarray | None:
    """(m, 6) the shortest path (joint-space L2, PRM's path length cost) through `planner`'s roadmap from its
    start to its nearest goal milestone, or None when they are not connected. Every edge of the roadmap
    is a motion the planner checked."""
    data = ob.PlannerData(si)
    planner.getPlannerData(data)
    n = data.numVertices()
    if n == 0 or data.numStartVertices() == 0 or data.numGoalVertices() == 0:
        return None
    X = np.array([data.getVertex(i).getState()[0:6] for i in range(n)], dtype=float)
    pairs = [(i, j) for i in range(n) for j in data.getEdges(i)]
    if not pairs:
        return None
    E = np.array(pairs, dtype=np.int64)
    E = np.unique(np.concatenate([E, E[:, ::-1]]), axis=0)  # both directions, each once
    # the smallest positive weight keeps an edge between coincident states (csgraph drops zeros)
    w = np.maximum(np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1), np.finfo(float).tiny)
    graph = csr_matrix((w, (E[:, 0], E[:, 1])), shape=(n, n))
    s = data.getStartIndex(0)
    dist, pred = dijkstra(graph, directed=True, indices=s, return_predecessors=True)
    goals = [data.getGoalIndex(k) for k in range(data.numGoalVertices())]
    g = min(goals, key=lambda k: (dist[k], k))
    if not np.isfinite(dist[g]):
        return None
    order = [g]
    while order[-1] != s:
        order.append(int(pred[order[-1]]))
    return X[order[::-1]]
