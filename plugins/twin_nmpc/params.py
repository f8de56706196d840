"""Parameters of `nmpc` (a pydantic model: a planner block's `params:` are validated by it): the shared MPC ones
(`RecedingParams` in `twin.planning.receding_params`, with the default proxy spheres) and IPOPT's.
"""

from __future__ import annotations

from pydantic import Field, model_validator

from twin.plugin import RecedingParams

__all__ = ["NMPCParams"]


class NMPCParams(RecedingParams):
    """Parameters of `nmpc` (defaults: SPEC, seed 000; seed 001 is dt=0.1, execute_steps=3): the shared ones
    and IPOPT's."""

    self_slots: int = Field(
        4,
        ge=0,
        le=20,
        description="self rows per step (`twin.planning.selfrows`): the nearest pairs of a gripper or held-object"
        " sphere and a forearm or upper-arm sphere (`DEFAULT_WHOLE_ARM_TOOL_SPHERES`, `DEFAULT_ARM_SPHERES`); 0: the"
        " seed's formulation, the arm not kept from itself",
    )
    self_screen_m: float = Field(
        0.03, gt=0, le=1.0, description="a pair gets a self row at a step only within this distance there"
    )
    self_tightening_m: float = Field(
        0.005,
        ge=0,
        le=0.05,
        description="self rows hold this much beyond twice the box margin (they hold at the knots; the loop's"
        " check judges between them too)",
    )
    box_slots: int | None = Field(
        None,
        ge=0,
        le=20,
        description="box slots of the NLP: each solve puts the boxes near its plan in them (a slot left over holds a"
        " box far away, whose rows are never active), so one NLP shape, built expanded when the planner is"
        " constructed, serves every solve; a solve with more boxes near than slots adds one (that shape is built"
        " mapped, inside the step). None: one per fixture perception reports (`known: false`; warehouse: the"
        " wall), and one more where the config has objects (a placed object becomes a box beside the way to the"
        " next drop)",
    )
    prebuild_boxes: list[int] | None = Field(
        None,
        description="box-slot counts whose NLPs are built when the planner is constructed; None: `box_slots`. Another"
        " count is built on first use, inside that (slower) step",
    )
    ipopt_tol: float = Field(
        1e-3, gt=0, description="IPOPT tol of warm-started solves (the shifted plan is usually 1-5 iterations away)"
    )
    ipopt_max_iter: int = Field(100, ge=1, description="IPOPT iteration limit of warm-started solves")
    warm_mu_init: float = Field(
        1e-5,
        gt=0,
        description="IPOPT mu_init of warm-started solves: the barrier parameter they start from. Inside warehouse"
        " runs (rows of the wall, the table and the step bounds near active) 1e-3 first pulled the shifted plan,"
        " already near the optimum, out to that barrier's central path and back: 11-18 iterations a solve, ~2"
        " from 1e-5 (1e-7: outliers of 40-108)",
    )
    solve_time_limit_s: float | None = Field(
        None,
        gt=0,
        description="CPU-time cap of a warm-started solve; None (default): none, its iteration limit bounds it, so"
        " it ends, and its plan is accepted or not, alike on every machine",
    )
    cold_ipopt_tol: float = Field(
        1e-3, gt=0, description="IPOPT tol of a cold solve (looser left the first warm solve with more to do)"
    )
    cold_mu_init: float = Field(1e-3, gt=0, description="IPOPT mu_init of a cold solve (the guess is good)")
    cold_max_iter: int = Field(300, ge=1)
    cold_solve_time_limit_s: float | None = Field(
        None, gt=0, description="CPU-time cap of a cold solve; None (default): none, `cold_max_iter` bounds it"
    )
    ipopt_options: dict[str, float | int | str] = Field(
        default_factory=dict, description="extra IPOPT options for every solve, e.g. {linear_solver: mumps}"
    )

    @model_validator(mode="after")
    def _prebuild(self) -> NMPCParams:
        if self.prebuild_boxes is not None and any(n < 0 for n in self.prebuild_boxes):
            raise ValueError(f"prebuild_boxes must be box counts >= 0, got {self.prebuild_boxes}")
        return self
