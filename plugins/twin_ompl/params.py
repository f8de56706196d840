"""Parameters of the OMPL planners: one pydantic model per planner, built from one table.

Why a table: OMPL 2.0.1's Python bindings cannot return a planner's `ParamSet` (`params()` raises), so
the names OMPL declares for each planner (`range`, `goal_bias`, `rewire_factor`, ...) are listed here
with their types, bounds and the setter that applies them. Each planner's model accepts exactly its own
OMPL parameters plus the options every `ompl.*` planner shares (`OmplParams`), and rejects anything
else: the registry turns that into a ConfigError that lists the allowed names. When a planner is created
the setters are looked up on the installed binding, so a parameter the binding lacks is a clear error too
(OMPL 2.0.1 binds no setter for BFMT*'s `balanced` and `optimality`).

`try_direct` is off by default: the planner being compared is what plans. Turned on in a planner block, a
straight joint-space motion that is free is returned without sampling (a shortcut for task stages, not for
comparing planners).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from pydantic import Field, create_model

from twin.plugin import PathPlannerParams

__all__ = [
    "OMPL_PARAMS",
    "PLANNER_SPECS",
    "OmplParam",
    "OmplParams",
    "OptimizingOmplParams",
    "PlannerSpec",
    "params_model",
]


class OmplParams(PathPlannerParams):
    """Options shared by every `ompl.*` planner (units in the names; None = derived, see each field): every path
    planner's (`twin.plugin.PathPlannerParams`) and these."""

    collision_model: Literal["exact", "spheres"] = Field(
        "spheres",
        description=(
            "what the search checks states and motions on: 'exact' = the FCL scene (behind the sphere filter); "
            "'spheres' = the planning model (the robot's sphere cover, touching = in collision, compiled, no "
            "FCL; a query whose start or every goal the cover refuses is planned on 'exact'). The path is "
            "verified on the FCL scene either way"
        ),
    )
    validity_resolution_rad: float = Field(
        0.02, gt=0, le=0.5, description="largest joint step between two checked states of a motion (max-abs, rad)"
    )
    try_direct: bool = Field(
        False,
        description=(
            "return the straight joint-space motion when it is free, without sampling (off: the planner being "
            "compared is what plans; turn it on per planner block for a quick shortcut)"
        ),
    )
    simplify: bool = Field(True, description="shortcut the path with OMPL's PathSimplifier before retiming")
    simplify_max_steps: int = Field(
        20,
        ge=1,
        le=10_000,
        description="cap on vertex-reduction attempts per simplification pass (bounded, so seeded runs repeat)",
    )
    simplify_passes: int = Field(
        1,
        ge=1,
        le=10,
        description="rope shortcut + vertex reduction + collapse passes (stops early when nothing changes)",
    )
    max_repairs: int = Field(
        2, ge=0, le=5, description="replans at 4x finer validity resolution if the final check finds a collision"
    )


@dataclass(frozen=True)
class OmplParam:
    """One OMPL planner parameter: python type, pydantic Field, and the binding's setter name (or the
    candidate names, first found wins: OMPL names one parameter's setter differently in different planners)."""

    type: Any
    field: Any
    setter: str | tuple[str, ...]


def _p(tp: Any, setter: str | tuple[str, ...], description: str, **bounds: Any) -> OmplParam:
    return OmplParam(tp | None, Field(None, description=description, **bounds), setter)


