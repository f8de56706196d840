"""Joint limits are part of the one judge: a trajectory or segment beyond the request's velocity or
acceleration limits (jerk too, for a planner that declares itself jerk-limited) is refused before it can
move the arm, in `twin plan`, `twin run` and `twin compare`, and every row says how close to its limits
a motion went (`max_vel_ratio`, `max_acc_ratio`, `max_jerk_ratio`).

`acme.hasty` (conftest.py) is a third-party planner whose straight line is timed by Ruckig under the
request's limits times `factor`: it would win every race it were allowed to run.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_runner import twin

from twin.collision import PlanningScene
from twin.config import PlannerBlock, load_config
from twin.failures import failure_of_plan
from twin.limit_check import LIMIT_TOLERANCE, limit_excess
from twin.planning import KinematicPlant, Segment, as_checked, limit_ratios, make_context, make_planner
from twin.types import JointGoal, Limits, MotionRequest, MotionResult, Status, Trajectory

ROBOCUP = load_config("robocup")
HOME = np.array(ROBOCUP.robot.home)
LIMITS = Limits.uniform(ROBOCUP.robot.max_joint_vel, ROBOCUP.robot.max_joint_acc, ROBOCUP.robot.max_joint_jerk)
# a long swing of the base: long enough for the velocity limit to bind
FAR = HOME + np.array([2.5, 0.0, 0.0, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def scene():
    return PlanningScene.from_settings(ROBOCUP)


@pytest.mark.parametrize("kind", ["velocity", "acceleration", "jerk"])
def test_each_limit_broken_is_refused_naming_joint_value_and_limit(acme_plugin, scene, kind):
    ctx = make_context(ROBOCUP)
    hasty = make_planner(PlannerBlock(name="acme.hasty", params={"limits": [kind], "factor": 2.0}), ctx)
    res = hasty.plan(MotionRequest(HOME, JointGoal(FAR), LIMITS), scene)
    assert res.status is Status.LIMIT_VIOLATION and res.trajectory is None
    assert f"{kind} joint 1 reaches" in res.reason and "limit" in res.reason, res.reason
    ratios = limit_ratios(res)
    assert ratios[kind] > 1.0 + LIMIT_TOLERANCE
    # only the broken limit is named
    assert all(k not in res.reason for k in {"velocity", "acceleration", "jerk"} - {kind})
    assert failure_of_plan(res.status.value, res.reason, res.info) == "limit_violation"


def test_a_planner_within_its_limits_passes_and_reports_its_ratios(acme_plugin, scene):
    ctx = make_context(ROBOCUP)
    res = make_planner(PlannerBlock(name="acme.hasty", params={"factor": 1.0}), ctx).plan(
        MotionRequest(HOME, JointGoal(FAR), LIMITS), scene
    )
    assert res.success, res.reason
    ratios = limit_ratios(res)
    assert set(ratios) == {"velocity", "acceleration", "jerk"}
    assert all(0.9 < r <= 1.0 + LIMIT_TOLERANCE for r in ratios.values()), ratios  # time-optimal: on its limits


class _JerkNotClaimed:
    """Declares `jerk_limited = False` (as a TOPP-RA-timed path does) and returns a quintic from rest to rest
    whose jerk is 3x its limit while velocity and acceleration keep theirs."""

    jerk_limited = False

    def plan(self, request, scene):
        d = request.goal.q - request.start
        T = float(np.cbrt(60.0 * np.abs(d).max() / (3.0 * request.limits.max_joint_jerk[0])))
        t = np.linspace(0.0, T, 400)
        u = t / T
        s = 10 * u**3 - 15 * u**4 + 6 * u**5
        sd = (30 * u**2 - 60 * u**3 + 30 * u**4) / T
        sdd = (60 * u - 180 * u**2 + 120 * u**3) / T**2
        traj = Trajectory(t, request.start + np.outer(s, d), np.outer(sd, d), np.outer(sdd, d))
        return MotionResult(Status.SUCCESS, "", traj)


def test_jerk_is_judged_only_for_a_planner_that_claims_it(scene):
    ctx = make_context(ROBOCUP)
    request = MotionRequest(HOME, JointGoal(HOME + [0.02, 0, 0, 0, 0, 0]), LIMITS)
    planner = _JerkNotClaimed()
    assert limit_excess(planner.plan(request, scene).trajectory, LIMITS)["jerk"].ratio > 2.5
    res = as_checked(planner, ctx, name="jerky").plan(request, scene)
    assert res.success, res.reason
    assert limit_ratios(res)["jerk"] > 2.5 and limit_ratios(res)["acceleration"] <= 1.0 + LIMIT_TOLERANCE
    _JerkNotClaimed.jerk_limited = True
    try:
        res = as_checked(planner, ctx, name="jerky").plan(request, scene)
    finally:
        _JerkNotClaimed.jerk_limited = False
    assert res.status is Status.LIMIT_VIOLATION and "jerk joint 1" in res.reason


def _cruise(start: np.ndarray, goal: np.ndarray, *, speed: float, acc: float | None) -> Trajectory:
    """Along the straight line: from rest at `acc` (None: at once) up to `speed` rad/s, then on at that
    speed up to the goal, where it ends without braking."""
    d = goal - start
    length = float(np.abs(d).max())
    t_acc = 0.0 if acc is None else speed / acc
    s_acc = 0.5 * speed * t_acc
    T = t_acc + (length - s_acc) / speed
    t = np.linspace(0.0, T, int(T / 1e-3) + 2)
    a = 0.0 if acc is None else acc
    s = np.where(t < t_acc, 0.5 * a * t**2, s_acc + speed * (t - t_acc))
    sd = np.where(t < t_acc, a * t, speed)
    sdd = np.where(t < t_acc, a, 0.0)
    u = d / length
    return Trajectory(t, start + np.outer(s, u), np.outer(sd, u), np.outer(sdd, u))


class _Slicer:
    """A receding-horizon planner that follows a motion planned at reset in slices of `dt_s`."""

    def __init__(self, motion, *, dt_s: float = 0.1, jerk_limited: bool = True):
        self.motion, self.dt_s, self.jerk_limited = motion, dt_s, jerk_limited

    def reset(self, request, scene):
        self.full, self.t = self.motion(np.array(request.start), np.array(request.goal.q)), 0.0

    def step(self, q):
        end = self.full.t[-1]
        if self.t >= end - 1e-12:
            return MotionResult(
                Status.SUCCESS, "arrived", Trajectory(np.zeros(1), q[None], np.zeros((1, 6)), np.zeros((1, 6)))
            )
        ts = np.linspace(self.t, min(end, self.t + self.dt_s), 6)
        self.t = ts[-1]
        qs, qds, qdds = self.full.sample(ts)
        qs[0] = q
        return Segment(Trajectory(ts - ts[0], qs, qds, qdds), 1e-4, {})


def test_a_receding_horizon_segment_beyond_the_limits_is_never_executed(scene):
    ctx = make_context(ROBOCUP)
    request = MotionRequest(HOME, JointGoal(HOME + [1.0, 0, 0, 0, 0, 0]), LIMITS)
    plant = KinematicPlant(HOME)
    sprinter = _Slicer(lambda a, b: _cruise(a, b, speed=10.0, acc=None))  # 3.2x the velocity limit, at once
    res = as_checked(sprinter, ctx, name="sprinter").drive(request, scene, plant)
    assert res.status is Status.LIMIT_VIOLATION and "segment 1 would exceed the joint limits" in res.reason
    assert "not executed" in res.reason and np.array_equal(plant.q, HOME)  # the arm never moved
    assert failure_of_plan(res.status.value, res.reason, res.info) == "limit_violation"
    assert limit_ratios(res)["velocity"] > 3.0


def test_a_receding_horizon_motion_that_cannot_stop_at_its_end_is_refused(scene):
    """Within the limits on every segment, but it arrives at full speed: stopping there takes an infinite
    deceleration, so the end is judged with the arm at rest after it."""
    ctx = make_context(ROBOCUP)
    request = MotionRequest(HOME, JointGoal(HOME + [0.3, 0, 0, 0, 0, 0]), LIMITS)
    plant = KinematicPlant(HOME)
    runner = _Slicer(lambda a, b: _cruise(a, b, speed=0.5, acc=4.0), jerk_limited=False)  # jerk not claimed
    res = as_checked(runner, ctx, name="runner").drive(request, scene, plant)
    assert res.status is Status.LIMIT_VIOLATION and res.reason.startswith("stopping at the end of segment"), res.reason
    assert "acceleration joint 1" in res.reason and "velocity" not in res.reason
    assert np.allclose(plant.q, request.goal.q)  # every segment was within the limits and ran


# ---- the command line: plan, run and compare refuse it alike ---------------------------------------------
def test_twin_plan_refuses_it_and_exits_1(acme_plugin, tmp_path):
    out = tmp_path / "plan.json"
    r = twin(
        "plan",
        "robocup",
        "--planner",
        "acme.hasty",
        "--start",
        ",".join(f"{v:.6f}" for v in HOME),
        "--goal",
        ",".join(f"{v:.6f}" for v in FAR),
        "--json",
        str(out),
        extra_path=acme_plugin,
    )
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert "acme.hasty: limit_violation" in r.stdout and "velocity joint 1 reaches" in r.stdout
    assert json.loads(out.read_text())["status"] == "limit_violation"


def test_twin_run_places_nothing_with_it(acme_plugin, tmp_path):
    out = tmp_path / "run.json"
    r = twin("run", "warehouse", "--seed", "1", "--planner", "acme.hasty", "--json", str(out), extra_path=acme_plugin)
    assert r.returncode == 1, (r.stdout[-2000:], r.stderr[-2000:])  # objects not placed
    data = json.loads(out.read_text())
    assert data["objects"] and not any(o["placed"] for o in data["objects"])
    assert {o["failure"] for o in data["objects"]} == {"limit_violation"}
    assert all("transfer: acme.hasty: limit_violation" in o["error"] for o in data["objects"])
    assert data["environment"]["python"] and data["environment"]["cpu"]  # where it ran
    hasty = data["metrics"]["acme.hasty"]
    assert hasty["succeeded"] == 0 and hasty["max_acc_ratio"] > 2.0
    # the built-in planners of the other stages kept their limits
    for name in ("ruckig.movej", "toppra.movel"):
        m = data["metrics"][name]
        assert m["max_vel_ratio"] <= 1.0 + LIMIT_TOLERANCE and m["max_acc_ratio"] <= 1.0 + LIMIT_TOLERANCE, (name, m)


def test_twin_compare_rows_fail_it_with_the_ratios(acme_plugin, tmp_path):
    from twin.compare import run_comparison
    from twin.compare.spec import compare_spec_from_dict
    from twin.config import PROJECT_ROOT

    spec = compare_spec_from_dict(
        {
            "name": "limits",
            "planners": ["acme.hasty", "ruckig.movej"],
            "scenarios": [
                {"name": "swing", "scene": "robocup.yaml", "queries": [{"start": HOME.tolist(), "goal": FAR.tolist()}]}
            ],
        },
        base_dir=PROJECT_ROOT / "configs",
    )
    result = run_comparison(spec, out_dir=tmp_path / "out", workers=0, plots=False)
    rows = {r["planner"]: r for r in result.rows}
    hasty, ruckig = rows["acme.hasty"], rows["ruckig.movej"]
    assert not hasty["success"] and hasty["status"] == "limit_violation" and hasty["failure"] == "limit_violation"
    assert hasty["metrics"]["max_vel_ratio"] > 1.0 + LIMIT_TOLERANCE and hasty["metrics"]["max_acc_ratio"] > 2.0
    assert hasty["metrics"]["duration_s"] is None  # nothing it planned was accepted, so nothing was measured
    assert ruckig["success"] and 0.9 < ruckig["metrics"]["max_vel_ratio"] <= 1.0 + LIMIT_TOLERANCE
    summary = (tmp_path / "out" / "summary.md").read_text()
    assert "limit_violation" in summary


# ---- the measure itself: what round-off may do, and what it may not hide -----------------------------------
def _ruckig_swing(dt: float = 1e-3) -> Trajectory:
    import ruckig

    otg, inp, out = ruckig.Ruckig(6), ruckig.InputParameter(6), ruckig.Trajectory(6)
    inp.current_position, inp.target_position = HOME.tolist(), FAR.tolist()
    inp.max_velocity, inp.max_acceleration = LIMITS.max_joint_vel.tolist(), LIMITS.max_joint_acc.tolist()
    inp.max_jerk = LIMITS.max_joint_jerk.tolist()
    otg.calculate(inp, out)
    t = np.linspace(0.0, out.duration, int(out.duration / dt) + 2)  # a last interval shorter than the rest
    q, qd, qdd = (np.array(x) for x in zip(*(out.at_time(float(ti)) for ti in t), strict=True))
    return Trajectory(t, q, qd, qdd)


def test_position_round_off_is_not_a_violation_and_the_end_is_judged_where_it_is():
    """A time-optimal motion on its limits, sampled every 1 ms, with 3 nrad of noise on its positions (what a
    planner's own integration leaves): the third differences of 1 ms samples would read 1.1x the jerk limit;
    the judge reads the limit. Its end is judged where the motion ends, not at the last sample it thins to."""
    swing = _ruckig_swing()
    noisy = Trajectory(
        swing.t, swing.q + np.random.default_rng(0).uniform(-3e-9, 3e-9, swing.q.shape), swing.qd, swing.qdd
    )
    for traj in (swing, noisy):
        excess = limit_excess(traj, LIMITS)
        assert all(e.ratio <= 1.0 + LIMIT_TOLERANCE for e in excess.values()), excess
        assert excess["jerk"].ratio > 0.99  # on its jerk limit: nothing hides a real excess
    # the same motion 3 % faster everywhere breaks every limit, and the judge says so
    fast = Trajectory(swing.t / 1.03, swing.q, swing.qd * 1.03, swing.qdd * 1.03**2)
    assert {k for k, e in limit_excess(fast, LIMITS).items() if e.ratio > 1.0 + LIMIT_TOLERANCE} == {
        "velocity",
        "acceleration",
        "jerk",
    }


def test_thinning_keeps_the_samples_a_search_after_each_kept_one_keeps() -> None:
    from twin.limit_check import _thinned

    def reference(t, min_dt):  # before issue 41: one search after each kept sample
        n = t.shape[0]
        if n < 2 or float(np.diff(t).min()) >= min_dt:
            return np.arange(n)
        keep = [0]
        while (j := int(np.searchsorted(t, t[keep[-1]] + min_dt, side="left"))) < n:
            keep.append(j)
        if keep[-1] != n - 1:
            if len(keep) > 1 and t[-1] - t[keep[-1]] < min_dt:
                keep[-1] = n - 1
            else:
                keep.append(n - 1)
        return np.array(keep)

    rng = np.random.default_rng(41)
    for trial in range(200):
        n = int(rng.integers(1, 400))
        t = np.cumsum(rng.choice([0.0, 0.0005, 0.001, 0.004], n)) if trial % 2 else np.arange(n) * 0.001
        min_dt = float(rng.choice([0.0005, 0.001, 0.002, 0.0037, 0.01]))
        assert np.array_equal(_thinned(t, min_dt), reference(t, min_dt))
