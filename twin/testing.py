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
colliding trajectory, and pass others on, such as a limit violation). A rule passes when both pass; a
`PlanningError` with which CheckedPlanner refuses the plugin's output counts as refused, not as a crash.
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
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.errors import PlanningError, TwinError
from twin.types import JointGoal, Limits, MotionRequest, MotionResult, Pose, PoseGoal, Trajectory

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.config import PlannerBlock, Settings
    from twin.kinematics import UR5e
    from twin.planning import CheckedPlanner
    from twin.registry import PluginContext, Registry

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

log = logging.getLogger("twin")

# rule name -> (number of the rule in the contract, what it demands)
RULES: dict[str, tuple[int, str]] = {
    "statuses": (1, "a status, never an exception; unreachable and colliding goals get a failure status with a reason"),
    "start_goal": (
        2,
        "starts exactly at the start (segments: at the measured state), ends on the goal within its tolerance",
    ),
    "velocity": (3, "joint velocities within the request's limits"),
    "acceleration": (3, "joint accelerations within the request's limits"),
    "jerk": (3, "joint jerks within the request's limits"),
    "time_limit": (4, "every planning call returns within the request's time limit (plus slack)"),
    "determinism": (5, "the same request and seed give the same status and trajectory"),
    "invalid_start": (6, "a start in collision gets a status, not a trajectory"),
    "collision_free": (7, "no trajectory or segment it returns collides (FCL, configured resolution)"),
}

START_TOLERANCE_RAD = 1e-6  # what CheckedPlanner accepts as "starts at the start / measured state"
# Relative excess over a limit that is still float round-off, not a violation: Ruckig and the quintic hit
# their limits exactly, TOPP-RA's samples are kept under them, and 0.1 % of pi rad/s is 3 mrad/s.
LIMIT_TOLERANCE = 1e-3
# The divided differences of q are taken over samples at least this far apart (s): closer samples (a
# trajectory's last sample 1e-12 s after the previous one) would turn round-off into huge "jerk".
_MIN_DIFF_DT_S = 5e-4
_TRAJ_ATOL = 1e-9  # two trajectories are "the same" when t and q agree within this
_CLEARANCE_M = 0.02  # queries' starts and goals are at least this far from anything
_MAX_SEGMENTS = 300  # a receding-horizon planner that has not finished after this many segments is cut off


def time_slack_s(time_limit_s: float) -> float:
    """How far past `time_limit_s` a planning call may return: 25 % of the limit plus 0.3 s.

    Why: a planner stops searching at its deadline, but the work after the search (shortcutting,
    retiming, the final collision check of the trajectory) cannot be cut short without returning
    nothing; Python cannot pre-empt a native call at an exact instant; and a loaded CI machine adds
    scheduling noise of a few 100 ms. A planner that ignores its limit overshoots by far more."""
    return 0.25 * time_limit_s + 0.3


# ---- results ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CheckResult:
    """One rule's verdict: `passed` when both the plugin's own output (`raw`) and what the runs get through
    `CheckedPlanner` (`checked`) keep it; `detail` says why, in one line."""

    rule: str
    passed: bool
    detail: str
    raw: bool = True
    checked: bool = True

    @property
    def number(self) -> int:
        return RULES[self.rule][0]

    @property
    def description(self) -> str:
        return RULES[self.rule][1]

    def to_json(self) -> dict[str, Any]:
        return {
            "rule": self.rule,
            "number": self.number,
            "passed": self.passed,
            "raw": self.raw,
            "checked": self.checked,
            "detail": self.detail,
            "description": self.description,
        }