# OMPL's declared parameter names (ParamSet keys) -> setter on the bound planner class
OMPL_PARAMS: dict[str, OmplParam] = {
    "range": _p(
        float,
        "setRange",
        "longest motion added in one step (joint-space L2, rad); None = OMPL's 20% of the extent",
        gt=0,
    ),
    "goal_bias": _p(float, "setGoalBias", "probability of sampling the goal", ge=0, le=1),
    "intermediate_states": _p(bool, "setIntermediateStates", "keep the states passed on each extension in the tree"),
    "rewire_factor": _p(float, "setRewireFactor", "scales the rewiring radius / k", gt=0),
    "use_k_nearest": _p(
        bool, ("setKNearest", "setNearestK"), "connect to the k nearest instead of those within a radius"
    ),
    "delay_collision_checking": _p(bool, "setDelayCC", "check motions of rewiring candidates lazily"),
    "tree_pruning": _p(bool, "setTreePruning", "prune the tree by the current best cost"),
    "prune_threshold": _p(float, "setPruneThreshold", "fractional cost change that triggers pruning", ge=0, le=1),
    "informed_sampling": _p(bool, "setInformedSampling", "sample the informed set only"),
    "sample_rejection": _p(bool, "setSampleRejection", "reject samples that cannot improve the solution"),
    "new_state_rejection": _p(bool, "setNewStateRejection", "reject new states that cannot improve the solution"),
    "use_admissible_heuristic": _p(bool, "setAdmissibleCostToCome", "admissible cost-to-come heuristic for pruning"),
    "focus_search": _p(bool, "setFocusSearch", "focus the search on the informed set"),
    "number_sampling_attempts": _p(int, "setNumSamplingAttempts", "attempts to find an informed sample", ge=1),
    "ordered_sampling": _p(bool, "setOrderedSampling", "sort sample batches by heuristic cost"),
    "ordering_batch_size": _p(int, "setBatchSize", "batch size of ordered sampling", ge=1),
    "max_nearest_neighbors": _p(int, "setMaxNearestNeighbors", "roadmap connections per new vertex", ge=1),
    "samples_per_batch": _p(int, "setSamplesPerBatch", "samples per BIT* batch", ge=1),
    "use_bitstar_k_nearest": _p(bool, "setUseKNearest", "BIT* k-nearest instead of r-disc graph"),
    "use_graph_pruning": _p(bool, "setPruning", "prune the BIT* graph by the informed set"),
    "prune_threshold_as_fractional_cost_change": _p(
        float, "setPruneThresholdFraction", "cost change that triggers pruning", ge=0, le=1
    ),
    "delay_rewiring_to_first_solution": _p(
        bool, "setDelayRewiringUntilInitialSolution", "no rewiring before the first solution"
    ),
    "use_just_in_time_sampling": _p(bool, "setJustInTimeSampling", "generate samples only where needed"),
    "drop_unconnected_samples_on_prune": _p(bool, "setDropSamplesOnPrune", "drop unconnected samples when pruning"),
    "stop_on_each_solution_improvement": _p(bool, "setStopOnSolnImprovement", "return after every improvement"),
    "use_strict_queue_ordering": _p(bool, "setStrictQueueOrdering", "re-sort the queue on every rewiring"),
    "find_approximate_solutions": _p(bool, "setConsiderApproximateSolutions", "track approximate solutions"),
    "border_fraction": _p(float, "setBorderFraction", "fraction of expansions spent on border cells", gt=0, le=1),
    "failed_expansion_score_factor": _p(
        float, "setFailedExpansionCellScoreFactor", "score factor after a failed expansion", gt=0, le=1
    ),
    "min_valid_path_fraction": _p(
        float, "setMinValidPathFraction", "least valid fraction of a motion to keep it", ge=0, le=1
    ),
    "temp_change_factor": _p(float, "setTempChangeFactor", "BiTRRT temperature change factor", gt=0),
    "init_temperature": _p(float, "setInitTemperature", "BiTRRT initial temperature", gt=0),
    "frontier_threshold": _p(float, "setFrontierThreshold", "BiTRRT frontier distance", ge=0),
    "frontier_node_ratio": _p(float, "setFrontierNodeRatio", "BiTRRT frontier/non-frontier node ratio", gt=0),
    "cost_threshold": _p(float, "setCostThreshold", "BiTRRT cost threshold"),
    "num_samples": _p(
        int,
        "setNumSamples",
        "FMT*/BFMT* samples drawn in one batch (the extended variant adds more if needed)",
        ge=10,
        le=1_000_000,
    ),
    "radius_multiplier": _p(float, "setRadiusMultiplier", "FMT*/BFMT* scale of the connection radius (or k)", gt=0),
    "nearest_k": _p(bool, "setNearestK", "BFMT* connects to the k nearest instead of those within a radius"),
    "cache_cc": _p(bool, "setCacheCC", "FMT*/BFMT* remember collision-check results between samples"),
    "heuristics": _p(
        bool, "setHeuristics", "FMT*/BFMT* order the open set by cost-to-come plus a cost-to-go heuristic"
    ),
    "extended_fmt": _p(bool, "setExtendedFMT", "FMT*/BFMT* add samples when the batch holds no path (else fail)"),
    "balanced": _p(bool, "setExploration", "BFMT* alternates the two trees (balanced exploration)"),
    "optimality": _p(bool, "setTermination", "BFMT* terminates on the optimal connection instead of the first one"),
}

