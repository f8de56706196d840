"""OMPL sampling planners as one-shot `twin` planners (`ompl.rrtconnect`, `ompl.rrtstar`, ...).

One `plan(request, scene)`:

1. start and goal checks on the scene as given (typed failures, no sampling): start outside the limits
   or in collision -> INVALID_START; joint goal outside the limits or in collision -> INVALID_GOAL; pose
   goal -> every IK solution (all 2*pi wraps) inside the sampling bounds that is collision-free, nearest
   first; none -> INVALID_GOAL saying whether the pose is out of reach or every solution collides (and
   with what);
2. planning happens on the scene with its environment inflated by `clearance_m` (5 mm; see
   `twin.plugin.padded_scene`), unless the start or every goal lies closer than that;
3. only with `try_direct: true` (off by default: the planner being compared is what plans): the straight
   joint-space motion to one of the nearest goals, when free, is the answer without sampling;
4. otherwise OMPL plans in a RealVectorStateSpace(6) whose bounds are `joint_range`: 'compact' by
   default = [-pi, pi] per joint widened to start +- pi and to a joint goal, clipped to the limits. Every
   IK branch keeps a representative within pi of the start in each joint, and the sampled volume is ~1/20
   of the full +-2pi box (elbow +-pi), which RRT-style planners explore much faster; 'full' = the limits;
5. bounded OMPL shortcutting (rope shortcut, reduceVertices, collapseCloseVertices);
6. a retimer plugin (`toppra` by default, or the config block's `retimer:`) times the path;
7. the trajectory is checked every `verify_resolution_rad` / `verify_resolution_m` on the inflated
   scene; if a straight segment grazes something between the states checked while planning, that segment
   is planned again at the fine resolution, by the same planner inside the segment's box widened by 0.3 rad,
   and spliced in (`max_repairs`); if only the timing spline cuts a corner, the path is re-timed through
   denser waypoints.

Time: the request's `time_limit_s` (or the smaller `time_limit_s` parameter) bounds the whole call up to
the final retiming and check: sampling stops early enough to leave up to a quarter of the limit for steps
5-7, and past the sampling deadline every new validity query answers "invalid", so planners that test
their termination condition only between long batches stop promptly too. The retimer is warmed up when
the planner is built (TOPP-RA's first import costs ~1 s), not inside a request's limit. Within that limit
the optimising planners search until their work budget is spent (`max_state_checks`, `max_iterations`:
state checks and iterations counted, `twin_ompl.budget`), so where they stop does not depend on the
machine's speed; the others stop at their first path. PRM and PRM* grow their roadmap from here, in turns
counted in state checks (OMPL's own loop times them by the clock and finds the path from a helper thread).

Seeding: OMPL's global seed generator is re-seeded (`ou.RNG.setSeed`) with the request's seed before the
state space is built, so every random generator of the run starts from it (the space's random projection
KPIECE uses, the planner's, the path simplifier's); the same request and scene give the same path, whatever
was planned before in the process. The seed is process-global: do not plan with OMPL from two threads at
once (the FCL scene is not thread-safe either).

OMPL 2.0.1 specifics: planners are found by `getattr(ompl.geometric, name)`; LazyPRMstar and BiTRRT are
not bound (`unavailable_reason()` says so without building a planner, and creating one raises
DependencyMissing); the PRM family and BFMT* get only the nearest goal configuration (see
`PlannerSpec.single_goal`: the PRM goal-adding helper thread deadlocks with Python callbacks, BFMT*
crashes with a goal set).

The pieces: `twin_ompl.params` (one parameter model per planner), `twin_ompl.validity` (FCL state and
motion checks, the inflated scene), `twin_ompl.problem` (step 4: bounds, OMPL space, start and goals, the
seeded planner), `twin_ompl.budget` (how a search ends: work budgets, the roadmap search of PRM and
PRM*), `twin_ompl.postprocess` (steps 5-7); this module holds the planner class and its loop.
"""

