"""The RoboCup run's referee: which true object each estimate was, and whether each ended in its bin.

Ground truth, read only to judge and to measure (`twin.tasks.judge` holds the rules every referee shares);
the task hands the referee its records and never decides with what it knows. Beside it, the ORACLE hand-off
of the task's perception: only a detector labelled as needing ground truth is given the simulator's objects.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np

from twin.perception.detection import with_ground_truth
from twin.tasks.judge import (
    DisplacementWatch,
    Referee,
    Verdict,
    judge_in_bin,
    knocked_error,
    nearest_object,
    oracle_ground_truth,
    settle_until_rest,
    stage_of,
)
from twin.tasks.robocup.bins import bin_for, bin_geometries
from twin.tasks.robocup.perception import RobocupResult, perceive_robocup
from twin.types import ObjectOutcome

if TYPE_CHECKING:
    from twin.camera import RGBDFrame
    from twin.config import Settings
    from twin.perception.detection import Detector
    from twin.world import World

__all__ = ["RobocupReferee", "RobocupTarget", "perceive_robocup_scene"]


class RobocupTarget(Protocol):
    """What the RoboCup task records about one object it worked on (twin.tasks.robocup._Target)."""

    error: str | None
    failure: str | None
    stage: str | None
    planner: str | None
    done: bool
    cycle_time_s: float
    first_estimate: np.ndarray | None
    true_ids: set[int]


class RobocupReferee(Referee):
    """Ground truth of one RoboCup run: the true objects at the start, which of them each estimate was
    (metrics), and the verdict on each at the end. The task hands it its records; it never answers a
    question the task could act on."""

    def __init__(self, world: World, settings: Settings, watch: DisplacementWatch | None = None) -> None:
        super().__init__(world, settings, watch)
        self.bins = bin_geometries(settings)  # the task's rules: which bin, what a bin looks like

    def match(self, position: np.ndarray) -> set[int]:
        """Metrics: the true object an estimate at `position` (3,) was, as a set of none or one id."""
        oid = nearest_object(self.world.objects(), np.asarray(position, dtype=float))
        return set() if oid is None else {oid}

    def outcomes(self, targets: Sequence[RobocupTarget], *, stopped: str | None = None) -> list[ObjectOutcome]:
        """One outcome per true object; errors read "<stage>: <why>". `stopped`: why the run ended early."""
        settle_until_rest(self.world)
        out = []
        for oid, o0 in self.truth.items():
            bin_name = bin_for(o0.cls, o0.color, self.settings)
            mine = [t for t in targets if oid in t.true_ids]
            bin_ = self.bins.get(bin_name)
            verdict = (
                judge_in_bin(self.world, oid, bin_)
                if bin_ is not None
                else Verdict(False, f"there is no fixture {bin_name!r}")
            )
            failure = stage = planner = None
            if verdict.placed:
                err = None
            elif not mine:
                err = "perception: never seen on the table" + (f" (the run stopped: {stopped})" if stopped else "")
            elif mine[-1].error or (not mine[-1].done and any(t.error for t in mine)):
                # seen again elsewhere after a failure (dropped, knocked), the object is a new target to the
                # task; its first failure is still the object's, the later targets' are added to the text
                failed = [t for t in mine if t.error]
                origin = failed[0]
                err, failure, stage, planner = origin.error, origin.failure, origin.stage, origin.planner
                err = "; then: ".join([str(err), *(str(t.error) for t in failed[1:])])
            elif mine[-1].done and (knock := self.watch and self.watch.knocked(oid)):
                err = knocked_error(knock, f"{verdict.reason}{self._elsewhere(oid, bin_name)}")
                failure, stage, planner = "execution_contact", knock.stage, knock.planner
            elif mine[-1].done:
                err = f"place: released, but {verdict.reason}{self._elsewhere(oid, bin_name)}"
            else:
                err = "task: attempted, but neither placed nor failed" + (
                    f" (the run stopped: {stopped})" if stopped else ""
                )
            first = mine[0].first_estimate if mine else None
            out.append(
                ObjectOutcome(
                    id=o0.name,
                    cls=o0.cls,
                    color=o0.color,
                    target_bin=bin_name,
                    placed=verdict.placed,
                    error=err,
                    failure=failure,
                    stage=stage or stage_of(err),
                    planner=planner,
                    cycle_time_s=sum(t.cycle_time_s for t in mine),
                    pose_error_m=float(np.linalg.norm(first[:2] - o0.position[:2])) if first is not None else None,
                )
            )
        return out

    def _elsewhere(self, oid: int, target: str) -> str:
        for name, b in self.bins.items():
            if name != target and judge_in_bin(self.world, oid, b).placed:
                return f" (it is in {name})"
        return ""


def perceive_robocup_scene(
    world: World,
    frame: RGBDFrame,
    T_base_camera: np.ndarray,
    settings: Settings,
    detector: Detector,
    *,
    known_boxes: list[tuple[np.ndarray, np.ndarray]] | None = None,
) -> RobocupResult:
    """The RoboCup perception of one frame (`twin.tasks.robocup.perception.perceive_robocup`), with the ORACLE
    hand-off: only a detector labelled as needing ground truth is given the simulator's objects."""
    fed = with_ground_truth(detector, oracle_ground_truth(world, detector))
    return perceive_robocup(frame, T_base_camera, settings, fed, seed=world.seed, known_boxes=known_boxes)