_RRTSTAR = [
    "range",
    "goal_bias",
    "rewire_factor",
    "use_k_nearest",
    "delay_collision_checking",
    "tree_pruning",
    "prune_threshold",
    "informed_sampling",
    "sample_rejection",
    "new_state_rejection",
    "use_admissible_heuristic",
    "focus_search",
    "number_sampling_attempts",
    "ordered_sampling",
    "ordering_batch_size",
]
_BITSTAR = [
    "rewire_factor",
    "samples_per_batch",
    "use_bitstar_k_nearest",
    "use_graph_pruning",
    "prune_threshold_as_fractional_cost_change",
    "delay_rewiring_to_first_solution",
    "use_just_in_time_sampling",
    "drop_unconnected_samples_on_prune",
    "stop_on_each_solution_improvement",
    "use_strict_queue_ordering",
    "find_approximate_solutions",
]
_KPIECE = ["range", "border_fraction", "failed_expansion_score_factor", "min_valid_path_fraction"]


@dataclass(frozen=True)
class PlannerSpec:
    """One OMPL planner: its class name in `ompl.geometric`, its parameters, whether it optimises
    (searches until its work budget is spent, unless `stop_at_first_solution`)."""

    ompl_class: str
    params: tuple[str, ...]
    optimizing: bool = False
    defaults: tuple[tuple[str, Any], ...] = ()  # our defaults where OMPL's do not suit a 6-joint arm
    # OMPL's PRM family adds goal states from a helper thread while the roadmap grows; with Python
    # validity callbacks and bindings that hold the GIL during solve() that deadlocks (seen with a
    # pose goal's goal set), and BFMT* crashes with a goal set; these planners get one goal
    # configuration: the nearest
    single_goal: bool = False
    # a defect of the bound planner that makes it unusable here: the planner is then reported unavailable
    # (`twin planners`, DependencyMissing on creation) with this reason instead of being run
    defect: str | None = None
    # OMPL's PRM family looks for a solution from a helper thread while the roadmap grows: no Python
    # termination condition may reach its solve() (see twin_ompl.budget), so its work budget is spent by
    # growing the roadmap from Python (`twin_ompl.budget.search_roadmap`)
    solution_thread: bool = False
    # an optimising planner's work budget (`max_state_checks`, `max_iterations`; see twin_ompl.budget)
    max_state_checks: int | None = None
    max_iterations: int | None = None


# Work budgets of the optimising planners (`max_state_checks`, `max_iterations`; see twin_ompl.budget): an
# anytime search ends when its budget is spent, so a seeded run repeats on any machine; the request's time
# limit stays a hard cap. Chosen so that a typical blocked query of the reference scenes (robocup and
# warehouse, straight joint motion colliding) spends it in ~0.2 s, well before the 0.75 s a 1 s limit leaves
# for sampling, with room for a machine three times slower or busier. On the 2-core development machine
# under a load of ~2.5 (other jobs running), 20 such queries took (search wall time, median / max):
# RRT* 15k checks 0.19 / 0.23 s, Informed RRT* 15k 0.20 / 0.27 s, PRM* 12k 0.21 / 0.25 s, BIT* 8k 0.17 /
# 0.27 s, AORRTC 30k 0.18 / 0.31 s. At about 1.5x these budgets a planner on a half-shared core already
# met its 0.75 s cap (RRT* 20k: 17-20k checks done). Iterations (termination-condition queries) come at
# ~1-15k a second while a planner checks states; AORRTC, once its path is near its cost bound, can reject
# samples without checking one, at 1.2-1.6 million iterations a second: 100k ends that after ~0.07 s and
# never binds otherwise. The budgets are per second of the request's time limit (`_work_budget`): a 2 s limit
# buys twice the work, still counted, so still deterministic; the share of the limit spent stays ~20 %.
# BIT*'s own work grows faster than its checks: each batch of samples is wired into a graph that keeps every
# earlier one. On MotionBenchMaker's UR5 problems (10 s limit) it checked ~60k of its 80k configurations in the
# full 10 s, ~8k iterations a second, so the clock ended it and a run's result depended on the machine's load
# (the same problem twice: 79 318 and 77 255 iterations). 2 000 iterations a second of the limit end those runs
# by count after ~1.5 s with the same paths (table_pick #0-#24: every length equal); on the reference cells'
# blocked queries (1 s) BIT* needs 380-820 (median; max 2 831) before its checks run out: 39 of their 40
# paths stayed the same, the one capped is 1.28 rad long instead of 1.16.
_ITERATIONS = 100_000
_BITSTAR_ITERATIONS = 2_000