from __future__ import annotations

import logging
import math
import time
from contextlib import nullcontext
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import ompl.base as ob
import ompl.geometric as og

from twin.plugin import (
    ConfigError,
    DependencyMissing,
    MotionRequest,
    MotionResult,
    PathPlanner,
    PlanningError,
    PlanningScene,
    QueryEnds,
    Retimer,
    SphereModel,
    Status,
    URArm,
    add_time,
    jerk_limited,
    padded_scene,
    path_length,
    query_ends,
    timed_and_checked,
    warm_up_checks,
    warm_up_retimer,
)
from twin_ompl.budget import Budget, search_roadmap, stop_at_first_path
from twin_ompl.params import OMPL_PARAMS, PLANNER_SPECS, OmplParams, OptimizingOmplParams, PlannerSpec, params_model
from twin_ompl.postprocess import simplify
from twin_ompl.problem import geometric_path, repair_bounds, simple_setup, space_information, states
from twin_ompl.validity import CheckCounter

if TYPE_CHECKING:
    from twin.plugin import PluginContext

__all__ = [
    "AORRTC",
    "BFMT",
    "BKPIECE1",
    "FMT",
    "KPIECE1",
    "LBKPIECE1",
    "PRM",
    "RRT",
    "BITstar",
    "BiTRRT",
    "InformedRRTstar",
    "LazyPRMstar",
    "OmplPlanner",
    "PRMstar",
    "RRTConnect",
    "RRTstar",
    "SORRTstar",
]

log = logging.getLogger("twin")

# kept free of sampling (for shortcutting, retiming and the final check) when a planner would use all of
# its time: a quarter of the limit, at most this many seconds
_POST_RESERVE_S = 0.25
_REPAIR_RESERVE_S = 0.05  # a repaired path needs only retiming and the final check
_DIRECT_GOALS = 3  # nearest goals tried with a straight motion


@dataclass
class _Attempt:
    """What one sampling run produced (path or a failure) and what it cost."""

    path: np.ndarray | None = None
    status: Status = Status.NO_SOLUTION
    reason: str = ""
    direct: bool = False
    goal_index: int | None = None
    budget_spent: bool | None = None  # None: the search had no work budget


