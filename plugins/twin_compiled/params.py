"""Parameters of `compiled.rrtconnect` (units in the names), validated by the plugin itself."""

from __future__ import annotations

from pydantic import Field

from twin.plugin import PathPlannerParams

__all__ = ["CompiledParams"]


class CompiledParams(PathPlannerParams):
    """What `compiled.rrtconnect` takes: every path planner's options (`twin.plugin.PathPlannerParams`; the
    clearance is kept in the planning model, the retimer is ruckig by default) and its search's."""

    range_rad: float | None = Field(
        2.0,
        gt=0,
        le=20,
        description="longest motion added to a tree in one step (joint-space L2, rad; 2.0: VAMP's default); None = "
        "20% of the sampling bounds' diagonal (OMPL's default)",
    )
    resolution_rad: float = Field(
        0.05,
        ge=0,
        le=0.5,
        description=(
            "the search checks a motion's configurations this far apart (max-abs joint step), coarse to fine; "
            "0 = continuously (slower). The path found is proven free continuously either way"
        ),
    )
    search_margin_m: float = Field(
        5e-4,
        gt=0,
        le=0.01,
        description=(
            "the search keeps its states and the configurations it checks this far from touching, so the "
            "continuous check of the path (which refuses within floor_m) starts from states it accepts"
        ),
    )
    max_repairs: int = Field(
        3, ge=0, le=20, description="segments planned again when the continuous check cannot prove them free"
    )
    floor_m: float = Field(
        1e-4,
        gt=0,
        le=0.01,
        description="a motion whose spheres come this close to touching counts as touching (the continuous check)",
    )
    dynamic_domain_rad: float | None = Field(
        4.0,
        gt=0,
        le=100,
        description=(
            "dynamic domain (VAMP's default): a node whose extension failed draws only samples within this "
            "joint-space distance (rad), shrinking on each further failure; None: off (OMPL's RRTConnect)"
        ),
    )
    domain_min_radius_rad: float = Field(1.0, gt=0, le=100, description="the dynamic domain's smallest radius, rad")
    domain_alpha: float = Field(
        1e-4, ge=0, lt=1, description="a dynamic domain shrinks by (1 - alpha) on a failure, grows by (1 + alpha)"
    )
    tree_ratio: float = Field(
        1.0,
        ge=0,
        le=100,
        description=(
            "tree balance (VAMP's default): a tree with at most 1/(1 + tree_ratio) of the other's nodes is "
            "extended again; 0: the trees take strict turns (OMPL's RRTConnect)"
        ),
    )
    max_nodes: int = Field(200_000, ge=100, le=5_000_000, description="capacity of each tree")
    iterations_per_call: int = Field(
        2000, ge=1, le=1_000_000, description="search iterations per compiled call (the deadline is read between)"
    )
    shortcut_tries: int = Field(
        50, ge=0, le=100_000, description="random shortcuts tried after the greedy vertex reduction (0: none)"
    )
    escape_rad: float = Field(
        0.5,
        gt=0,
        le=3.2,
        description=(
            "a start or goal FCL calls free but the cover calls touching is left along an FCL-checked straight "
            "way of at most this length (max-abs, rad) toward the other end or a random direction"
        ),
    )
    retimer: str = Field(
        "ruckig",
        description=(
            "retimer plugin that turns the path into a trajectory (a config block's retimer: wins); ruckig: "
            "jerk-limited, and a third of TOPP-RA's time on MBM paths"
        ),
    )