def _budget(max_state_checks: int, max_iterations: int = _ITERATIONS) -> dict[str, Any]:
    return {"max_state_checks": max_state_checks, "max_iterations": max_iterations}


PLANNER_SPECS: dict[str, PlannerSpec] = {
    # OMPL's default range is 20% of the space extent (~3 rad here): long edges that are mostly rejected
    # and raw paths that wander; 1 rad halved planning + shortcutting time in the warehouse queries
    "RRTConnect": PlannerSpec("RRTConnect", ("range", "intermediate_states"), defaults=(("range", 1.0),)),
    "RRT": PlannerSpec("RRT", ("range", "goal_bias", "intermediate_states"), defaults=(("range", 1.0),)),
    "RRTstar": PlannerSpec("RRTstar", tuple(_RRTSTAR), True, **_budget(15_000)),
    "InformedRRTstar": PlannerSpec("InformedRRTstar", tuple(_RRTSTAR), True, **_budget(15_000)),
    "SORRTstar": PlannerSpec(
        "SORRTstar",
        tuple(_RRTSTAR),
        True,
        **_budget(15_000),
        defect=(
            "OMPL 2.0.1's SORRT* spins inside OrderedInfSampler::clearBatch once a path is found on an easy query "
            "and ignores its time limit (seen with gdb), so it is disabled; use ompl.informedrrtstar (the same "
            "planner without ordered sampling) or an OMPL build where this is fixed"
        ),
    ),
    "PRM": PlannerSpec("PRM", ("max_nearest_neighbors",), single_goal=True, solution_thread=True),
    "PRMstar": PlannerSpec("PRMstar", (), True, single_goal=True, solution_thread=True, **_budget(12_000)),
    "LazyPRMstar": PlannerSpec("LazyPRMstar", ("range",), True, single_goal=True, **_budget(12_000)),
    "BITstar": PlannerSpec("BITstar", tuple(_BITSTAR), True, **_budget(8_000, _BITSTAR_ITERATIONS)),
    "AORRTC": PlannerSpec("AORRTC", ("range",), True, **_budget(30_000)),
    "KPIECE1": PlannerSpec("KPIECE1", ("goal_bias", *_KPIECE)),
    "BKPIECE1": PlannerSpec("BKPIECE1", tuple(_KPIECE)),
    "LBKPIECE1": PlannerSpec("LBKPIECE1", ("range", "border_fraction", "min_valid_path_fraction")),
    "BiTRRT": PlannerSpec(
        "BiTRRT",
        (
            "range",
            "temp_change_factor",
            "init_temperature",
            "frontier_threshold",
            "frontier_node_ratio",
            "cost_threshold",
        ),
    ),
    # FMT* and BFMT* march once through one batch of samples and return the path they find (they do not
    # optimise for the rest of the time limit). OMPL's defaults (1000 samples, radius multiplier 1.1 / 1.0,
    # k-nearest with k = ceil((2 r)^d e/d ln n)) give k ~ 52 ln n in 6 joints: every sample's neighbourhood is
    # the whole batch, edges as long as the sampling box (~100 configurations checked each at 0.02 rad), and
    # with the Python-side FCL check no path within 1 s (robocup table <-> bin queries whose straight motion
    # is blocked, bench of issue 12: 0/20 at 1000 and 500 samples, 0/30 at 200). A multiplier of 0.6 gives
    # k ~ 1.35 ln n (7 at 100 samples): local edges; 100 samples then solved 30/30 such queries (FMT* median
    # ~0.13 s, BFMT* ~0.19 s; 300+ samples fall below 90 % again). This gives up FMT*'s asymptotic-optimality
    # condition on k, which a 1 s budget never reaches anyway; raise both for longer limits.
    "FMT": PlannerSpec(
        "FMT",
        ("num_samples", "radius_multiplier", "use_k_nearest", "cache_cc", "heuristics", "extended_fmt"),
        defaults=(("num_samples", 100), ("radius_multiplier", 0.6)),
    ),
    # BFMT* with a goal set (several goal states) crashes inside solve() in OMPL 2.0.1 (a segfault on a
    # robocup pose goal with 11 IK solutions, reproducible with its seed): it gets the nearest goal only
    "BFMT": PlannerSpec(
        "BFMT",
        (
            "num_samples",
            "radius_multiplier",
            "nearest_k",
            "balanced",
            "optimality",
            "heuristics",
            "cache_cc",
            "extended_fmt",
        ),
        defaults=(("num_samples", 100), ("radius_multiplier", 0.6)),
        single_goal=True,
    ),
}


