"""Progress and quiet (issue 38): -v/-q before or after the command; elapsed time and an estimate of the time
left in `twin run`'s display, `twin compare`'s lines and `--dry-run`; no banner of PyBullet, its EGL plugin or
Crocoddyl in a command's output; a repeated refusal of the judge said once, with which joint, how far and when.
Every clock here is a fake one: no assertion depends on how fast the machine is."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
import pytest
from cli_runner import twin

from twin.cli import build_parser, compare_progress, progress_line
from twin.compare.estimate import ROUGH_QUERY_OVERHEAD_S, ROUGH_TASK_RUN_S, estimate_sweep
from twin.compare.spec import RunTask
from twin.config import load_config
from twin.progress import ProgressClock, RunDisplay, clock_text
from twin.types import JointGoal, Limits, MotionRequest, MotionResult, Status, Trajectory

ROBOCUP = load_config("robocup")
HOME = np.array(ROBOCUP.robot.home)
LIMITS = Limits.uniform(ROBOCUP.robot.max_joint_vel, ROBOCUP.robot.max_joint_acc, ROBOCUP.robot.max_joint_jerk)


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


# ---- -v / -q anywhere ------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("before", "after"),
    [
        (["-v", "run", "robocup"], ["run", "robocup", "-v"]),
        (["-v", "run", "robocup"], ["run", "-v", "robocup"]),
        (["-vv", "compare", "c.yaml"], ["compare", "c.yaml", "-vv"]),
        (["-v", "-v", "plan", "robocup"], ["plan", "robocup", "--verbose", "-v"]),
        (["-q", "run", "robocup"], ["run", "robocup", "--quiet"]),
        (["--quiet", "planners"], ["planners", "-q"]),
    ],
)
def test_verbose_and_quiet_parse_the_same_before_and_after_the_command(before, after):
    parser = build_parser()
    if before[-2:] == ["plan", "robocup"]:  # `plan` needs its query; the same on both sides
        query = ["--planner", "ruckig.movej", "--start", "0,0,0,0,0,0", "--goal", "0,0,0,0,0,0"]
        before, after = before + query, after + query
    assert vars(parser.parse_args(before)) == vars(parser.parse_args(after))


def test_verbose_counts_on_both_sides_and_excludes_quiet(capsys):
    parser = build_parser()
    assert parser.parse_args(["-v", "run", "robocup", "-v"]).verbose == 2
    assert parser.parse_args(["run", "robocup"]).verbose == 0 and not parser.parse_args(["run", "robocup"]).quiet
    with pytest.raises(SystemExit) as e:
        parser.parse_args(["-v", "run", "robocup", "-q"])
    assert e.value.code == 2 and "exclude each other" in capsys.readouterr().err


def test_quiet_leaves_the_result_and_drops_the_warning(acme_plugin):
    """`acme.hasty` breaks the velocity limit: the judge's warning names joint, value and time; -q (after the
    command) keeps the result line on stdout and nothing else."""
    far = HOME + np.array([2.5, 0.0, 0.0, 0.0, 0.0, 0.0])
    query = ["--start", ",".join(f"{v:.6f}" for v in HOME), "--goal", ",".join(f"{v:.6f}" for v in far)]
    loud = twin("plan", "robocup", "--planner", "acme.hasty", *query, extra_path=acme_plugin)
    quiet = twin("plan", "robocup", "--planner", "acme.hasty", *query, "-q", extra_path=acme_plugin)
    assert loud.returncode == quiet.returncode == 1, (loud.stderr, quiet.stderr)
    warning = [line for line in loud.stderr.splitlines() if line.startswith("WARNING")]
    assert len(warning) == 1 and "acme.hasty returned a trajectory beyond the joint limits" in warning[0], loud.stderr
    assert "velocity joint 1 reaches" in warning[0] and " at t=" in warning[0], warning
    assert quiet.stderr == ""

    def untimed(text: str) -> str:  # the planning time is wall-clock time: it differs between the two runs
        return re.sub(r" in [0-9.]+ ms", " in - ms", text)

    assert untimed(quiet.stdout) == untimed(loud.stdout) and "acme.hasty: limit_violation in" in quiet.stdout


# ---- banners ---------------------------------------------------------------------------------------------
def test_a_command_that_imports_pybullet_prints_no_banner(tmp_path: Path):
    r = twin("scene", "robocup", "--snapshot", str(tmp_path / "s.png"))
    assert r.returncode == 0, r.stderr
    for noise in ("pybullet build time", "EGL device choice", "argv[0]"):
        assert noise not in r.stdout and noise not in r.stderr, (r.stdout, r.stderr)
    assert r.stderr == "" and r.stdout.strip() == f"wrote {tmp_path / 's.png'}"


def test_crocoddyl_says_nothing_when_a_problem_with_a_python_model_gets_one_thread(capfd):
    crocoddyl = pytest.importorskip("crocoddyl")
    pin = pytest.importorskip("pinocchio")
    pytest.importorskip("mim_solvers")
    from twin_croc.ocp import _one_thread

    state = crocoddyl.StateMultibody(pin.buildSampleModelManipulator())

    class Zero(crocoddyl.ResidualModelAbstract):  # a model written in Python, as twin_croc's PairDistances
        def __init__(self) -> None:
            crocoddyl.ResidualModelAbstract.__init__(self, state, 1, state.nv, True, False, False)

        def calc(self, data, x, u=None):
            data.r[:] = 0.0

    costs = crocoddyl.CostModelSum(state, state.nv)
    costs.addCost("zero", crocoddyl.CostModelResidual(state, Zero()), 1.0)
    dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, crocoddyl.ActuationModelFull(state), costs)
    model = crocoddyl.IntegratedActionModelEuler(dam, 0.1)
    problem = crocoddyl.ShootingProblem(np.zeros(state.nx), [model] * 3, model)
    capfd.readouterr()
    _one_thread(problem)
    _one_thread(problem)
    assert problem.nthreads == 1
    out, err = capfd.readouterr()
    assert "thread" not in out + err, (out, err)


# ---- the judge's refusals: once per planner, with the detail -------------------------------------------
class _TooFast:
    """A quintic from rest to rest in 0.5 s over 1 rad: 3.75 rad/s at its middle (t = 0.25 s), beyond 3.14."""

    jerk_limited = False

    def plan(self, request, scene):
        d = request.goal.q - request.start
        t = np.linspace(0.0, 0.5, 201)
        u = t / 0.5
        s = 10 * u**3 - 15 * u**4 + 6 * u**5
        sd = (30 * u**2 - 60 * u**3 + 30 * u**4) / 0.5
        sdd = (60 * u - 180 * u**2 + 120 * u**3) / 0.25
        return MotionResult(
            Status.SUCCESS, "", Trajectory(t, request.start + np.outer(s, d), np.outer(sd, d), np.outer(sdd, d))
        )


def test_a_repeated_limit_refusal_is_said_once_with_joint_excess_and_time(caplog):
    from twin.collision import PlanningScene
    from twin.planning import as_checked, make_context

    planner = as_checked(_TooFast(), make_context(ROBOCUP), name="too-fast-once")  # a name no other test uses
    scene = PlanningScene.from_settings(ROBOCUP)
    request = MotionRequest(HOME, JointGoal(HOME + np.array([1.0, 0, 0, 0, 0, 0])), LIMITS)
    with caplog.at_level(logging.DEBUG, logger="twin"):
        results = [planner.plan(request, scene) for _ in range(3)]
    assert all(r.status is Status.LIMIT_VIOLATION for r in results)
    mine = [r for r in caplog.records if r.getMessage().startswith("too-fast-once ")]
    warnings = [r.getMessage() for r in mine if r.levelno == logging.WARNING]
    assert len(warnings) == 1, warnings
    assert "beyond the joint limits" in warnings[0] and "velocity joint 1 reaches 3.75 rad/s" in warnings[0]
    assert "at t=0.250 s" in warnings[0] and "(1.19x)" in warnings[0], warnings[0]
    repeats = [r.getMessage() for r in mine if r.levelno == logging.DEBUG]
    assert len(repeats) == 2 and "(3 times so far)" in repeats[-1], repeats
    assert "at t=0.250 s" in results[0].reason  # the result says when too


# ---- elapsed time and the time left --------------------------------------------------------------------
def test_compare_progress_lines_carry_elapsed_time_and_the_estimate():
    clock, lines = FakeClock(), []
    on_row = compare_progress(clock=clock, write=lines.append)
    row = {"run_id": "ompl.rrt|robocup#0|seed=0|ab", "status": "success", "success": True}
    clock.now += 41.0
    on_row(row, 1, 26)  # 41 s for one run: 25 more take 17:05
    clock.now += 82.0
    on_row(dict(row, status="no_solution", success=False, reason="time limit"), 3, 26)  # 123 s for 3: 23 x 41
    clock.now += 10.0
    on_row(row, 26, 26)
    assert lines == [
        "[1/26 00:41 eta 17:05] ompl.rrt|robocup#0|seed=0|ab: success",
        "[3/26 02:03 eta 15:43] ompl.rrt|robocup#0|seed=0|ab: no_solution (time limit)",
        "[26/26 02:13 eta 00:00] ompl.rrt|robocup#0|seed=0|ab: success",
    ]
    assert progress_line(row, 3, 26) == "[3/26] ompl.rrt|robocup#0|seed=0|ab: success"  # no clock: as before


def test_the_estimate_counts_down_between_items_and_waits_for_the_first():
    clock = FakeClock()
    watch = ProgressClock(clock=clock)
    assert watch.stamp(0, 4) == "0/4 00:00 eta --:--"
    clock.now += 30.0
    assert watch.stamp(1, 4) == "1/4 00:30 eta 01:30"
    clock.now += 20.0  # still 1 done: the estimate counts down from when it was
    assert watch.stamp(1, 4) == "1/4 00:50 eta 01:10"
    clock.now += 3700.0
    assert watch.stamp(1, 4).endswith("eta 00:00") and clock_text(3725.0) == "1:02:05"


def test_run_display_shows_stage_objects_elapsed_and_time_left():
    clock = FakeClock()
    shown = RunDisplay("robocup seed 0", enabled=False, clock=clock)  # enabled=False: -q, nothing drawn
    assert shown.status() == "robocup seed 0: starting 00:00"
    clock.now += 10.0  # set-up, the first capture: not counted in the objects' rate
    shown.stage("scene: capture")
    shown.objects(0, 8)
    assert shown.status() == "robocup seed 0: scene: capture objects 0/8 00:10 eta --:--"
    clock.now += 20.0
    shown.objects(2, 8)  # 10 s an object: 6 more
    shown.stage("cube_red: descent")
    assert shown.status() == "robocup seed 0: cube_red: descent objects 2/8 00:30 eta 01:00"
    clock.now += 5.0
    assert shown.status().endswith("objects 2/8 00:35 eta 00:55")


def _run(run_id: str, planner: str, scenario: str, kind: str = "query") -> RunTask:
    return RunTask(run_id, planner, {"name": planner}, scenario, f"{scenario}#0", kind, 0, "c.yaml", time_limit_s=2.0)


def test_dry_run_estimate_from_a_recorded_sweep_else_a_rough_figure_said_to_be_rough():
    runs = [_run("a", "p", "s"), _run("b", "p", "s"), _run("c", "q", "s"), _run("d", "q", "t", kind="task")]
    rough = estimate_sweep(runs, workers=2)
    assert rough.measured == 0 and rough.rough == 4
    assert rough.run_s == pytest.approx(3 * (ROUGH_QUERY_OVERHEAD_S + 2.0) + ROUGH_TASK_RUN_S)
    assert rough.wall_s == pytest.approx(ROUGH_TASK_RUN_S)  # no faster than its longest run
    assert "rough figure" in rough.describe() and "no sweep recorded" in rough.describe()
    recorded = [
        {"run_id": "a", "planner": "p", "scenario": "s", "timing": {"wall_time_s": 4.0}},
        {"run_id": "x", "planner": "q", "scenario": "s", "timing": {"wall_time_s": 6.0}},
        {"run_id": "y", "planner": "q", "scenario": "s", "timing": {"wall_time_s": 8.0}},
    ]
    est = estimate_sweep(runs, workers=4, recorded=recorded, source=Path("out/x/results.jsonl"))
    # a: its own 4 s; b: p on s's mean, 4 s; c: q on s's mean, 7 s; d: nothing like it, rough
    assert (est.measured, est.rough) == (3, 1) and est.run_s == pytest.approx(15.0 + ROUGH_TASK_RUN_S)
    text = est.describe()
    assert "3 timed from the rows of out/x/results.jsonl" in text and "1 at a rough figure" in text, text
    assert text.startswith("estimated time: ~40 s with 4 workers (4 runs, 55 s of run time"), text


def test_bench_mbm_says_each_scene_as_it_ends_with_elapsed_and_eta():
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_mbm", Path(__file__).parent.parent / "bench" / "bench_mbm.py")
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    clock, lines = FakeClock(), []
    progress = bench.SceneProgress({"box": 2, "cage": 2}, clock=clock, write=lines.append)
    for done, (scene, ok) in enumerate([("box", True), ("box", False), ("cage", True), ("cage", True)], 1):
        clock.now += 10.0
        progress({"scenario": scene, "success": ok}, done, 4)
    assert lines == [
        "[1/4 00:10 eta 00:30] box: 1/2 runs",
        "[2/4 00:20 eta 00:20] box done: 1/2 solved",
        "[3/4 00:30 eta 00:10] cage: 1/2 runs",
        "[4/4 00:40 eta 00:00] cage done: 2/2 solved",
    ]


def test_quiet_check_planner_shows_no_spinner(monkeypatch: pytest.MonkeyPatch) -> None:
    """`twin check-planner NAME -q`: the verdict table on stdout, nothing on stderr, not even the spinner that
    rich draws where stderr is a terminal (FORCE_COLOR and TTY_COMPATIBLE make it draw one here too)."""
    monkeypatch.setenv("FORCE_COLOR", "1")
    monkeypatch.setenv("TTY_COMPATIBLE", "1")
    loud = twin("check-planner", "seed.quintic_movej")
    assert loud.returncode == 0 and loud.stderr, loud.stderr[-2000:]  # the spinner is drawn without -q
    r = twin("check-planner", "seed.quintic_movej", "-q")
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stderr == "" and "keeps every rule" in r.stdout
