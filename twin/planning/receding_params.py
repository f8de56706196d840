"""The parameters every receding-horizon MPC shares (`RecedingParams`, a pydantic model a planner's own `Params`
extends), the default proxy spheres of the gripper, the wrist and the whole arm, and the seed's cost weights
(`Weights`): one formulation, so that `nmpc` and `croc` with the same parameters differ only in their solver.

Defaults are the SPEC's (seed 000); seed 001 is `dt: 0.1, execute_steps: 3`. What each sphere covers and
why the wrist has two is said beside the defaults.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = [
    "DEFAULT_ARM_SPHERES",
    "DEFAULT_TOOL_SPHERES",
    "DEFAULT_WHOLE_ARM_TOOL_SPHERES",
    "DEFAULT_WRIST_SPHERES",
    "RecedingParams",
    "Weights",
]

# (x, y, z, radius) in the TCP frame (z along the tool, pointing out of the gripper; the flange is at
# z = -0.135): fingertips/held object, fingers, the two halves of the 0.14 x 0.06 x 0.07 m gripper body,
# flange + wrist_3. With the default 1 cm box margin every sphere covers its part of the URDF collision
# geometry (a half gripper body needs 0.058 m), so the FCL check of the whole arm passes too.
DEFAULT_TOOL_SPHERES: tuple[tuple[float, float, float, float], ...] = (
    (0.0, 0.0, 0.0, 0.05),
    (0.0, 0.0, -0.06, 0.05),
    (0.035, 0.0, -0.088, 0.05),
    (-0.035, 0.0, -0.088, 0.05),
    (0.0, 0.0, -0.15, 0.05),
)
# (DH frame, x, y, z, radius): one sphere on each of the wrist_1 (frame 4) and wrist_2 (frame 5) link
# housings; with the box margin they cover the r 0.045 m x 0.13 / 0.11 m cylinders (0.079 / 0.071 m
# needed). Not in the seed (it models the end effector only), but without them the wrist, tilted on the
# way, clipped the perceived box while the gripper spheres stayed clear; `wrist_spheres: []` is the seed's
# model. They sit 0.2 m or more above the TCP of a tool facing down, so their size costs little room.
DEFAULT_WRIST_SPHERES: tuple[tuple[int, float, float, float, float], ...] = (
    (4, 0.0, -0.02, 0.0, 0.07),
    (5, 0.0, 0.005, 0.0, 0.062),
)


# The whole arm's spheres (croc's whole_arm mode, and the self rows of both MPCs: `twin.planning.selfrows`), tight
# where the seed's are generous (its 5 cm sphere at the tcp, sized for a held cube, reached 35 mm into a bin wall
# from starts the cell's queries keep 1 cm clear). Each covers its part of the URDF's collision geometry with the
# 1 cm box margin (tests/test_croc_planner.py checks it): (DH frame, x, y, z, radius): the shoulder (frame 1),
# upper arm (2), forearm (3), wrist 1 (4) and wrist 2 (5) link cylinders, each cut into slabs along its axis, one
# sphere of the cylinder's radius or less per slab.
DEFAULT_ARM_SPHERES: tuple[tuple[int, float, float, float, float], ...] = (
    (1, 0.0, -0.0588, 0.0, 0.0577),
    (1, 0.0, 0.0038, 0.0, 0.0577),
    (2, 0.425, 0.0, 0.07, 0.0571),
    (2, 0.425, 0.0, 0.13, 0.0571),
    (2, 0.0304, 0.0, 0.138, 0.052),
    (2, 0.0911, 0.0, 0.138, 0.052),
    (2, 0.1518, 0.0, 0.138, 0.052),
    (2, 0.2125, 0.0, 0.138, 0.052),
    (2, 0.2732, 0.0, 0.138, 0.052),
    (2, 0.3339, 0.0, 0.138, 0.052),
    (2, 0.3946, 0.0, 0.138, 0.052),
    (3, 0.3922, 0.0, 0.0383, 0.047),
    (3, 0.3922, 0.0, 0.085, 0.047),
    (3, 0.3922, 0.0, 0.1317, 0.047),
    (3, 0.0282, 0.0, 0.02, 0.0389),
    (3, 0.0842, 0.0, 0.02, 0.0389),
    (3, 0.1402, 0.0, 0.02, 0.0389),
    (3, 0.1962, 0.0, 0.02, 0.0389),
    (3, 0.2522, 0.0, 0.02, 0.0389),
    (3, 0.3082, 0.0, 0.02, 0.0389),
    (3, 0.3642, 0.0, 0.02, 0.0389),
    (4, 0.0, -0.0633, 0.0, 0.04),
    (4, 0.0, -0.02, 0.0, 0.04),
    (4, 0.0, 0.0233, 0.0, 0.04),
    (5, 0.0, 0.0325, 0.0, 0.0428),
    (5, 0.0, -0.0225, 0.0, 0.0428),
)
# (x, y, z, radius) in the tcp frame: the finger region over the whole stroke (x +-0.0545 m, the fingertips
# 12 mm past the tcp) in a 3 x 2 grid, the gripper body (0.14 x 0.06 x 0.07 m) in 4, wrist 3 and the flange in 2
DEFAULT_WHOLE_ARM_TOOL_SPHERES: tuple[tuple[float, float, float, float], ...] = (
    (-0.03633, 0.0, -0.03675, 0.0168),
    (0.0, 0.0, -0.03675, 0.0168),
    (0.03633, 0.0, -0.03675, 0.0168),
    (-0.03633, 0.0, -0.00425, 0.0168),
    (0.0, 0.0, -0.00425, 0.0168),
    (0.03633, 0.0, -0.00425, 0.0168),
    (-0.0525, 0.0, -0.088, 0.0394),
    (-0.0175, 0.0, -0.088, 0.0394),
    (0.0175, 0.0, -0.088, 0.0394),
    (0.0525, 0.0, -0.088, 0.0394),
    (0.0, 0.0, -0.138, 0.031),
    (0.0, 0.0, -0.168, 0.031),
)


class RecedingParams(BaseModel):
    """The parameters every MPC of `twin.planning.receding` shares: the seed formulation's (defaults: SPEC, seed
    000; seed 001 is dt=0.1, execute_steps=3) and the loop's."""

    model_config = ConfigDict(extra="forbid")

    horizon: int = Field(30, ge=2, le=200, description="steps per solve")
    dt: float = Field(0.08, gt=0, le=1.0, description="s per step (seed 001: 0.1)")
    execute_steps: int = Field(1, ge=1, description="steps executed per solve (seed 001: 3)")
    max_step_rad: float = Field(0.15, gt=0, le=1.0, description="per-step joint increment bound")
    limit_acceleration: bool = Field(
        True,
        description="bound the change of the step by the request's max_joint_acc * dt^2 (not in the seed, which"
        " jumps to full speed in one step; the simulated grasp shook the cube loose that way)",
    )
    limit_jerk: bool = Field(
        True,
        description="bound the change of the step's change by the request's max_joint_jerk * dt^3 (not in the seed;"
        " declared as the planner's `jerk_limited`)",
    )
    goal_tolerance_m: float = Field(
        0.03, gt=0, description="stop when the TCP is this close to the goal (or the goal's tighter tolerance)"
    )
    max_solves: int = Field(40, ge=1, description="give up after this many solves")
    tool_spheres: list[tuple[float, float, float, float]] = Field(
        default_factory=lambda: list(DEFAULT_TOOL_SPHERES),
        description="proxy spheres (x, y, z, r) in the TCP frame",
        min_length=1,
    )
    wrist_spheres: list[tuple[int, float, float, float, float]] = Field(
        default_factory=lambda: list(DEFAULT_WRIST_SPHERES),
        description="proxy spheres (DH frame 4..6, x, y, z, r) on the wrist",
    )
    object_sphere_min_radius_m: float = Field(0.03, gt=0)
    object_sphere_max_radius_m: float = Field(0.05, gt=0)
    max_object_spheres: int = Field(4, ge=1, le=16)
    box_margin_m: float = Field(0.01, ge=0, le=0.1, description="boxes are grown by this on every side")
    box_screen_m: float | None = Field(
        0.1,
        gt=0,
        description="boxes farther than this from every proxy sphere along the plan a solve starts from (the shifted"
        " last plan or the initial guess) are left out of its NLP; a solution that comes within half of it of a box"
        " left out is solved again with that box. None: every box in every NLP",
    )
    constraint_substeps: int = Field(2, ge=1, le=8, description="box constraint points per step (1 = knots only)")
    table_z_m: float = Field(0.0, description="table top height")
    table_clearance_m: float = Field(0.0, ge=0, description="sphere bottoms above the table (soft)")
    facing_down: bool = Field(True, description="terminal facing-down term (soft)")
    facing_down_tol_rad: float = Field(0.05, ge=0, le=math.pi / 2)
    position_weight: float = Field(1.0, gt=0)
    terminal_weight_factor: float = Field(10.0, gt=0)
    step_weight: float = Field(0.02, ge=0, description="per rad^2 of joint step (lighter than position)")
    table_slack_weight: float = Field(1e4, gt=0)
    facing_down_weight: float = Field(1e3, gt=0)
    initial_guess: Literal["over_box", "straight"] = Field(
        "over_box",
        description="cold-solve guess when the straight line to the goal crosses a box: lift/transfer/lower over it,"
        " or the straight line anyway (only to show the local-minimum trap)",
    )
    lift_clearance_m: float = Field(0.05, ge=0, description="extra height of the over-the-box initial guess")
    guess_step_fraction: float = Field(0.9, gt=0, le=1.0, description="initial guess steps, fraction of max")

    @model_validator(mode="after")
    def _consistent(self) -> RecedingParams:
        if self.execute_steps > self.horizon:
            raise ValueError(f"execute_steps ({self.execute_steps}) must not exceed horizon ({self.horizon})")
        if self.object_sphere_min_radius_m > self.object_sphere_max_radius_m:
            raise ValueError("object_sphere_min_radius_m must not exceed object_sphere_max_radius_m")
        for s in self.tool_spheres:
            if s[3] <= 0:
                raise ValueError(f"tool sphere radii must be positive, got {s}")
        for w in self.wrist_spheres:
            if w[0] not in (4, 5, 6) or w[4] <= 0:
                raise ValueError(f"wrist spheres need a DH frame 4, 5 or 6 and a positive radius, got {w}")
        return self


@dataclass(frozen=True)
class Weights:
    """Cost weights: position error (stage; terminal = position * terminal_factor), joint step, slacks."""

    position: float
    terminal_factor: float
    step: float
    table_slack: float
    facing_down_slack: float
