"""Why a motion or a task failed, in one fixed set of names for every planner, so failures can be counted
and compared across planners whatever words their reasons use (`twin compare` rows, task outcomes).

The name follows who found the failure: a planner that reports a collision found it itself (`collision`);
a trajectory the planner called a success and twin's independent check turned down is a `final_check_*`
or `limit_violation`; `no_solution` only when the planner searched and found nothing.
"""

from __future__ import annotations

import re
from typing import Any

__all__ = ["FAILURES", "failure_of_plan", "failure_of_task"]

# `MotionResult.info["rejected_by"]` of a result the independent check turned down (twin.planning.FINAL_CHECK;
# repeated here so the names need no planning import)
_FINAL_CHECK = "final_check"

FAILURES: dict[str, str] = {
    "start_in_collision": "the start is in collision or outside the joint limits",
    "goal_in_collision": "the goal is in collision, out of reach or outside the joint limits",
    "ik_failure": "no acceptable inverse-kinematics solution for the goal or a waypoint",
    "timeout": "the time limit ran out before a solution was found",
    "no_solution": "the planner searched and found no solution",
    "collision": "the planner's own check found its motion colliding and returned none",
    "retiming_failed": "the path could not be time-parameterised within the limits",
    "final_check_collision": "the returned trajectory failed twin's independent FCL re-check",
    "final_check_goal": "the returned trajectory does not end on the goal within its tolerances (twin's check)",
    "limit_violation": "the returned trajectory exceeds the joint velocity, acceleration or (for a planner that "
    "declares itself jerk-limited) jerk limits (twin's independent check)",
    "execution_contact": "executed in physics, the arm touched something",
    "grasp_lost": "a task run did not get an object where it belongs: never perceived, grasp not sensed, slipped, "
    "dropped, or released outside its bin",
    "dependency_missing": "the planner's backend is not installed",
    "plugin_error": "the planner plugin raised an exception of its own (a bug in the plugin)",
    "error": "the run raised an error or was stopped (time-out of the run, crashed worker)",
}

_STATUS_FAILURE = {
    "no_solution": "no_solution",
    "timeout": "timeout",
    "invalid_start": "start_in_collision",
    "invalid_goal": "goal_in_collision",
    "collision": "collision",  # the planner's own check found only a colliding motion
    "ik_failed": "ik_failure",
    "limit_violation": "retiming_failed",  # the planner's retimer could not keep the limits
    "execution_stopped": "execution_contact",
}
# what the independent check's verdicts are called, by the status it gives
_REJECTED_FAILURE = {
    "collision": "final_check_collision",
    "limit_violation": "limit_violation",
    "no_solution": "final_check_goal",
}
_TASK_STATUS = re.compile(r": (" + "|".join(_STATUS_FAILURE) + r"): ")


def failure_of_plan(status: str, reason: str = "", info: Any = None) -> str | None:
    """The failure name (a FAILURES key) of a planning result: None on success.

    From the status, refined where the status alone is ambiguous: a result the independent check turned
    down (`info["rejected_by"] == "final_check"`) is named for what the check found; an invalid goal
    whose reason names IK (no or no acceptable IK solution) is an ik_failure."""
    if status == "success":
        return None
    if isinstance(info, dict) and info.get("rejected_by") == _FINAL_CHECK and status in _REJECTED_FAILURE:
        return _REJECTED_FAILURE[status]
    if status == "invalid_goal" and re.search(r"\bIK\b", reason):
        return "ik_failure"
    return _STATUS_FAILURE.get(status, "error")


def failure_of_task(errors: list[str]) -> str | None:
    """The failure name of a task run from the error texts of its objects not placed (in object order),
    for outcomes that carry no `failure` of their own (rows written before they did): that of the first.
    None when every object was placed.

    A stage that failed to move says its planner's status (`"<stage>: <planner>: <status>: <why>"`, see
    twin.tasks.cell), which maps as for a motion query; a run out of time is a timeout; every other
    object not placed (not perceived, grasp not sensed, slipped, dropped, released outside its bin) is
    grasp_lost; a calibration failure is an error."""
    if not errors:
        return None
    e = errors[0]
    m = _TASK_STATUS.search(e)
    if m:
        return failure_of_plan(m.group(1), e[m.end() :])
    if e.startswith("time:"):
        return "timeout"
    if e.startswith("calibration:"):
        return "error"
    return "grasp_lost"
