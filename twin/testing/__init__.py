"""The planner contract, checked against any registered planner (as gymnasium's `check_env` checks an env).

`check_planner("ompl.rrtconnect")` builds the planner exactly as the runs do (`twin.planning.make_planner`,
so its params, retimer and the `CheckedPlanner` around it are the real ones), asks it a handful of seeded
requests in a reference scene and judges what comes back against the contract every planner must meet:

1. ``statuses``: a request is answered by a status, never an exception; an unreachable goal (a pose far
   outside the workspace, a joint goal outside the limits) and a colliding goal (in the table) get a
   failure status with a reason, never a trajectory;
2. ``start_goal``: a trajectory starts exactly at the request's start (1e-6 rad; a receding-horizon segment at
   the measured state) and ends on the goal within the goal's own tolerances (`twin.planning.goal_miss`);
3. ``velocity``, ``acceleration``, ``jerk``: within the request's `Limits`, both the trajectory's declared
   qd and qdd (jerk: differences of qdd) and the divided differences of its q samples, which by the mean
   value theorem cannot exceed a limit the motion keeps; the arm stands still before the first sample and
   holds the last one, so a trajectory that starts moving or accelerating jumps from rest;
   `LIMIT_TOLERANCE` (0.1 %) absorbs float round-off;
4. ``time_limit``: a call returns within `request.time_limit_s` plus `time_slack_s(limit)` (see there), wall
   clock measured here; for a receding-horizon planner every `reset`/`step` call is one planning call;
5. ``determinism``: the same request (same seed) planned again gives the same status and trajectory;
6. ``invalid_start``: a start in collision gets a status, not a trajectory (nor a first segment);
7. ``collision_free``: no returned trajectory or segment collides (FCL, whole scene, at the configured
   `collision.check_resolution_*`, the judge the runs use: `twin.planning.first_collision`).

Every rule is judged twice: on what the plugin itself returns (`raw`: the plugin author's contract) and on
what the runs get through `CheckedPlanner` (`checked`: twin's own checks refuse some breaches, such as a
colliding trajectory or one beyond the joint limits, and pass others on, such as a planning-time
overrun). A rule passes when both pass; a `PlanningError` with which CheckedPlanner refuses the plugin's
output counts as refused, not as a crash.
The planner is asked only for the goal kinds it declares (`goal_kinds`; nmpc: positions); a receding-
horizon planner is driven through `CheckedPlanner.drive` on a kinematic plant, as `twin plan` does.
Rules 2, 3 and 7 need a trajectory: a planner that solves none of the collision-free queries fails them.

The queries (`contract_queries`): top-down tool poses within reach, on the IK branch nearest home, 2 cm
clear of the scene: a move of 0.2 m or more whose straight joint motion and straight tool line are free;
one whose straight joint motion collides (a sampling planner must search; not asked of receding-horizon
planners, which are local); a short move (8-15 cm, one IK branch: a Cartesian line's query); then more.
By default a one-shot planner gets 3, a receding-horizon planner 2 (each of its steps is a solve). Then:
the solved query that made it search (else the first solved) again, an unreachable goal and a goal in the
table per goal kind, and a start in the table.

For a plugin's own test suite:

    from twin.testing import assert_conformant

    def test_my_planner_keeps_the_contract():
        assert_conformant("acme.straight", time_limit_s=0.5)

`twin check-planner NAME` runs the same check from the command line.

The package, one idea per module: `rules` (the rules and the report types), `queries` (the seeded
starts and goals), `judge` (limits, time slack, sameness), `recorder` (what the plugin itself returned),
`checker` (asking the requests and judging every rule), `check` (`check_planner`, `assert_conformant`).
"""

from twin.testing.allowances import LIMIT_TOLERANCE, START_TOLERANCE_RAD, limit_violations, time_slack_s
from twin.testing.check import DEFAULT_CONFIG, assert_conformant, check_planner
from twin.testing.contract import RULES, CheckResult, ConformanceReport
from twin.testing.seeded_queries import Query, contract_queries

__all__ = [
    "DEFAULT_CONFIG",
    "LIMIT_TOLERANCE",
    "RULES",
    "START_TOLERANCE_RAD",
    "CheckResult",
    "ConformanceReport",
    "Query",
    "assert_conformant",
    "check_planner",
    "contract_queries",
    "limit_violations",
    "time_slack_s",
]
