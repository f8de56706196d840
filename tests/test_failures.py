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
        ("collision", "the straight line collides", {}, "collision"),  # the planner's own verdict
        ("collision", "the trajectory collides (x with y)", {"rejected_by": FINAL_CHECK}, "final_check_collision"),
        ("limit_violation", "joint 2 reaches 5.2 rad/s", {"rejected_by": FINAL_CHECK}, "limit_violation"),
        ("no_solution", "reported success but ends 0.1 m away", {"rejected_by": FINAL_CHECK}, "final_check_goal"),
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
        (["hover: ruckig.movej: collision: the trajectory collides (right_finger with obstacle)"], "collision"),
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


def test_a_task_row_takes_the_failure_its_failed_stage_named(monkeypatch) -> None:
    """A motion the judge refused fails the task row under the judge's name (its text alone would read as the
    planner's own collision); objects without a structured failure fall back to their text."""
    from twin.compare import worker
    from twin.compare.spec import RunTask
    from twin.types import ObjectOutcome, RunSummary

    refused = "transfer: nmpc: collision: segment 4 would collide (left_finger with obstacle); not executed"
    outcomes = (
        ObjectOutcome("cube_0", "cube", "red", "drop_red", placed=True),
        ObjectOutcome(
            "cube_1", "cube", "blue", "drop_blue", placed=False, error=refused, failure="final_check_collision"
        ),
        ObjectOutcome(
            "cube_2", "cube", "green", "drop_green", placed=False, error="grasp: nothing between the fingers"
        ),
    )
    metrics = {"nmpc": {"max_vel_ratio": 0.5, "max_acc_ratio": 1.0, "max_jerk_ratio": 0.9}}
    summary = RunSummary("warehouse", 0, "nmpc", outcomes, 30.0, 10.0, metrics=metrics)
    monkeypatch.setattr("twin.tasks.run_task", lambda *a, **k: summary)
    task = RunTask(
        run_id="nmpc|warehouse-task|seed=0|x",
        planner_id="nmpc",
        planner={"name": "nmpc"},
        scenario="warehouse-task",
        case="warehouse-task",
        kind="task",
        seed=0,
        config="warehouse",
    )
    row = worker.execute_run(task)
    assert row["failure"] == "final_check_collision" and row["status"] == "incomplete"
    assert refused in row["reason"] and "grasp: nothing" in row["reason"]
    assert row["metrics"]["max_acc_ratio"] == 1.0 and row["metrics"]["max_vel_ratio"] == 0.5
    summary = RunSummary("warehouse", 0, "nmpc", outcomes[::2], 30.0, 10.0, metrics=metrics)
    assert worker.execute_run(task)["failure"] == "grasp_lost"  # no name given: from the text


def test_a_long_reason_on_screen_is_cut_at_a_word_and_says_so() -> None:
    from twin.cli import progress_line

    reason = "descent: toppra.movel: collision: the trajectory collides (right_finger with obstacle, " + (
        "densified sample 16, checked every 0.01 rad / 0.01 m)"
    )
    row = {"run_id": "ompl.rrt|warehouse-task|seed=0|ab", "status": "incomplete", "success": False, "reason": reason}
    short = progress_line(row, 3, 26, width=100)
    assert short.endswith(" ...)") and len(short) < len(reason) + 60
    kept = short.split(" (", 1)[1][: -len(" ...)")]
    assert reason.startswith(kept) and reason[len(kept)] == " "  # cut between words, never inside "0.01"
    assert progress_line(row, 3, 26).endswith("0.01 m))")  # a reason that fits is shown whole