class OmplPlanner(PathPlanner):
    """A one-shot planner around one OMPL geometric planner (the subclasses below fix which one).

    `params` is the planner's pydantic model (`Params`), `context` the plugin context (settings,
    kinematics, registry). `plan(request, scene)` never raises for "no path": it returns a status.
    A `PathPlanner`: a config block's `retimer:` arrives through `set_retimer` (`self.retimer`); without
    one, the retimer named in `params.retimer` times the path.
    """

    spec: PlannerSpec = PLANNER_SPECS["RRTConnect"]
    Params: type[OmplParams] = params_model(spec)

    def __init__(self, params: OmplParams | None, context: PluginContext):
        reason = self.unavailable_reason()
        if reason is not None:
            raise DependencyMissing(reason)
        self.params = params if params is not None else self.Params()
        self.context = context  # the robot it plans for: no default arm (a UR10e config plans a UR10e)
        self.kin: URArm = context.kinematics
        self.settings = context.settings
        self._planner_setters = self._setters()
        self._default_retimer: Retimer | None = None
        self._warm_up()

    # ---- configuration ---------------------------------------------------------------------------
    @classmethod
    def unavailable_reason(cls) -> str | None:
        """None when the installed OMPL bindings expose this planner's class; else why not (the registry
        asks this for `twin planners` without building a planner)."""
        if cls.spec.defect is not None:
            return f"planner 'ompl.{cls.spec.ompl_class.lower()}' is disabled: {cls.spec.defect}"
        if hasattr(og, cls.spec.ompl_class):
            return None
        import ompl

        version = getattr(ompl, "__version__", "") or _dist_version()
        return (
            f"planner 'ompl.{cls.spec.ompl_class.lower()}' needs ompl.geometric.{cls.spec.ompl_class}, "
            f"which the installed OMPL {version} Python bindings do not expose (upstream ompl/ompl#1419). "
            "Install an OMPL build whose "
            "bindings include it, or pick another ompl.* planner (`twin planners`)."
        )

    @property
    def name(self) -> str:
        return f"ompl.{self.spec.ompl_class.lower()}"

    def _setters(self) -> list[tuple[str, Any]]:
        """(setter name, value) for every OMPL parameter set in params; a setter the binding lacks is an error."""
        cls = getattr(og, self.spec.ompl_class)
        out = []
        for pname in self.spec.params:
            value = getattr(self.params, pname)
            if value is None:
                continue
            names = OMPL_PARAMS[pname].setter
            candidates = (names,) if isinstance(names, str) else names
            setter = next((s for s in candidates if hasattr(cls, s)), None)
            if setter is None:
                raise ConfigError(
                    f"{self.name}: parameter {pname!r} is not settable in this OMPL build "
                    f"({' / '.join(candidates)} missing)"
                )
            out.append((setter, value))
        return out

    def set_retimer(self, retimer: Retimer) -> None:
        """Use this retimer (the config block's `retimer:`) instead of `params.retimer`; warmed up at once."""
        super().set_retimer(retimer)
        self._warm_up()

    def _warm_up(self) -> None:
        """Time one tiny path now, so a retimer's first-use imports (TOPP-RA ~1 s) are paid at construction,
        not inside the first request's time limit; load the final check's compiled proof (`warm_up_checks`)."""
        warm_up_checks(self.context.robot)
        warm_up_retimer(self._timer())  # an unknown retimer name or bad retimer params fail here

    @property
    def jerk_limited(self) -> bool:
        """As jerk-limited as the retimer that actually times its paths: the config's, else the one
        `params.retimer` names (the default, TOPP-RA, is not)."""
        return jerk_limited(self._timer())  # the module-level twin.plugin.jerk_limited

    def _timer(self) -> Retimer:
        """The retimer that times paths: the config's (`self.retimer`), else the one `params.retimer` names."""
        if self.retimer is not None:
            return self.retimer
        if self._default_retimer is None:
            registry = self.context.registry
            self._default_retimer = registry.retimer(self.params.retimer, self.params.retimer_params, self.context)
        return self._default_retimer

    # ---- the protocol ----------------------------------------------------------------------------
    def plan(self, request: MotionRequest, scene: PlanningScene) -> MotionResult:
        """Plan `request` in `scene`; "no path" is a status with a reason, never an exception."""
        t0 = time.perf_counter()
        limit = (
            request.time_limit_s
            if self.params.time_limit_s is None
            else min(request.time_limit_s, self.params.time_limit_s)
        )
        deadline = t0 + limit
        result = self._plan(request, scene, t0, deadline, limit)
        return replace(result, planning_time_s=time.perf_counter() - t0)

    def _plan(
        self, request: MotionRequest, scene: PlanningScene, t0: float, deadline: float, limit: float
    ) -> MotionResult:
        p = self.params
        kin = self.kin
        info: dict[str, Any] = {"planner": self.name, "seed": request.seed}

        # 1. start and goals ------------------------------------------------------------------------
        ends = query_ends(kin, scene, request, p)
        if not isinstance(ends, QueryEnds):
            return MotionResult(ends[0], ends[1], info=info)
        start, bounds, goals = ends.start, ends.bounds, ends.goals
        # plan (and check finely) on the scene inflated by the clearance, unless start or goal lie closer
        clearance = p.clearance_m
        plan_scene = padded_scene(scene, clearance) if clearance > 0 else None
        if plan_scene is not None:
            far = ~plan_scene.in_collision_batch(goals)
            if plan_scene.in_collision(start) or not far.any():
                plan_scene = None
            else:
                goals = goals[far]
        if plan_scene is None:
            plan_scene, clearance = scene, 0.0
        info.update(goal_count=int(goals.shape[0]), bounds=bounds.tolist(), clearance_m=clearance)
        search_on, info["collision_model"] = self._search_model(scene, clearance, start, goals)
        scene = plan_scene

        # 2.-6. plan, simplify, retime, verify; repair a grazing segment by planning it finer -----------
        counter = CheckCounter()
        timings: dict[str, float] = {}
        att = self._attempt(
            start,
            goals,
            bounds,
            search_on or scene,
            request.seed,
            p.validity_resolution_rad,
            counter,
            deadline,
            limit,
            timings,
        )
        info.update(direct=att.direct)
        if att.budget_spent is not None:
            info.update(budget_spent=att.budget_spent)
        if att.path is None:
            return MotionResult(att.status, att.reason, info=self._info(info, counter, timings))
        path = att.path
        info.update(goal_index=att.goal_index)
        repairs = 0
        while True:
            traj, outcome, segment = timed_and_checked(
                path, self._timer(), request, scene, kin, p.verify_resolution_rad, p.verify_resolution_m, timings
            )
            info.update(repairs=repairs, waypoints=int(path.shape[0]), path_length_rad=path_length(path))
            if traj is not None:
                info.update(duration_s=traj.duration)
                reason = "ok (straight joint motion)" if att.direct and repairs == 0 else "ok"
                return MotionResult(Status.SUCCESS, reason, traj, path=path, info=self._info(info, counter, timings))
            if segment is None or repairs >= p.max_repairs or time.perf_counter() >= deadline:
                status = Status.LIMIT_VIOLATION if outcome.startswith("retiming failed") else Status.COLLISION
                return MotionResult(
                    status, f"{outcome} (after {repairs} repairs)", path=path, info=self._info(info, counter, timings)
                )
            # the straight segment grazes an obstacle between the states checked while planning: plan that
            # segment again at the final check's resolution and splice the detour in
            repairs += 1
            a, b = path[segment], path[segment + 1]
            fine = p.verify_resolution_rad
            sub = self._attempt(
                a,
                b[None],
                repair_bounds(a, b, bounds),
                search_on or scene,
                request.seed + 7919 * repairs,
                fine,
                counter,
                deadline,
                limit,
                timings,
                repair=True,
            )
            if sub.path is None:
                return MotionResult(
                    Status.COLLISION if sub.status is Status.NO_SOLUTION else sub.status,
                    f"{outcome}; replanning segment {segment} at {fine:g} rad failed: {sub.reason}",
                    path=path,
                    info=self._info(info, counter, timings),
                )
            path = np.concatenate([path[: segment + 1], sub.path[1:-1], path[segment + 1 :]])
            log.debug("%s: segment %d grazed an obstacle; replanned it at %.4f rad", self.name, segment, fine)

    def _search_model(
        self, scene: PlanningScene, clearance: float, start: np.ndarray, goals: np.ndarray
    ) -> tuple[SphereModel | None, str]:
        """The planning model the search checks on with `collision_model: spheres` (None: the FCL scene), and
        the model's name for the result's info. The exact scene decides a query whose start or every goal the
        cover refuses (closer to something than the cover's overshoot)."""
        if self.params.collision_model != "spheres" or not isinstance(scene, PlanningScene):
            return None, "exact"
        model = scene.sphere_model(clearance)
        if model.in_collision(start) or model.in_collision_batch(goals).all():
            return None, "exact (the sphere cover refuses the start or every goal)"
        return model, "spheres"

    @staticmethod
    def _info(info: dict[str, Any], counter: CheckCounter, timings: dict[str, float]) -> dict[str, Any]:
        if counter.error is not None:
            raise PlanningError(f"the validity check raised {counter.error!r}") from counter.error
        return dict(
            info,
            states_checked=counter.states,
            motions_checked=counter.motions,
            configs_checked=counter.configs,
            iterations=counter.iterations,
            **{f"{k}_time_s": v for k, v in timings.items()},
        )

    # ---- steps -------------------------------------------------------------------------------------
    def _attempt(
        self,
        start: np.ndarray,
        goals: np.ndarray,
        bounds: np.ndarray,
        scene: PlanningScene | SphereModel,
        seed: int,
        resolution: float,
        counter: CheckCounter,
        deadline: float,
        limit: float,
        timings: dict[str, float],
        repair: bool = False,
    ) -> _Attempt:
        """One sampling run from `start` to the goal set at `resolution`; adds its timings to `timings`.
        A `repair` run (one short segment) keeps less time in reserve and stops at its first path."""
        p = self.params
        si, mv = space_information(bounds, scene, resolution, counter, seed)

        if p.try_direct:
            t = time.perf_counter()
            for i in range(min(_DIRECT_GOALS, goals.shape[0])):
                if mv.motion_free(start, goals[i]):
                    add_time(timings, "direct", t)
                    return _Attempt(np.stack([start, goals[i]]), Status.SUCCESS, direct=True, goal_index=i)
            add_time(timings, "direct", t)

        # decide before any OMPL planner exists: a planner destroyed without setup() can crash (AORRTC does)
        reserve = min(_REPAIR_RESERVE_S, 0.05 * limit) if repair else min(_POST_RESERVE_S, 0.25 * limit)
        budget_s = deadline - time.perf_counter() - reserve
        if budget_s <= 0.001:
            return _Attempt(status=Status.TIMEOUT, reason=f"no time left to sample within {limit:.3g} s")
        if self.spec.single_goal:
            goals = goals[:1]  # see PlannerSpec.single_goal
        ss = simple_setup(si, start, goals, self.spec.ompl_class, self._planner_setters)
        first_only = repair or (isinstance(p, OptimizingOmplParams) and p.stop_at_first_solution)
        work = self._work_budget(counter, repair, limit)
        log.debug(
            "%s: sampling for up to %.3f s (work budget: %s), %d goal(s), resolution %.4f rad",
            self.name,
            budget_s,
            "none" if work is None else work.describe(),
            goals.shape[0],
            resolution,
        )
        t = time.perf_counter()
        counter.deadline = t + budget_s
        roadmap: np.ndarray | None = None
        status: Any = None
        try:
            with work if work is not None else nullcontext():
                if self.spec.solution_thread:  # PRM, PRM*: grown from here (twin_ompl.budget)
                    first_path = first_only or not self.spec.optimizing
                    budget = work or Budget(counter, None, None)
                    roadmap = search_roadmap(ss, si, budget, counter.deadline, first_path=first_path)
                else:
                    ptc = ob.timedPlannerTerminationCondition(budget_s)
                    if first_only:
                        exact = ob.exactSolnPlannerTerminationCondition(ss.getProblemDefinition())
                        ptc = ob.plannerOrTerminationCondition(ptc, exact)
                        stop_at_first_path(ss)  # an anytime planner: its path, not the clock, ends the search
                    if work is not None:
                        ptc = ob.plannerOrTerminationCondition(ptc, work.condition())
                    status = ss.solve(ptc)
                    del ptc  # holds the budget's Python callable: let it go with the solve
        finally:
            counter.deadline = math.inf
        add_time(timings, "solve", t)
        spent = None if work is None else work.spent
        if counter.error is not None:
            return _Attempt(reason=f"the validity check raised {counter.error!r}", budget_spent=spent)
        found = roadmap is not None if self.spec.solution_thread else ss.haveExactSolutionPath()
        if not found:
            elapsed = time.perf_counter() - t
            if status is None:
                what = "no path through the roadmap"
            else:
                what = status.asString() if hasattr(status, "asString") else str(status)
            checked = f"{counter.states} states, {counter.motions} motions checked"
            if work is not None and spent:
                return _Attempt(
                    status=Status.NO_SOLUTION,
                    reason=(
                        f"{self.spec.ompl_class} found no path within its work budget of {work.describe()} "
                        f"({what}; {checked})"
                    ),
                    budget_spent=spent,
                )
            if elapsed >= budget_s * 0.95:
                return _Attempt(
                    status=Status.TIMEOUT,
                    reason=f"{self.spec.ompl_class} found no path within {limit:.3g} s ({what}; {checked})",
                    budget_spent=spent,
                )
            return _Attempt(status=Status.NO_SOLUTION, reason=f"{self.spec.ompl_class}: {what}", budget_spent=spent)
        path = geometric_path(si, roadmap) if roadmap is not None else ss.getSolutionPath()
        if p.simplify:
            t = time.perf_counter()
            simplify(si, path, p, deadline)  # bounded passes; no refusals here (OMPL would warn of "touching")
            add_time(timings, "simplify", t)
        waypoints = states(path)
        waypoints[0] = start  # OMPL copies states exactly; make the ends bit-identical anyway
        gi = int(np.argmin(np.abs(goals - waypoints[-1]).max(axis=1)))
        waypoints[-1] = goals[gi]
        return _Attempt(waypoints, Status.SUCCESS, goal_index=gi, budget_spent=spent)

    def _work_budget(self, counter: CheckCounter, repair: bool, time_limit_s: float) -> Budget | None:
        """The work budget of this search, or None: a repair and a planner that stops at its first path end by
        that path or the time limit. `max_state_checks` and `max_iterations` are per second of the request's
        time limit (a 2 s limit buys twice the search of a 1 s one: still a count, so still deterministic)."""
        if repair or not isinstance(self.params, OptimizingOmplParams):
            return None
        checks, iterations = self.params.max_state_checks, self.params.max_iterations
        if checks is None and iterations is None:
            return None
        scale = max(time_limit_s, 1e-3)
        return Budget(
            counter,
            None if checks is None else max(1, round(checks * scale)),
            None if iterations is None else max(1, round(iterations * scale)),
        )