def _bounds(field: Any) -> dict[str, Any]:
    """The numeric bounds (gt, ge, lt, le) of a pydantic FieldInfo, to rebuild it with another default."""
    out: dict[str, Any] = {}
    for m in field.metadata:
        for key in ("gt", "ge", "lt", "le"):
            if getattr(m, key, None) is not None:
                out[key] = getattr(m, key)
    return out


_CHECKS_DOC = (
    "end the search after this many configurations per second of the request's time limit were checked for "
    "collision (states sampled plus the states along checked motions: info's states_checked + configs_checked). "
    "Counts work, not time, so a seeded run repeats on any machine; the time limit stays a hard cap. None: the "
    "time limit alone ends it, and the result depends on the machine's speed and load"
)
_ITERATIONS_DOC = (
    "end the search after the planner asked its termination condition this many times per second of the "
    "request's time limit (about once per iteration): bounds a search that stops checking states (AORRTC "
    "rejecting samples against its cost bound). None: no such bound"
)


class OptimizingOmplParams(OmplParams):
    """Options of the optimising (anytime) planners on top of the shared ones: when to stop improving."""

    stop_at_first_solution: bool = Field(
        False, description="stop at the first exact path instead of optimising until the budget or time limit ends it"
    )
    max_state_checks: int | None = Field(None, ge=1, description=_CHECKS_DOC)
    max_iterations: int | None = Field(None, ge=1, description=_ITERATIONS_DOC)


def params_model(spec: PlannerSpec) -> type[OmplParams]:
    """The pydantic model of one planner: the shared options plus its own OMPL parameters."""
    fields: dict[str, Any] = {name: (OMPL_PARAMS[name].type, OMPL_PARAMS[name].field) for name in spec.params}
    for name, value in spec.defaults:
        f = OMPL_PARAMS[name].field
        fields[name] = (OMPL_PARAMS[name].type, Field(value, description=f.description, **_bounds(f)))
    if spec.optimizing:  # the budget defaults are the planner's own (PLANNER_SPECS)
        fields["max_state_checks"] = (int | None, Field(spec.max_state_checks, ge=1, description=_CHECKS_DOC))
        fields["max_iterations"] = (int | None, Field(spec.max_iterations, ge=1, description=_ITERATIONS_DOC))
    base: type[OmplParams] = OptimizingOmplParams if spec.optimizing else OmplParams
    model = create_model(f"{spec.ompl_class}Params", __base__=base, **fields)
    model.__doc__ = (
        f"Parameters of ompl.{spec.ompl_class.lower()}: the shared options and OMPL's "
        f"{', '.join(spec.params) or '(none)'}."
    )
    return model
