"""Asking one planner the contract's requests and judging every rule on what came back; kept apart from
`check_planner`, which only builds the planner and the scene, so the rules read in one place."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from twin.errors import PlanningError
from twin.planning import (
    CheckedPlanner,
    Segment,
    colliding_pair,
    densify,
    first_collision,
    goal_miss,
    jerk_limited,
    limits_from_settings,
)
from twin.testing.allowances import (
    LIMIT_TOLERANCE,
    START_TOLERANCE_RAD,
    _same,
    _same_traj,
    limit_violations,
    time_slack_s,
)
from twin.testing.contract import RULES, CheckResult, _Verdict
from twin.testing.recorder import _Outcome, _Recorder, _TimingPlant
from twin.testing.seeded_queries import _goal, _served_goal, _top_down, contract_queries
from twin.types import JointGoal, Limits, MotionRequest, MotionResult, PoseGoal, Trajectory

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.config import Settings
    from twin.registry import PluginContext

__all__: list[str] = []

log = logging.getLogger("twin")

_MAX_SEGMENTS = 300  # a receding-horizon planner that has not finished after this many segments is cut off


def _err(e: BaseException) -> str:
    return f"{type(e).__name__}: {' '.join(str(e).split())[:200]}"


class _Checker:
    def __init__(
        self,
        checked: CheckedPlanner,
        name: str,
        settings: Settings,
        scene: PlanningScene,
        context: PluginContext,
        *,
        seed: int,
        time_limit_s: float,
        progress: Callable[[str], None],
    ):
        self.checked = checked
        self.name = name
        self.settings = settings
        self.scene = scene
        self.context = context
        self.kin = context.kinematics
        self.seed = seed
        self.time_limit_s = time_limit_s
        self.progress = progress
        self.limits = _limits(settings)
        self.recorder = _Recorder(checked.inner)
        checked.inner = self.recorder  # the checked planner now calls the plugin through the recorder
        self.rh = checked.receding_horizon
        self.kinds = tuple(k for k in ("joint", "pose", "position") if checked.serves(k))
        col = settings.collision
        self.res_rad, self.res_m = col.check_resolution_rad, col.check_resolution_m

    # ---- asking ------------------------------------------------------------------------------------
    def ask(self, label: str, purpose: str, request: MotionRequest) -> _Outcome:
        self.progress(label)
        self.recorder.calls = []
        plant = _TimingPlant(request.start)
        t0 = time.perf_counter()
        result, error = None, None
        try:
            result = self.checked.drive(request, self.scene, plant, max_segments=_MAX_SEGMENTS)
        except Exception as e:  # noqa: BLE001 - judged: rule 1 (the plugin raised) or CheckedPlanner refused
            error = e
        wall = time.perf_counter() - t0
        log.debug(
            "check %s: %s -> %s in %.3f s", self.name, label, error or (result.status.value if result else None), wall
        )
        return _Outcome(label, purpose, request, list(self.recorder.calls), result, error, wall, plant.step_times)

    def request(self, start: np.ndarray, goal: JointGoal | PoseGoal, seed: int) -> MotionRequest:
        return MotionRequest(start, goal, self.limits, time_limit_s=self.time_limit_s, seed=seed)

    # ---- the run -----------------------------------------------------------------------------------
    def run(self, n_queries: int) -> tuple[list[CheckResult], list[_Outcome]]:
        # a receding-horizon planner is a local planner: it is not asked to search around an obstacle
        queries = contract_queries(self.settings, self.scene, self.kin, n_queries, self.seed, blocked=not self.rh)
        outcomes: list[_Outcome] = []
        for i, qu in enumerate(queries):
            kind = self.kinds[i % len(self.kinds)]
            req = self.request(qu.start, _goal(kind, qu.goal, self.kin), self.seed * 1000 + i)
            o = self.ask(f"query {i + 1}: {kind} goal, {qu.label}", "query", req)
            outcomes.append(o)
        # determinism: the query that made it search if it was solved, else the first one solved
        solved = [o for o in outcomes if o.raw_result is not None and o.raw_result.success]
        blocked = [o for o, qu in zip(outcomes, queries, strict=True) if not qu.straight_free and o in solved]
        first = (blocked or solved or outcomes)[0]
        repeat = self.ask(f"{first.label}, asked again", "repeat", first.request)
        outcomes.append(repeat)
        # unreachable and colliding goals, from the first query's start
        a = queries[0].start
        far = _top_down(np.array([-2.5, 0.4, 0.3]), 0.0)
        q_out = np.array(a, dtype=float)
        q_out[2] = 3.5  # the elbow beyond its +-pi
        p_in = self.kin.fk(a, "tcp")[:3, 3].copy()
        p_in[2] = -0.02  # the tool 2 cm inside the table
        T_in = _top_down(p_in, 0.0)
        q_in = self._colliding_config(T_in, a)
        for kind in self.kinds:
            g = _served_goal(self.kinds, far, q_out, kind)
            if g is not None:
                what = "outside the joint limits" if kind == "joint" else "2.5 m away"
                outcomes.append(
                    self.ask(f"unreachable {kind} goal ({what})", "unreachable", self.request(a, g, self.seed))
                )
            g = _served_goal(self.kinds, T_in, q_in, kind)
            if g is not None:
                outcomes.append(self.ask(f"{kind} goal in the table", "colliding_goal", self.request(a, g, self.seed)))
        # a start in collision, towards the first query's goal
        if q_in is not None:
            g0 = outcomes[0].request.goal
            outcomes.append(
                self.ask(
                    "start in collision (tool 2 cm below the table top)",
                    "invalid_start",
                    self.request(q_in, g0, self.seed),
                )
            )
        results = [
            self.rule_statuses(outcomes),
            *self.rules_trajectories(outcomes),
            self.rule_time(outcomes),
            self.rule_determinism(first, repeat),
            self.rule_invalid_start(outcomes, q_in),
        ]
        order = list(RULES)
        return sorted(results, key=lambda r: order.index(r.rule)), outcomes

    def _colliding_config(self, T: np.ndarray, near: np.ndarray) -> np.ndarray | None:
        sols = self.kin.ik(T, all_wraps=False)
        if sols.shape[0] == 0:
            return None
        sols = sols[np.argsort(np.abs(sols - near).max(axis=1))]
        hit = self.scene.in_collision_batch(sols)
        return sols[int(np.argmax(hit))] if hit.any() else None

    # ---- rules -------------------------------------------------------------------------------------
    def rule_statuses(self, outcomes: list[_Outcome]) -> CheckResult:
        v = _Verdict()
        for o in outcomes:
            if o.raw_error is not None:
                v.both(f"{o.label}: raised {_err(o.raw_error)}")
                continue
            for c in o.calls:
                if c.what == "reset":
                    continue
                ok_types: tuple[type, ...] = (MotionResult,) if c.what == "plan" else (MotionResult, Segment)
                if not isinstance(c.output, ok_types):
                    v.fail(
                        "raw",
                        f"{o.label}: {c.what}() returned {type(c.output).__name__}, "
                        f"not {' or '.join(t.__name__ for t in ok_types)}",
                    )
                    break
            if o.error is not None and not isinstance(o.error, PlanningError):
                v.fail("checked", f"{o.label}: CheckedPlanner raised {_err(o.error)}")
            if o.purpose not in ("unreachable", "colliding_goal"):
                continue
            raw = o.raw_result
            if raw is None and o.segments:
                v.fail("raw", f"{o.label}: returned {len(o.segments)} segment(s) and no failure status")
            elif raw is not None and raw.success:
                v.fail("raw", f"{o.label}: reported success")
            elif raw is not None and not raw.reason.strip():
                v.fail("raw", f"{o.label}: {raw.status.value} without a reason")
            if o.result is not None and o.result.success:
                v.fail("checked", f"{o.label}: reported success")
        n = sum(o.purpose in ("unreachable", "colliding_goal") for o in outcomes)
        return v.result(
            "statuses",
            f"no exception in {len(outcomes)} requests; "
            f"{n} unreachable or colliding goals got failure statuses with reasons",
        )

    def rules_trajectories(self, outcomes: list[_Outcome]) -> list[CheckResult]:
        """Rules 2, 3 and 7 on every request with a valid start (a start in collision is rule 6's)."""
        sg, col = _Verdict(), _Verdict()
        lim = {k: _Verdict() for k in ("velocity", "acceleration", "jerk")}
        judged = [o for o in outcomes if o.purpose != "invalid_start" and o.raw_error is None]
        n_raw = n_checked = 0
        for o in judged:
            req, res = o.request, o.result
            # the plugin's own output: every trajectory (segment) starts where the arm is, a success ends on the goal
            trajs = o.raw_trajectories()
            at = req.start
            for k, tr in enumerate(trajs):
                off = float(np.abs(tr.q[0] - at).max())
                if off > START_TOLERANCE_RAD:
                    what = (
                        f"segment {k + 1} starts {off:.2e} rad from the measured state"
                        if self.rh
                        else f"the trajectory starts {off:.2e} rad from the start"
                    )
                    sg.fail("raw", f"{o.label}: {what}")
                    break
                at = tr.q[-1]
            raw = o.raw_result
            if raw is not None and raw.success and raw.trajectory is not None:
                why = self._goal_miss(req, raw.trajectory.q[-1])
                if why is not None:
                    sg.fail("raw", f"{o.label}: reported success but {why}")
            motion = o.raw_motion()
            if motion is not None:
                n_raw += 1
                # a receding-horizon run cut short (CheckedPlanner stopped it) does not end at rest
                for name, why in limit_violations(motion, req.limits, to_rest=not self.rh or raw is not None).items():
                    lim[name].fail("raw", f"{o.label}: {why}")
            for k, tr in enumerate(trajs):
                hit = self._collision(tr)
                if hit is not None:
                    col.fail(
                        "raw", f"{o.label}: {f'segment {k + 1}' if self.rh else 'the trajectory'} collides ({hit})"
                    )
                    break
            # what the run got through CheckedPlanner (a PlanningError is CheckedPlanner refusing the plugin's
            # output: nothing reached the run, and the plugin's own failure is reported above)
            if res is None or not res.success or res.trajectory is None:
                continue
            n_checked += 1
            off = float(np.abs(res.trajectory.q[0] - req.start).max())
            if off > START_TOLERANCE_RAD:
                sg.fail("checked", f"{o.label}: the trajectory starts {off:.2e} rad from the start")
            why = self._goal_miss(req, res.trajectory.q[-1])
            if why is not None:
                sg.fail("checked", f"{o.label}: reported success but {why}")
            for name, why in limit_violations(res.trajectory, req.limits).items():
                lim[name].fail("checked", f"{o.label}: {why}")
            hit = self._collision(res.trajectory)
            if hit is not None:
                col.fail("checked", f"{o.label}: the trajectory collides ({hit})")
        solved = [o for o in judged if o.purpose == "query" and o.raw_result is not None and o.raw_result.success]
        if not solved:
            n_queries = sum(o.purpose == "query" for o in outcomes)
            why = f"none of the {n_queries} collision-free queries was solved, so no trajectory could be judged"
            for v in (sg, col, *lim.values()):
                v.both(why)
        tol = f"{LIMIT_TOLERANCE:.1%}"
        judged_text = f"{n_raw} trajectories of the planner, {n_checked} checked"
        return [
            sg.result(
                "start_goal",
                f"{len(solved)} {'query' if len(solved) == 1 else 'queries'} solved: "
                f"every trajectory starts within {START_TOLERANCE_RAD:g} rad of its start and ends on its goal",
            ),
            lim["velocity"].result(
                "velocity", f"{judged_text}: within max_joint_vel (+{tol}), declared qd and differences of q"
            ),
            lim["acceleration"].result(
                "acceleration", f"{judged_text}: within max_joint_acc (+{tol}), declared qdd and differences of q"
            ),
            self._jerk_result(lim["jerk"], judged_text, tol),
            col.result(
                "collision_free", f"{judged_text}: free at {self.res_rad:g} rad / {self.res_m:g} m of tool travel"
            ),
        ]

    def _jerk_result(self, verdict: _Verdict, judged_text: str, tol: str) -> CheckResult:
        """Jerk is judged for a planner that keeps it (`jerk_limited`, the default); one that declares
        `jerk_limited = False` (TOPP-RA timing bounds velocity and acceleration only) is reported, not failed."""
        if jerk_limited(self.recorder._inner):
            return verdict.result("jerk", f"{judged_text}: within max_joint_jerk (+{tol}), differences of qdd and of q")
        seen = (verdict.raw or verdict.checked or ["within max_joint_jerk"])[0]
        return CheckResult("jerk", True, f"not claimed: the planner declares jerk_limited = False ({seen})")

    def rule_time(self, outcomes: list[_Outcome]) -> CheckResult:
        v = _Verdict()
        worst_raw = worst_checked = 0.0
        for o in outcomes:
            limit = o.request.time_limit_s
            allowed = limit + time_slack_s(limit)
            for c in o.calls:
                worst_raw = max(worst_raw, c.elapsed_s)
                if c.elapsed_s > allowed:
                    v.fail(
                        "raw",
                        f"{o.label}: {c.what}() took {c.elapsed_s:.2f} s, "
                        f"limit {limit:g} s (+{time_slack_s(limit):.2f} s slack)",
                    )
                    break
            checked_times = o.checked_step_times if self.rh else [o.wall_s]
            for t in checked_times:
                worst_checked = max(worst_checked, t)
                if t > allowed:
                    v.fail(
                        "checked",
                        f"{o.label}: a checked {'step' if self.rh else 'plan'} took {t:.2f} s, "
                        f"limit {limit:g} s (+{time_slack_s(limit):.2f} s slack)",
                    )
                    break
        per = "reset()/step() call" if self.rh else "plan() call"
        return v.result(
            "time_limit",
            f"slowest {per} {worst_raw:.2f} s, checked {worst_checked:.2f} s; "
            f"limit {self.time_limit_s:g} s + {time_slack_s(self.time_limit_s):.2f} s slack",
        )

    def rule_determinism(self, first: _Outcome, again: _Outcome) -> CheckResult:
        v = _Verdict()
        if first.raw_error is None and again.raw_error is None:
            a, b = first.raw_trajectories(), again.raw_trajectories()
            why = _same(first.raw_result, again.raw_result)
            if why is None and len(a) != len(b):
                why = f"{len(a)} then {len(b)} segments"
            if why is None:
                why = next((w for w in (_same_traj(x, y) for x, y in zip(a, b, strict=True)) if w is not None), None)
            note = _clock_note(first, again)
            if why is not None:
                v.fail("raw", f"{first.label}: {why}{note}")
            why = _same(first.result, again.result)
            if why is not None:
                v.fail("checked", f"{first.label}: {why}{note}")
        status = "no result" if first.result is None else first.result.status.value
        return v.result("determinism", f"{first.label}: the same {status} twice (seed {first.request.seed})")

    def rule_invalid_start(self, outcomes: list[_Outcome], q_in: np.ndarray | None) -> CheckResult:
        v = _Verdict()
        found = [o for o in outcomes if o.purpose == "invalid_start"]
        if q_in is None or not found:
            v.both("no configuration in the table found to start from (scene without a table at z = 0?)")
        for o in found:
            if o.raw_error is not None:
                continue  # rule 1's failure
            raw = o.raw_result
            if o.segments:
                v.fail("raw", f"{o.label}: returned a segment instead of a status")
            elif raw is not None and raw.success:
                v.fail("raw", f"{o.label}: returned a trajectory ({raw.status.value})")
            if o.result is not None and o.result.success:
                v.fail("checked", f"{o.label}: returned a trajectory ({o.result.status.value})")
        status = found[0].result.status.value if found and found[0].result is not None else "-"
        return v.result("invalid_start", f"start in collision refused ({status})")

    # ---- helpers -----------------------------------------------------------------------------------
    def _goal_miss(self, request: MotionRequest, q_end: np.ndarray) -> str | None:
        return goal_miss(request.goal, q_end, self.kin)

    def _collision(self, traj: Trajectory) -> str | None:
        hit = first_collision(traj, self.scene, self.kin, max_step_rad=self.res_rad, max_step_m=self.res_m)
        if hit is None:
            return None
        qs = densify(traj, self.kin, max_step_rad=self.res_rad, max_step_m=self.res_m)
        return colliding_pair(self.scene, qs[hit])


# a planning call that took this share of its time limit ran until the limit ended it
_LIMIT_USED = 0.9


def _clock_note(*outcomes: _Outcome) -> str:
    """Why two answers to one request may differ when a planning call of either ran until its time limit: a
    search that the clock ends stops wherever the machine has got by then (a slower or busier machine gets
    less far). Said beside a determinism failure, so its fix is plain: end the search by a count."""
    limit = outcomes[0].request.time_limit_s
    used = [max((c.elapsed_s for c in o.calls), default=0.0) for o in outcomes]
    if max(used) < _LIMIT_USED * limit:
        return ""
    return (
        f" (a call ran until its time limit of {limit:g} s: a search the clock ends stops where the machine has "
        "got; end it by a count, e.g. iterations or a work budget)"
    )


def _limits(settings: Settings) -> Limits:
    return limits_from_settings(settings)
