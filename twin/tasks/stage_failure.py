"""What a stage that failed says, and how a task keeps it: the one exception of the fixed stages.

It lives below the cell so that everything the cell drives (the jam handling, the detours round a refused
motion, the tasks) can raise and catch it without importing the cell.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from twin.types import MotionResult

__all__ = ["PATH_COLLIDES", "FailureRecord", "StageFailed", "clear_failure", "note_failure", "or_refusal"]

# refusals that say the direct way runs into something (another way may not)
PATH_COLLIDES = frozenset({"collision", "final_check_collision"})


class StageFailed(Exception):
    """A stage could not be done; the task logs the reason and moves on to the next object.

    `failure`: the failure's name (a `twin.failures.FAILURES` key) when the stage knows it, as a motion
    that failed does from its planner's result and the judge's verdict; None leaves it to the reason.
    `planner`: the planner block that planned the failed motion (None when no motion failed: a grasp not
    sensed, an object dropped). `moved`: whether the arm moved before the stage failed; a stage refused
    in planning did not, so the task may still choose another way there."""

    def __init__(
        self, stage: str, reason: str, *, failure: str | None = None, planner: str | None = None, moved: bool = True
    ):
        super().__init__(f"{stage}: {reason}")
        self.stage = stage
        self.reason = reason
        self.failure = failure
        self.planner = planner
        self.moved = moved


class FailureRecord(Protocol):
    """What a task keeps about an object's failed attempts (its `_Attempt` or `_Target`)."""

    error: str | None
    failure: str | None
    stage: str | None
    planner: str | None


def note_failure(rec: FailureRecord, e: StageFailed, attempt: int) -> None:
    """Keep a failed attempt's reason on `rec`. The first failure is the object's: a cube dropped in the
    transfer and then lying where no grasp reaches failed in the transfer; later attempts' reasons are
    added to the text ("...; attempt 2: descent: ...")."""
    if rec.stage is None:
        rec.error, rec.failure, rec.stage, rec.planner = str(e), e.failure, e.stage, e.planner
    else:
        rec.error = f"{rec.error}; attempt {attempt}: {e}"


def clear_failure(rec: FailureRecord) -> None:
    """The object was placed after all: no failure is its."""
    rec.error = rec.failure = rec.stage = rec.planner = None


def or_refusal(move: Callable[[], MotionResult]) -> MotionResult | StageFailed:
    """`move()`'s result, or its StageFailed when the stage's planner refused the way because it runs into
    something (planned, not moved: another way may not); any other failure is raised."""
    try:
        return move()
    except StageFailed as e:
        if e.moved or e.failure not in PATH_COLLIDES:
            raise
        return e
