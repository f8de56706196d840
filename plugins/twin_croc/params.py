"""Parameters of `croc` (a pydantic model, validated from a planner block's `params:`) and the default
spheres of the arm's links for its `whole_arm` mode.

The shared ones (`RecedingParams`, `twin.planning.receding_params`: horizon, dt, step bound, weights, tool,
wrist and held-object spheres, margin, the loop's tolerances) have the same defaults as `nmpc`'s, so that in
`seed` mode the two MPCs solve the same formulation and differ in their solver.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from twin.plugin import DEFAULT_ARM_SPHERES, DEFAULT_WHOLE_ARM_TOOL_SPHERES, RecedingParams

__all__ = ["DEFAULT_ARM_SPHERES", "DEFAULT_WHOLE_ARM_TOOL_SPHERES", "CrocParams"]


class CrocParams(RecedingParams):
    """Parameters of `croc`: the shared MPC ones (defaults as `nmpc`'s) and CSQP's."""

    mode: Literal["seed", "whole_arm"] = Field(
        "seed",
        description="seed: the tool, wrist and held-object spheres against the perceived boxes (nmpc's model);"
        " whole_arm: every link's spheres (`whole_arm_tool_spheres` and `arm_spheres` instead of the tool and wrist"
        " spheres) against every box of the planning scene (fixtures, perceived boxes; the table stays the soft"
        " table term)",
    )
    limit_jerk: bool = Field(
        False,
        description="not available: the control is the step's change, its own change is not a row of this"
        " formulation (so croc is not `jerk_limited`)",
    )
    arm_spheres: list[tuple[int, float, float, float, float]] = Field(
        default_factory=lambda: list(DEFAULT_ARM_SPHERES),
        description="whole_arm mode: spheres (DH frame 1..5, x, y, z, r) on the shoulder, arm and wrist links",
    )
    whole_arm_tool_spheres: list[tuple[float, float, float, float]] = Field(
        default_factory=lambda: list(DEFAULT_WHOLE_ARM_TOOL_SPHERES),
        description="whole_arm mode: spheres (x, y, z, r) in the tcp frame on the fingers, gripper and flange",
        min_length=1,
    )
    iterations_per_round: int = Field(
        1, ge=1, le=100, description="SQP iterations before the faces are chosen again on the iterate"
    )
    warm_rounds: int = Field(
        1,
        ge=1,
        le=100,
        description="rounds of a warm-started solve: its budget in the step (the next step's solve goes on from it)",
    )
    cold_rounds: int = Field(
        3, ge=1, le=200, description="rounds of a cold solve at least (the warm solves of the next steps go on from it)"
    )
    cold_max_rounds: int = Field(
        15, ge=1, le=500, description="rounds of a cold solve at most, while its plan does not pass the loop's check"
    )
    termination_tolerance: float = Field(
        1e-3, gt=0, description="CSQP's KKT tolerance (its 1e-6 default is never met here: twin_croc.ocp)"
    )
    qp_tolerance: float = Field(
        3e-3,
        gt=0,
        description="absolute and relative tolerance of CSQP's ADMM QP (1e-3: ~100 ADMM iterations per QP, 3e-3: ~50)",
    )
    row_tightening_m: float = Field(
        0.004,
        ge=0,
        le=0.05,
        description="sphere rows hold this much beyond the margin (CSQP keeps bounds to about its QP tolerance)",
    )

    self_slots: int = Field(
        4,
        ge=0,
        le=20,
        description="self-collision rows per knot (the nearest pairs of spheres on links that are not neighbours:"
        " `arm_spheres`, `whole_arm_tool_spheres` and the held object's, in both modes); 0: the arm is not kept"
        " from itself (the seeds' formulation; the loop's FCL check still stops a plan that folds into itself)",
    )
    self_screen_m: float = Field(
        0.03,
        gt=0,
        le=1.0,
        description="a pair of the arm's own spheres gets a row at a knot only within this distance there (the"
        " loop's check judges every pair)",
    )

    @model_validator(mode="after")
    def _croc(self) -> CrocParams:
        if self.cold_max_rounds < self.cold_rounds:
            raise ValueError(
                f"cold_max_rounds ({self.cold_max_rounds}) must not be below cold_rounds ({self.cold_rounds})"
            )
        if self.limit_jerk:
            raise ValueError("limit_jerk: croc has no jerk rows (its control is the step's change); allowed: false")
        for a in self.arm_spheres:
            if a[0] not in (1, 2, 3, 4, 5) or a[4] <= 0:
                raise ValueError(f"arm spheres need a DH frame 1 to 5 and a positive radius, got {a}")
        for s in self.whole_arm_tool_spheres:
            if s[3] <= 0:
                raise ValueError(f"whole-arm tool sphere radii must be positive, got {s}")
        return self
