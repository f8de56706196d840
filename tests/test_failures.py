"""One failure taxonomy for every planner: each failed row carries one reason of a fixed set."""

from __future__ import annotations

import pytest

from twin.compare.metrics import FAILURES, failure_of_exception, failure_of_plan, failure_of_row, failure_of_task
from twin.errors import DependencyMissing, PlanningError
from twin.planning import FINAL_CHECK


@pytest.mark.parametrize(
    ("status", "reason", "info", "want"),
    [
        ("success", "", None, None),
        ("timeout", "no solution within 1 s", None, "timeout"),
        ("no_solution", "the planner searched", None, "no_solution"),
        ("invalid_start", "the start is in collision (wrist_3_link with table)", None, "start_in_collision"),
        ("invalid_goal", "the joint goal is in collision (tcp with bin_blue)", None, "goal_in_collision"),
        ("invalid_goal", "the goal pose has no IK solution (out of reach)", None, "ik_failure"),
        ("ik_failed", "the line passes a singularity", None, "ik_failure"),
        ("limit_violation", "TOPP-RA could not keep the limits", None, "retiming_failed"),
        ("collision", "the straight line collides", {}, "no_solution"),  # the planner's own verdict
        ("collision", "the trajectory collides (x with y)", {"rejected_by": FINAL_CHECK}, "final_check_collision"),
        ("execution_stopped", "protective stop: contact", None, "execution_contact"),
        ("something_new", "", None, "error"),
    ],
)
def test_a_plan_status_maps_to_one_reason(status: str, reason: str, info: dict | None, want: str | None) -> None:
    got = failure_of_plan(status, reason, info)
    assert got == want and (got is None or got in FAILURES)


@pytest.mark.parametrize(
    ("errors", "want"),
    [
        ([], None),
        (["transfer: ompl.rrtconnect: timeout: no path in 1 s", "grasp: nothing"], "timeout"),
        (["approach: toppra.movel: ik_failed: the line leaves the workspace"], "ik_failure"),
        (["transfer: nmpc: execution_stopped: protective stop"], "execution_contact"),
        (["grasp: the fingers closed on nothing (can, upright)"], "grasp_lost"),
        (["transfer: the object was dropped while carrying it: opening fell"], "grasp_lost"),
        (["place: released, but it is outside the bin"], "grasp_lost"),
        (["perception: never seen on the table"], "grasp_lost"),
        (["time: the run time limit was reached before this cube"], "timeout"),
        (["calibration: the ArUco marker was not found: x"], "error"),
    ],
)
def test_a_task_run_fails_for_its_first_object_not_placed(errors: list[str], want: str | None) -> None:
    assert failure_of_task(errors) == want


def test_exceptions() -> None:
    assert failure_of_exception(DependencyMissing("ompl is not installed")) == "dependency_missing"
    assert failure_of_exception(PlanningError("broken contract")) == "error"


def test_rows_written_before_the_taxonomy_get_their_reason_from_the_status() -> None:
    assert failure_of_row({"status": "timeout", "success": False, "reason": "x"}) == "timeout"
    assert failure_of_row({"status": "error", "success": False, "reason": "WorkerDied"}) == "error"
    assert failure_of_row({"status": "success", "success": True}) is None
    assert failure_of_row({"status": "skipped", "success": None}) is None
    assert failure_of_row({"status": "collision", "success": False, "failure": "final_check_collision"}) == (
        "final_check_collision"
    )
