"""Parameters of `compiled.rrtconnect` (units in the names), validated by the plugin itself."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["CompiledParams"]


class CompiledParams(BaseModel):
    """What `compiled.rrtconnect` takes: the search, its model, the path's post-processing."""

    model_config = ConfigDict(extra="forbid")

    time_limit_s: float | None = Field(
        None, gt=0, description="cap on the planning time; the request's time_limit_s applies when smaller or when None"
    )
    joint_range: Literal["compact", "full"] = Field(
        "compact",
        description=(
            "sampling bounds: 'compact' = [-pi, pi] per joint widened to start +- pi and to the joint goal "
            "(every IK branch keeps a representative); 'full' = the joint limits"
        ),
    )
    range_rad: float | None = Field(
        None,
        gt=0,
        le=20,
        description="longest motion added to a tree in one step (joint-space L2, rad); None = 20% of the "
        "sampling bounds' diagonal (OMPL's default)",
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
    clearance_m: float = Field(
        0.005,
        ge=0,
        le=0.05,
        description=(
            "planning keeps this distance to the environment (obstacles inflated in the planning model); "
            "a query whose start or every goal lies closer is planned without it"
        ),
    )
    floor_m: float = Field(
        1e-4,
        gt=0,
        le=0.01,
        description="a motion whose spheres come this close to touching counts as touching (the continuous check)",
    )
    max_nodes: int = Field(200_000, ge=100, le=5_000_000, description="capacity of each tree")
    iterations_per_call: int = Field(
        2000, ge=1, le=1_000_000, description="search iterations per compiled call (the deadline is read between)"
    )
    max_goal_states: int = Field(
        64, ge=1, le=512, description="most IK solutions of a pose goal put in the goal tree (nearest first)"
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
    verify_resolution_rad: float = Field(
        0.002, ge=0, le=0.1, description="joint step of the check of the timed trajectory; 0 = no check"
    )
    verify_resolution_m: float = Field(
        0.004, gt=0, le=0.05, description="TCP travel resolution of that check (checked every half of it)"
    )
    retimer: str = Field(
        "ruckig",
        description=(
            "retimer plugin that turns the path into a trajectory (a config block's retimer: wins); ruckig: "
            "jerk-limited, and a third of TOPP-RA's time on MBM paths"
        ),
    )
    retimer_params: dict[str, Any] = Field(default_factory=dict, description="parameters of that retimer")