@dataclass(frozen=True)
class ConformanceReport:
    """What `check_planner` found: one `CheckResult` per rule, and what was asked (`requests`)."""

    planner: str
    kind: str  # "one-shot" or "receding-horizon"
    config: str
    seed: int
    time_limit_s: float
    goal_kinds: tuple[str, ...]
    results: tuple[CheckResult, ...]
    requests: tuple[dict[str, Any], ...] = ()
    wall_time_s: float = 0.0

    @property
    def ok(self) -> bool:
        return all(r.passed for r in self.results)

    @property
    def failures(self) -> list[CheckResult]:
        return [r for r in self.results if not r.passed]

    def result(self, rule: str) -> CheckResult:
        for r in self.results:
            if r.rule == rule:
                return r
        raise KeyError(f"no rule {rule!r}; rules: {', '.join(RULES)}")

    def summary(self) -> str:
        """'ompl.rrtconnect: 9/9 rules pass' or the failures, one per line."""
        head = f"{self.planner}: {len(self.results) - len(self.failures)}/{len(self.results)} rules pass"
        return "\n".join([head] + [f"  {r.number} {r.rule}: {r.detail}" for r in self.failures])

    def to_json(self) -> dict[str, Any]:
        return {
            "planner": self.planner,
            "kind": self.kind,
            "config": self.config,
            "seed": self.seed,
            "time_limit_s": self.time_limit_s,
            "time_slack_s": time_slack_s(self.time_limit_s),
            "goal_kinds": list(self.goal_kinds),
            "ok": self.ok,
            "rules": [r.to_json() for r in self.results],
            "requests": list(self.requests),
            "wall_time_s": self.wall_time_s,
        }


# ---- queries ------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Query:
    """A collision-free start (6,) and goal configuration (6,), rad; `straight_free`: whether the straight
    joint motion between them is free (False: a planner has to search)."""

    start: np.ndarray
    goal: np.ndarray
    straight_free: bool
    label: str


def _top_down(p: np.ndarray, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])  # tool z down, turned by yaw
    T[:3, 3] = p
    return T


class _Sampler:
    """Collision-free top-down configurations in the scene's reach, on the IK branch nearest `home`."""

    def __init__(self, scene: PlanningScene, kin: UR5e, home: np.ndarray, rng: np.random.Generator):
        self.scene, self.kin, self.home, self.rng = scene, kin, home, rng

    def pose(self) -> tuple[np.ndarray, float]:
        r = self.rng.uniform(0.30, 0.70)
        a = self.rng.uniform(0.5 * math.pi, 1.5 * math.pi)  # in front of the arm (the work area lies at -x)
        p = np.array([r * math.cos(a), r * math.sin(a), self.rng.uniform(0.03, 0.30)])
        return p, float(self.rng.uniform(-0.5 * math.pi, 0.5 * math.pi))

    def config(self, T: np.ndarray, near: np.ndarray) -> np.ndarray | None:
        sols = self.kin.ik(T, all_wraps=False)
        if sols.shape[0] == 0:
            return None
        q = sols[int(np.argmin(np.abs(sols - near).max(axis=1)))]
        if self.scene.in_collision(q) or self.scene.min_distance(q, include_self=False).distance < _CLEARANCE_M:
            return None
        return q

    def free(self, a: np.ndarray, b: np.ndarray, resolution_rad: float) -> bool:
        return bool(self.scene.check_path(np.stack([a, b]), resolution_rad=resolution_rad).free)

    def line_free(self, a: np.ndarray, Tb: np.ndarray) -> bool:
        """Whether the tool can move on the straight line from its pose at `a` to `Tb` (yaw turning
        evenly) without colliding or jumping IK branches, checked every 1 cm."""
        Ta = self.kin.fk(a, "tcp")
        n = max(2, math.ceil(float(np.linalg.norm(Tb[:3, 3] - Ta[:3, 3])) / 0.01) + 1)
        ya, yb = math.atan2(Ta[1, 0], Ta[0, 0]), math.atan2(Tb[1, 0], Tb[0, 0])
        dy = math.remainder(yb - ya, 2 * math.pi)
        q, qs = a, []
        for s in np.linspace(0.0, 1.0, n)[1:]:
            sols = self.kin.ik(_top_down(Ta[:3, 3] + s * (Tb[:3, 3] - Ta[:3, 3]), ya + s * dy), all_wraps=False)
            if sols.shape[0] == 0:
                return False
            nxt = sols[int(np.argmin(np.abs(sols - q).max(axis=1)))]
            if np.abs(nxt - q).max() > 0.3:
                return False
            q = nxt
            qs.append(q)
        return not bool(self.scene.in_collision_batch(np.array(qs)).any())


