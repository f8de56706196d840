"""The warehouse run's referee: which true cube each perceived cube was, and whether each ended in its zone.

Ground truth, read only to judge and to measure (`twin.tasks.judge` holds the rules every referee shares);
the task hands the referee its records and never decides with what it knows.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np

from twin.tasks.judge import Referee, Verdict, judge_in_zone, knocked_error, nearest_object, settle_until_rest, stage_of
from twin.types import ObjectOutcome

if TYPE_CHECKING:
    from twin.tasks.warehouse.perception import LabeledCube

__all__ = ["WarehouseAttempt", "WarehouseReferee"]


class WarehouseAttempt(Protocol):
    """What the warehouse task records about one cube it worked on (twin.tasks.warehouse._Attempt)."""

    cube: LabeledCube
    true_id: int | None
    error: str | None
    failure: str | None
    stage: str | None
    planner: str | None
    cycle_time_s: float


class WarehouseReferee(Referee):
    """Ground truth of one warehouse run: the true cubes at the start, which one each perceived cube was,
    and the verdict on each at the end."""

    def match(self, centroid: np.ndarray) -> int | None:
        """Metrics: the true cube a perceived centroid (3,) was, or None."""
        return nearest_object(self.truth.values(), np.asarray(centroid, dtype=float))

    def outcomes(self, attempts: Sequence[WarehouseAttempt]) -> list[ObjectOutcome]:
        """One outcome per true cube; errors read "<stage>: <why>"."""
        task = self.settings.task.warehouse
        settle_until_rest(self.world)
        by_true = {a.true_id: a for a in attempts if a.true_id is not None}
        out = []
        for oid, o0 in self.truth.items():
            zone = task.drop_zones.get(o0.color or "")
            verdict = (
                judge_in_zone(self.world, oid, zone, task.drop_radius_m)
                if zone is not None
                else Verdict(False, "no drop zone")
            )
            att = by_true.get(oid)
            failure = stage = planner = None
            if verdict.placed:
                err = None
            elif att is None:
                err = "perception: never seen on the table"
            elif att.error:
                err, failure, stage, planner = att.error, att.failure, att.stage, att.planner
            elif knock := self.watch and self.watch.knocked(oid):
                err = knocked_error(knock, verdict.reason)
                failure, stage, planner = "execution_contact", knock.stage, knock.planner
            else:
                err = f"place: released, but {verdict.reason}"
            out.append(
                ObjectOutcome(
                    id=o0.name,
                    cls=o0.cls,
                    color=o0.color,
                    target_bin=f"drop_{o0.color}",
                    placed=verdict.placed,
                    error=err,
                    failure=failure,
                    stage=stage or stage_of(err),
                    planner=planner,
                    cycle_time_s=att.cycle_time_s if att else 0.0,
                    pose_error_m=float(np.linalg.norm(att.cube.centroid[:2] - o0.position[:2])) if att else None,
                )
            )
        return out
