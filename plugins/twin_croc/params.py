"""Parameters of `croc` (a pydantic model, validated from a planner block's `params:`) and the default
spheres of the arm's links for its `whole_arm` mode.

The shared ones (`twin_nmpc.params.RecedingParams`: horizon, dt, step bound, weights, tool, wrist and
held-object spheres, margin, the loop's tolerances) have the same defaults as `nmpc`'s, so that in `seed`
mode the two MPCs solve the same formulation and differ in their solver.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from twin_nmpc.params import RecedingParams

__all__ = ["DEFAULT_ARM_SPHERES", "CrocParams"]

# (DH frame, x, y, z, radius): the shoulder (frame 1), upper arm (2) and forearm (3) link cylinders of the
# UR5e URDF, each cut into slabs along its axis and every slab enclosed, with the 1 cm box margin, by a sphere
# at most 1 cm wider than the cylinder (radius = sqrt(r^2 + (slab/2)^2) - margin). tests/test_croc_planner.py
# checks that they cover the URDF's collision cylinders. With the tool and wrist spheres (the gripper, wrist 3,
# wrist 1 and 2) they are the whole arm beyond the base.
DEFAULT_ARM_SPHERES: tuple[tuple[int, float, float, float, float], ...] = (
    (1, 0.0, -0.0588, 0.0, 0.0577),
    (1, 0.0, 0.0038, 0.0, 0.0577),
    (2, 0.425, 0.0, 0.07, 0.0571),
    (2, 0.425, 0.0, 0.13, 0.0571),
    (2, 0.0425, 0.0, 0.138, 0.0588),
    (2, 0.1275, 0.0, 0.138, 0.0588),
    (2, 0.2125, 0.0, 0.138, 0.0588),
    (2, 0.2975, 0.0, 0.138, 0.0588),
    (2, 0.3825, 0.0, 0.138, 0.0588),
    (3, 0.3922, 0.0, 0.05, 0.0527),
    (3, 0.3922, 0.0, 0.12, 0.0527),
    (3, 0.0394, 0.0, 0.02, 0.0461),
    (3, 0.1178, 0.0, 0.02, 0.0461),
    (3, 0.1962, 0.0, 0.02, 0.0461),
    (3, 0.2746, 0.0, 0.02, 0.0461),
    (3, 0.353, 0.0, 0.02, 0.0461),
)


class CrocParams(RecedingParams):
    """Parameters of `croc`: the shared MPC ones (defaults as `nmpc`'s) and CSQP's."""

    mode: Literal["seed", "whole_arm"] = Field(
        "seed",
        description="seed: the tool, wrist and held-object spheres against the perceived boxes (nmpc's model);"
        " whole_arm: every link's spheres (`arm_spheres` too) against every box of the planning scene (fixtures,"
        " perceived boxes; the table stays the soft table term)",
    )
    limit_jerk: bool = Field(
        False,
        description="not available: the control is the step's change, its own change is not a row of this"
        " formulation (so croc is not `jerk_limited`)",
    )
    arm_spheres: list[tuple[int, float, float, float, float]] = Field(
        default_factory=lambda: list(DEFAULT_ARM_SPHERES),
        description="whole_arm mode: spheres (DH frame 1..3, x, y, z, r) on the shoulder, upper arm and forearm",
    )
    iterations_per_round: int = Field(
        2, ge=1, le=100, description="SQP iterations before the faces are chosen again on the iterate"
    )
    warm_rounds: int = Field(
        1,
        ge=1,
        le=100,
        description="rounds of a warm-started solve: its budget in the step (the next step's solve goes on from it)",
    )
    cold_rounds: int = Field(
        3, ge=1, le=200, description="rounds of a cold solve (the warm solves of the next steps go on from it)"
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

    @model_validator(mode="after")
    def _croc(self) -> CrocParams:
        if self.limit_jerk:
            raise ValueError("limit_jerk: croc has no jerk rows (its control is the step's change); allowed: false")
        for a in self.arm_spheres:
            if a[0] not in (1, 2, 3) or a[4] <= 0:
                raise ValueError(f"arm spheres need a DH frame 1, 2 or 3 and a positive radius, got {a}")
        return self
