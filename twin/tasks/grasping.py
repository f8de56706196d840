"""The gripper as both tasks and the jam handling know it: its geometry below the tcp, the top-down tcp pose,
and what its finger position says about a grasp.

Shared by the cell (grasping), the RoboCup task (how low a grasp may go) and the jam handling (what the wrist
camera sees between the fingers), so it lives below all three.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from twin.config import GripperSettings
from twin.types import Pose

__all__ = [
    "GRIPPER_POLL_S",
    "GraspCheck",
    "GripStatus",
    "GripperReading",
    "grasp_check",
    "holding_check",
    "top_down",
]

GRIPPER_POLL_S = 0.02  # the gripper's status is polled this long; free fingers are moving within a step


def top_down(xyz: np.ndarray | tuple[float, float, float], yaw: float) -> np.ndarray:
    """(4, 4) tcp pose at `xyz` pointing straight down, fingers closing along (cos yaw, sin yaw, 0)."""
    return Pose.from_xyz_rpy(tuple(float(v) for v in xyz), (math.pi, 0.0, float(yaw))).matrix()


class GripStatus(Enum):
    """What the gripper's finger position says about a grasp (a Robotiq 2F-85's "object detected" status)."""

    HOLDING = "holding"  # the fingers stopped on something of the expected width, or still hold it
    NOTHING = "nothing"  # the fingers closed (nearly) fully: nothing between them
    WRONG_WIDTH = "wrong_width"  # they stopped on something, but not as wide as the object should be
    LOST = "lost"  # the opening fell below the one sensed at the grasp: the object slipped out or dropped


@dataclass(frozen=True)
class GripperReading:
    """The gripper's sensor readings: opening between the pads (finger encoders), m; whether both fingers
    have stopped; mean finger motor effort, N."""

    opening_m: float
    settled: bool
    effort_n: float


@dataclass(frozen=True)
class GraspCheck:
    """A grasp judged from the gripper's readings alone; `reason` says why it is not HOLDING."""

    status: GripStatus
    opening_m: float
    reason: str = ""
    expect_width_m: tuple[float, float] | None = None  # what the task expected between the fingers, (min, max) m

    @property
    def holding(self) -> bool:
        return self.status is GripStatus.HOLDING


def grasp_check(r: GripperReading, expect_width_m: tuple[float, float] | None, g: GripperSettings) -> GraspCheck:
    """A grasp that just closed, judged by the finger position alone, as the 2F-85's "object detected" status
    does: holding when the fingers stopped clearly above fully closed (`g.object_min_opening_m`) and, when
    the task knows the width range (min, max) m that should lie between the fingers, no more than
    `g.width_over_tolerance_m` wider and no more than `g.width_under_tolerance_m` narrower."""
    mm = 1000.0 * r.opening_m
    if r.opening_m <= g.object_min_opening_m:
        return GraspCheck(
            GripStatus.NOTHING,
            r.opening_m,
            f"nothing between the fingers after closing (they closed to {mm:.1f} mm)",
            expect_width_m,
        )
    if expect_width_m is not None and not (
        expect_width_m[0] - g.width_under_tolerance_m <= r.opening_m <= expect_width_m[1] + g.width_over_tolerance_m
    ):
        lo, hi = (1000.0 * w for w in expect_width_m)
        want = f"{lo:.0f} mm" if abs(hi - lo) < 0.5 else f"{lo:.0f}-{hi:.0f} mm"
        return GraspCheck(
            GripStatus.WRONG_WIDTH,
            r.opening_m,
            f"the fingers stopped at {mm:.1f} mm, but the object should be {want} across "
            f"(-{1000 * g.width_under_tolerance_m:.0f}/+{1000 * g.width_over_tolerance_m:.0f} mm)",
            expect_width_m,
        )
    return GraspCheck(GripStatus.HOLDING, r.opening_m, "", expect_width_m)


def holding_check(r: GripperReading, grasp: GraspCheck | None, g: GripperSettings) -> GraspCheck:
    """Is the object grasped at `grasp` (None: no grasp closed on one) still between the fingers, by the
    reading `r` now? The force-limited fingers keep closing when it leaves, so it is lost when the opening
    fell more than `g.slip_tolerance_m` below the opening sensed at the grasp and also below the narrowest
    the object itself can be held at (its expected width less `g.width_under_tolerance_m`): a box caught
    across its edges that turns square in the fingers narrows the opening by up to a third of its width and
    is still held."""
    if grasp is None:
        return GraspCheck(GripStatus.NOTHING, r.opening_m, "no grasp closed on an object")
    floor = grasp.opening_m - g.slip_tolerance_m
    if grasp.expect_width_m is not None:
        floor = min(floor, grasp.expect_width_m[0] - g.width_under_tolerance_m)
    if r.opening_m < floor:
        return GraspCheck(
            GripStatus.LOST,
            r.opening_m,
            f"the fingers closed from {1000 * grasp.opening_m:.1f} mm at the grasp to {1000 * r.opening_m:.1f} mm",
            grasp.expect_width_m,
        )
    return GraspCheck(GripStatus.HOLDING, r.opening_m, "", grasp.expect_width_m)