def _dist_version() -> str:
    try:
        from importlib.metadata import version

        return version("ompl")
    except Exception:  # noqa: BLE001
        return "(unknown version)"


def _planner_class(spec: PlannerSpec) -> type[OmplPlanner]:
    doc = f"`ompl.{spec.ompl_class.lower()}`: OMPL's {spec.ompl_class} with FCL validity, IK goal sets and retiming."
    return type(
        spec.ompl_class,
        (OmplPlanner,),
        {"spec": spec, "Params": params_model(spec), "__doc__": doc, "__module__": __name__},
    )


RRTConnect = _planner_class(PLANNER_SPECS["RRTConnect"])
RRT = _planner_class(PLANNER_SPECS["RRT"])
RRTstar = _planner_class(PLANNER_SPECS["RRTstar"])
InformedRRTstar = _planner_class(PLANNER_SPECS["InformedRRTstar"])
SORRTstar = _planner_class(PLANNER_SPECS["SORRTstar"])
PRM = _planner_class(PLANNER_SPECS["PRM"])
PRMstar = _planner_class(PLANNER_SPECS["PRMstar"])
LazyPRMstar = _planner_class(PLANNER_SPECS["LazyPRMstar"])
BITstar = _planner_class(PLANNER_SPECS["BITstar"])
AORRTC = _planner_class(PLANNER_SPECS["AORRTC"])
KPIECE1 = _planner_class(PLANNER_SPECS["KPIECE1"])
BKPIECE1 = _planner_class(PLANNER_SPECS["BKPIECE1"])
LBKPIECE1 = _planner_class(PLANNER_SPECS["LBKPIECE1"])
BiTRRT = _planner_class(PLANNER_SPECS["BiTRRT"])
FMT = _planner_class(PLANNER_SPECS["FMT"])
BFMT = _planner_class(PLANNER_SPECS["BFMT"])