def contract_queries(
    settings: Settings, scene: PlanningScene, kin: UR5e, n: int, seed: int, *, blocked: bool = True
) -> list[Query]:
    """`n` seeded queries in `scene`: a move of at least 0.2 m of tool travel whose straight joint motion and
    straight tool line are free; with `blocked`, one whose straight joint motion collides (a sampling planner
    must search); a short move (8-15 cm, a small turn, the same IK branch: a Cartesian line's query); then
    free or blocked moves of at least 0.2 m. Deterministic for a given scene and seed; raises TwinError when
    the scene offers no such queries."""
    rng = np.random.default_rng(seed)
    home = np.asarray(settings.robot.home, dtype=float)
    res = settings.collision.check_resolution_rad
    s = _Sampler(scene, kin, home, rng)
    out: list[Query] = []
    for _ in range(4000):
        if len(out) >= n:
            return out
        p, yaw = s.pose()
        a = s.config(_top_down(p, yaw), home)
        if a is None:
            continue
        short = 2 if blocked else 1
        if len(out) == short:
            d = rng.uniform(0.08, 0.15)
            h = rng.uniform(0.0, 2 * math.pi)
            pb = p + np.array([d * math.cos(h), d * math.sin(h), rng.uniform(-0.03, 0.03)])
            b = s.config(_top_down(pb, yaw + rng.uniform(-0.3, 0.3)), a)
            if b is None or np.abs(b - a).max() > 1.0 or not s.free(a, b, res) or not s.line_free(a, kin.fk(b, "tcp")):
                continue
            out.append(Query(a, b, True, "short move, straight joint motion free"))
            continue
        pb, yb = s.pose()
        b = s.config(_top_down(pb, yb), a)
        if b is None or np.linalg.norm(pb - p) < 0.2:
            continue
        free = s.free(a, b, res)
        if len(out) < short and free != (len(out) == 0):  # the first free, the second blocked
            continue
        if len(out) == 0 and not s.line_free(a, _top_down(pb, yb)):  # free for a Cartesian line as well
            continue
        out.append(Query(a, b, free, "straight joint motion " + ("free" if free else "blocked")))
    raise TwinError(
        f"found only {len(out)} of {n} collision-free queries in the scene (seed {seed}); is the work area blocked?"
    )


def _goal(kind: str, q: np.ndarray, kin: UR5e) -> JointGoal | PoseGoal:
    """The goal configuration `q` as a goal of `kind`: the joints, the tool pose, or the tool position
    (orientation free, within 3 cm: what a task's transfer asks for)."""
    if kind == "joint":
        return JointGoal(q)
    pose = Pose.from_matrix(kin.fk(q, "tcp"))
    if kind == "pose":
        return PoseGoal(pose)
    return PoseGoal(pose, position_tolerance_m=0.03, orientation_tolerance_rad=None)


def _served_goal(kinds: tuple[str, ...], T: np.ndarray, q: np.ndarray | None, kind: str) -> JointGoal | PoseGoal | None:
    if kind not in kinds:
        return None
    if kind == "joint":
        return None if q is None else JointGoal(q)
    if kind == "pose":
        return PoseGoal(Pose.from_matrix(T))
    return PoseGoal(Pose.from_matrix(T), position_tolerance_m=0.03, orientation_tolerance_rad=None)


# ---- recording what the plugin itself returns -------------------------------------------------------------
@dataclass(eq=False)
class _Call:
    """One call into the plugin: `what` (plan, reset, step), its wall time, and its output or exception."""

    what: str
    elapsed_s: float
    output: Any = None
    error: BaseException | None = None


class _Recorder:
    """Stands in for the plugin inside its CheckedPlanner and records every call and what it returned."""

    def __init__(self, inner: Any):
        self._inner = inner
        self.calls: list[_Call] = []

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__"):
            raise AttributeError(attr)
        return getattr(self._inner, attr)

    def _call(self, what: str, fn: Callable[[], Any]) -> Any:
        t0 = time.perf_counter()
        try:
            out = fn()
        except Exception as e:
            self.calls.append(_Call(what, time.perf_counter() - t0, error=e))
            raise
        self.calls.append(_Call(what, time.perf_counter() - t0, output=out))
        return out

    def plan(self, request: MotionRequest, scene: PlanningScene) -> Any:
        return self._call("plan", lambda: self._inner.plan(request, scene))

    def reset(self, request: MotionRequest, scene: PlanningScene) -> Any:
        return self._call("reset", lambda: self._inner.reset(request, scene))

    def step(self, q: np.ndarray) -> Any:
        return self._call("step", lambda: self._inner.step(q))


class _TimingPlant:
    """The kinematic plant (`twin.planning.KinematicPlant`), timing each checked step: from the state read
    to the checked segment handed over."""

    def __init__(self, q: np.ndarray):
        self.q = np.asarray(q, dtype=float).copy()
        self.step_times: list[float] = []
        self._t: float | None = None

    def measured_q(self) -> np.ndarray:
        self._t = time.perf_counter()
        return self.q

    def run(self, traj: Trajectory) -> str | None:
        if self._t is not None:
            self.step_times.append(time.perf_counter() - self._t)
        self.q = traj.q[-1].copy()
        return None


@dataclass(eq=False)
class _Outcome:
    """One request, asked once: what the plugin returned (`calls`) and what the runs got (`result`)."""

    label: str
    purpose: str  # "query", "unreachable", "colliding_goal", "invalid_start", "repeat"
    request: MotionRequest
    calls: list[_Call]
    result: MotionResult | None
    error: BaseException | None  # raised out of the checked call (by the plugin or by CheckedPlanner)
    wall_s: float
    checked_step_times: list[float] = field(default_factory=list)

    @property
    def raw_error(self) -> BaseException | None:
        return next((c.error for c in self.calls if c.error is not None), None)

    @property
    def segments(self) -> list[Any]:
        return [
            c.output
            for c in self.calls
            if c.what == "step" and c.output is not None and not isinstance(c.output, MotionResult)
        ]

    @property
    def raw_result(self) -> MotionResult | None:
        """The plugin's own final answer: plan()'s result, or the MotionResult a step() ended with."""
        for c in self.calls:
            if c.what in ("plan", "step") and isinstance(c.output, MotionResult):
                return c.output
        return None

    def raw_trajectories(self) -> list[Trajectory]:
        """Every trajectory the plugin returned: a one-shot result's, or each segment's."""
        out = [s.trajectory for s in self.segments if isinstance(getattr(s, "trajectory", None), Trajectory)]
        r = self.raw_result
        if r is not None and r.success and r.trajectory is not None and not self.segments:
            out.append(r.trajectory)
        return out

    def raw_motion(self) -> Trajectory | None:
        """The motion the plugin commanded as one trajectory (segments joined as `drive` joins them)."""
        trajs = self.raw_trajectories()
        if not trajs:
            return None
        return trajs[0] if len(trajs) == 1 else _join(trajs)

    def to_json(self) -> dict[str, Any]:
        raw = self.raw_result
        return {
            "label": self.label,
            "purpose": self.purpose,
            "goal_kind": self.request.goal.kind,
            "raw_status": None if raw is None else raw.status.value,
            "raw_segments": len(self.segments),
            "raw_error": None if self.raw_error is None else f"{type(self.raw_error).__name__}: {self.raw_error}",
            "status": None if self.result is None else self.result.status.value,
            "reason": None if self.result is None else self.result.reason,
            "error": None if self.error is None else f"{type(self.error).__name__}: {self.error}",
            "wall_time_s": self.wall_s,
        }


def _join(pieces: list[Trajectory]) -> Trajectory:
    t, q, qd, qdd = [pieces[0].t - pieces[0].t[0]], [pieces[0].q], [pieces[0].qd], [pieces[0].qdd]
    offset = float(t[0][-1])
    for p in pieces[1:]:
        if p.t.shape[0] < 2:
            continue
        t.append(p.t[1:] - p.t[0] + offset)
        q.append(p.q[1:])
        qd.append(p.qd[1:])
        qdd.append(p.qdd[1:])
        offset = float(t[-1][-1])
    return Trajectory(np.concatenate(t), np.concatenate(q), np.concatenate(qd), np.concatenate(qdd))


# ---- judging a trajectory ----------------------------------------------------------------------------------
def _thinned(t: np.ndarray, min_dt: float) -> np.ndarray:
    """Indices of samples at least `min_dt` apart (the first and, if far enough, the last kept)."""
    keep = [0]
    for i in range(1, t.shape[0]):
        if t[i] - t[keep[-1]] >= min_dt:
            keep.append(i)
    return np.array(keep)


def limit_violations(
    traj: Trajectory,
    limits: Limits,
    *,
    tolerance: float = LIMIT_TOLERANCE,
    from_rest: bool = True,
    to_rest: bool = True,
) -> dict[str, str]:
    """{'velocity' | 'acceleration' | 'jerk': why} for every limit `traj` exceeds by more than `tolerance`
    (relative). Judged on the declared qd and qdd (jerk: differences of qdd between samples) and on the
    divided differences of q, which a motion that keeps a limit cannot exceed (mean value theorem).

    `from_rest`: the arm stands still before the first sample (a request has no start velocity), so a
    trajectory that begins moving jumps from rest; `to_rest`: it holds the last sample afterwards."""
    out: dict[str, str] = {}
    if traj.t.shape[0] < 2:
        return out
    i = _thinned(traj.t, _MIN_DIFF_DT_S)
    t, q, qd, qdd = traj.t[i], traj.q[i], traj.qd[i], traj.qdd[i]
    if t.shape[0] >= 2:  # standing still: three samples of rest before and after, at the first/last spacing
        k = np.arange(3, 0, -1)[:, None]
        if from_rest:
            h = t[1] - t[0]
            t = np.concatenate([t[0] - h * k[:, 0], t])
            q, qd, qdd = (
                np.vstack([np.repeat(q[:1], 3, 0), q]),
                np.vstack([np.zeros((3, 6)), qd]),
                np.vstack([np.zeros((3, 6)), qdd]),
            )
        if to_rest:
            h = t[-1] - t[-2]
            t = np.concatenate([t, t[-1] + h * k[::-1, 0]])
            q, qd, qdd = (
                np.vstack([q, np.repeat(q[-1:], 3, 0)]),
                np.vstack([qd, np.zeros((3, 6))]),
                np.vstack([qdd, np.zeros((3, 6))]),
            )
    dt = np.diff(t)[:, None]
    d1 = np.diff(q, axis=0) / dt
    d2 = 2.0 * np.diff(d1, axis=0) / (t[2:] - t[:-2])[:, None] if t.shape[0] > 2 else np.zeros((0, 6))
    d3 = 3.0 * np.diff(d2, axis=0) / (t[3:] - t[:-3])[:, None] if t.shape[0] > 3 else np.zeros((0, 6))
    jerk_declared = np.diff(qdd, axis=0) / dt
    checks = (
        ("velocity", limits.max_joint_vel, "rad/s", (("declared qd", qd), ("differences of q", d1))),
        ("acceleration", limits.max_joint_acc, "rad/s^2", (("declared qdd", qdd), ("second differences of q", d2))),
        (
            "jerk",
            limits.max_joint_jerk,
            "rad/s^3",
            (("differences of qdd", jerk_declared), ("third differences of q", d3)),
        ),
    )
    for name, lim, unit, sources in checks:
        worst: tuple[float, str, int, float] | None = None
        for src, values in sources:
            if values.size == 0:
                continue
            ratio = np.abs(values) / lim[None, :]
            k2 = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
            r = float(ratio[k2])
            if worst is None or r > worst[0]:
                worst = (r, src, int(k2[1]), float(np.abs(values[k2])))
        if worst is not None and worst[0] > 1.0 + tolerance:
            r, src, j, v = worst
            out[name] = f"joint {j + 1} reaches {v:.4g} {unit} ({src}), limit {lim[j]:.4g} ({r:.2f}x)"
    return out


def _same(a: MotionResult | None, b: MotionResult | None) -> str | None:
    """Why two results differ (status, or trajectory beyond _TRAJ_ATOL), or None."""
    if a is None or b is None:
        return None if a is b else "one call returned no result"
    if a.status is not b.status:
        return f"{a.status.value} then {b.status.value}"
    ta, tb = a.trajectory, b.trajectory
    if ta is None or tb is None:
        return None if ta is tb else "a trajectory only once"
    return _same_traj(ta, tb)


def _same_traj(ta: Trajectory, tb: Trajectory) -> str | None:
    if ta.t.shape != tb.t.shape:
        return f"{ta.t.shape[0]} then {tb.t.shape[0]} samples"
    dq = float(np.abs(ta.q - tb.q).max())
    dt = float(np.abs(ta.t - tb.t).max())
    if dq > _TRAJ_ATOL or dt > _TRAJ_ATOL:
        return f"trajectories differ by up to {dq:.3g} rad, {dt:.3g} s"
    return None


# ---- the check ---------------------------------------------------------------------------------------------
class _Verdict:
    """Collects the failures of one rule on both layers; the first reason of each is kept for the detail."""

    def __init__(self) -> None:
        self.raw: list[str] = []
        self.checked: list[str] = []

    def fail(self, layer: str, why: str) -> None:
        (self.raw if layer == "raw" else self.checked).append(why)

    def both(self, why: str) -> None:
        self.raw.append(why)
        self.checked.append(why)

    def result(self, rule: str, ok_detail: str) -> CheckResult:
        raw_ok, checked_ok = not self.raw, not self.checked
        if raw_ok and checked_ok:
            return CheckResult(rule, True, ok_detail)
        parts = []
        if self.raw and self.checked and self.raw[0] == self.checked[0]:
            parts.append(self.raw[0] + _more(self.raw))
        else:
            if self.raw:
                parts.append("the planner itself: " + self.raw[0] + _more(self.raw))
            if self.checked:
                parts.append("through CheckedPlanner: " + self.checked[0] + _more(self.checked))
        return CheckResult(rule, False, "; ".join(parts), raw_ok, checked_ok)


def _more(items: list[str]) -> str:
    return f" (and {len(items) - 1} more)" if len(items) > 1 else ""


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
        from twin.planning import Segment

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
        from twin.planning import jerk_limited

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
            if why is not None:
                v.fail("raw", f"{first.label}: {why}")
            why = _same(first.result, again.result)
            if why is not None:
                v.fail("checked", f"{first.label}: {why}")
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
        from twin.planning import goal_miss

        return goal_miss(request.goal, q_end, self.kin)

    def _collision(self, traj: Trajectory) -> str | None:
        from twin.planning import colliding_pair, densify, first_collision

        hit = first_collision(traj, self.scene, self.kin, max_step_rad=self.res_rad, max_step_m=self.res_m)
        if hit is None:
            return None
        qs = densify(traj, self.kin, max_step_rad=self.res_rad, max_step_m=self.res_m)
        return colliding_pair(self.scene, qs[hit])


def _limits(settings: Settings) -> Limits:
    from twin.planning import limits_from_settings

    return limits_from_settings(settings)


DEFAULT_CONFIG = "robocup"  # the shipped reference config whose scene and limits the check uses by default


def _default_settings() -> Settings:
    from twin.config import load_config

    return load_config(DEFAULT_CONFIG)


def _block(
    planner: PlannerBlock | str | dict[str, Any] | type, registry: Registry | None
) -> tuple[PlannerBlock, Registry | None]:
    """A config block for `planner` (a name, a block or its dict, or a planner class, registered here
    under 'check.<class name>' in a registry of every installed plugin plus this class)."""
    from twin.config import PlannerBlock

    if isinstance(planner, PlannerBlock):
        return planner, registry
    if isinstance(planner, str):
        return PlannerBlock(name=planner), registry
    if isinstance(planner, dict):
        return PlannerBlock(**planner), registry
    if isinstance(planner, type):
        from twin.registry import Registry, plugin_manager

        reg = registry or Registry.from_plugin_manager(plugin_manager())
        name = f"check.{planner.__name__.lower()}"
        rh = callable(getattr(planner, "reset", None)) and callable(getattr(planner, "step", None))
        if name not in reg.names():
            reg.add_planner(name, planner, receding_horizon=rh, description="checked by twin.testing")
        return PlannerBlock(name=name), reg
    raise TypeError(f"planner must be a name, a PlannerBlock, a dict or a class, got {type(planner).__name__}")


def check_planner(
    planner: PlannerBlock | str | dict[str, Any] | type,
    *,
    settings: Settings | None = None,
    seed: int = 0,
    queries: int | None = None,
    time_limit_s: float = 1.0,
    registry: Registry | None = None,
    config_name: str | None = None,
    on_progress: Callable[[str], None] | None = None,
) -> ConformanceReport:
    """Check one planner against the planner contract (the module docstring lists the rules).

    `planner`: a registered name, a config block (`{name, params, retimer}`), or a planner class (then
    registered for the check). `settings`: the scene and limits (default: the shipped config 'robocup').
    `queries`: collision-free queries to plan (default 3 for one-shot planners, 2 for receding-horizon
    ones, whose every step is a solve). `time_limit_s`: the requests' time limit. `registry`: where the
    name is looked up (default: every installed plugin). `on_progress(text)` is told each request asked.

    Bad input (an unknown name, bad params, a missing backend) raises a TwinError, as `make_planner` does;
    every breach of the contract is a failed `CheckResult` in the report, never an exception."""
    from twin.collision import PlanningScene
    from twin.planning import make_context, make_planner

    if not (math.isfinite(time_limit_s) and time_limit_s > 0):
        from twin.errors import InvalidRequestError

        raise InvalidRequestError(f"time_limit_s must be positive, got {time_limit_s}")
    t0 = time.perf_counter()
    block, registry = _block(planner, registry)
    if settings is None:
        settings = _default_settings()
        config_name = config_name or DEFAULT_CONFIG
    context = make_context(settings, registry)
    checked = make_planner(block, context)
    rh = checked.receding_horizon
    n = queries if queries is not None else (2 if rh else 3)
    if n < 1:
        from twin.errors import InvalidRequestError

        raise InvalidRequestError(f"queries must be at least 1, got {n}")
    scene = PlanningScene.from_settings(settings)
    scene.add_unknown_fixtures(settings)  # obstacles perception would report, reported perfectly
    checker = _Checker(
        checked,
        block.name,
        settings,
        scene,
        context,
        seed=seed,
        time_limit_s=time_limit_s,
        progress=on_progress or (lambda _: None),
    )
    results, outcomes = checker.run(n)
    return ConformanceReport(
        planner=block.name,
        kind="receding-horizon" if rh else "one-shot",
        config=config_name or settings.name,
        seed=seed,
        time_limit_s=time_limit_s,
        goal_kinds=checker.kinds,
        results=tuple(results),
        requests=tuple(o.to_json() for o in outcomes),
        wall_time_s=time.perf_counter() - t0,
    )


def assert_conformant(
    planner: PlannerBlock | str | dict[str, Any] | type, *, ignore: Iterable[str] = (), **kwargs: Any
) -> ConformanceReport:
    """`check_planner(planner, **kwargs)`, raising AssertionError that lists every failed rule (those in
    `ignore` aside); returns the report. For a plugin's own test suite."""
    report = check_planner(planner, **kwargs)
    skip = set(ignore)
    unknown = skip - set(RULES)
    if unknown:
        raise ValueError(f"unknown rules {sorted(unknown)}; rules: {', '.join(RULES)}")
    failed = [r for r in report.failures if r.rule not in skip]
    if failed:
        lines = "\n".join(f"  rule {r.number} {r.rule}: {r.detail}" for r in failed)
        raise AssertionError(
            f"{report.planner} breaks the planner contract ({report.config}, seed {report.seed}):\n{lines}"
        )
    return report
