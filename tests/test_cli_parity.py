"""One judge, one cell: `twin plan`, `twin compare` and problem sets plan in the same scene; `--planner`
takes its parameters from `--set` and checks them; `twin plan` reaches position goals; `twin run` says in
its exit code whether every object was placed."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_runner import twin

from twin import planning as twin_planning
from twin import tasks as twin_tasks
from twin.cli import main
from twin.collision import PlanningScene
from twin.config import find_config, load_config
from twin.types import ObjectOutcome, RunSummary

ROOT = Path(__file__).resolve().parent.parent
HOME = "0,-1.5708,1.5708,-1.5708,-1.5708,0"
NEAR_HOME = "0.2,-1.5708,1.5708,-1.5708,-1.5708,0"
# a warehouse query of compare-smoke's kind (`straight: blocked`): the straight joint motion sweeps the
# gripper through the obstacle wall, a fixture marked `known: false`
WALL_START = "-0.6794,-0.9834,1.2036,-1.7909,-1.5708,0.7297"
WALL_GOAL = "-0.3377,-1.5493,2.2881,-2.3096,-1.5708,1.0678"


def assert_one_line_usage_error(r: subprocess.CompletedProcess[str], *needles: str) -> None:
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    for n in needles:
        assert n in lines[0], lines[0]


def _cell(scene: PlanningScene) -> tuple[list[str], dict[str, tuple[list[float], list[float]]]]:
    """A scene's object names and its boxes (size, pose), comparable across scenes."""
    boxes = {n: (sz.round(9).tolist(), T.round(9).ravel().tolist()) for n, (sz, T) in scene.boxes().items()}
    return scene.names(), boxes


def _plan_scene(config: str, monkeypatch: pytest.MonkeyPatch) -> PlanningScene:
    """The scene `twin plan` plans in (caught on its way into `twin.planning.plan`)."""
    seen: list[PlanningScene] = []
    real = twin_planning.plan

    def spy(*args: Any, **kw: Any) -> Any:
        seen.append(kw["scene"])
        return real(*args, **kw)

    monkeypatch.setattr(twin_planning, "plan", spy)
    assert main(["plan", config, "--planner", "ruckig.movej", "--start", HOME, "--goal", NEAR_HOME]) == 0
    [scene] = seen
    return scene


@pytest.mark.parametrize("config", ["warehouse", "robocup"])
def test_plan_compare_and_problem_sets_plan_in_one_scene(config: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same objects and the same boxes in `twin plan`, `PlanningScene.from_settings`, `twin compare`'s
    cell, a `twin problems export` world and that world imported back; the obstacle marked `known: false` is
    in all of them as a box where it stands, and only a task's own cell leaves it to perception."""
    from twin.problems.cells import cell_for
    from twin.problems.export import export_problem_set
    from twin.problems.world import planning_scene, settings_for

    settings = load_config(config)
    want = _cell(PlanningScene.from_settings(settings))
    unknown = [f.name for f in settings.world.fixtures if not f.known]
    assert sorted(want[1]) == sorted(unknown)
    assert want[0] == [f.name for f in settings.world.fixtures if f.known] + unknown
    if config == "warehouse":
        assert unknown == ["obstacle"]
        size, pose = want[1]["obstacle"]
        assert size == pytest.approx([0.12, 0.30, 0.20]) and pose[3::4][:3] == pytest.approx([-0.42, 0.24, 0.10])

    assert _cell(_plan_scene(config, monkeypatch)) == want
    path = str(find_config(config).resolve())
    assert _cell(cell_for(path, (), "box").scene) == want
    ps = export_problem_set(config, count=1, seed=0, random={"goal": "joint"})
    exported = {o.name: [(p.size, p.pose.position) for p in o.primitives] for o in ps.world.objects}
    assert list(exported) == want[0] and ps.world.perceived_boxes == unknown
    for name, (size, pose) in want[1].items():
        [(sz, xyz)] = exported[name]
        assert list(sz) == pytest.approx(size) and list(xyz) == pytest.approx(pose[3::4][:3])
    assert _cell(planning_scene(ps, settings_for(ps, settings))) == want

    known_only = PlanningScene.from_settings(settings, unknown_fixtures="ignore")
    assert known_only.names() == [f.name for f in settings.world.fixtures if f.known] and not known_only.boxes()


def test_a_task_cell_does_not_know_the_obstacle_it_perceives() -> None:
    from twin.tasks.cell import Cell
    from twin.world import World

    # the fixtures are what matters here (and a transfer planner quicker to build than nmpc)
    settings = load_config("warehouse", ["world.objects.items=[]", "planners.transfer.name=ruckig.movej"])
    with World(settings, seed=0, renderer="tiny") as world:
        cell = Cell(settings, world)
        assert "obstacle" not in cell.scene.names() and not cell.scene.boxes()


def test_plan_refuses_a_motion_through_the_wall_and_names_the_pair() -> None:
    r = twin("plan", "warehouse", "--planner", "ruckig.movej", "--start", WALL_START, "--goal", WALL_GOAL, "-v")
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert "scene: table, aruco_plate, obstacle (known: false, as a box)" in r.stdout
    assert "collision" in r.stdout and " with obstacle" in r.stdout, r.stdout


# ---- --planner and --set planners.transfer.* ---------------------------------------------------------


def _transfer_params(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """A `twin run` that builds its stage planners (where parameters are checked) and stops; the transfer
    planner's validated params are appended to the returned list."""
    from twin.config import with_planner
    from twin.planning import make_context
    from twin.tasks.cell import stage_planners

    seen: list[Any] = []

    def fake_run_task(settings: Any, **kw: Any) -> RunSummary:
        if kw.get("planner"):
            settings = with_planner(settings, "transfer", kw["planner"])
        planners = stage_planners(settings, make_context(settings))
        seen.append(planners["transfer"].inner.params)
        return _summary(settings.planners.transfer.name, placed=(True,))

    monkeypatch.setattr(twin_tasks, "run_task", fake_run_task)
    return seen


def test_planner_takes_its_params_from_set_and_drops_the_old_planners(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    cfg = tmp_path / "timed.yaml"  # a transfer block with a parameter only ruckig.movej has
    block = "{name: ruckig.movej, params: {synchronization: time}}"
    cfg.write_text(f"extends: {ROOT / 'configs/robocup.yaml'}\nplanners:\n  transfer: {block}\n")
    seen = _transfer_params(monkeypatch)
    over = ["--set", "planners.transfer.params.min_duration_s=2.5"]
    assert main(["run", str(cfg), "--planner", "seed.quintic_movej", *over]) == 0
    assert main(["run", str(cfg), "--planner", "seed.quintic_movej"]) == 0
    assert seen[0].min_duration_s == 2.5 and seen[1].min_duration_s == 0.0
    assert main(["run", str(cfg)]) == 0  # without --planner the config's block, its params included
    assert seen[2].synchronization == "time"


@pytest.mark.parametrize(
    ("override", "needle"),
    [
        ("planners.transfer.params.min_duraton_s=2", "unknown parameter 'min_duraton_s'"),
        ("planners.transfer.params.min_duration_s=abc", "parameter 'min_duration_s'"),
        ("planners.transfer.name=nmpc", "both choose the transfer planner"),
    ],
    ids=["typo", "bad-value", "two-names"],
)
def test_planner_overrides_are_checked_like_any_other(override: str, needle: str) -> None:
    r = twin("run", "robocup", "--planner", "seed.quintic_movej", "--set", override)
    assert_one_line_usage_error(r, needle)


# ---- twin plan --goal-position -------------------------------------------------------------------------


def test_plan_reaches_a_position_goal_with_nmpc(tmp_path: Path) -> None:
    out = tmp_path / "plan.json"
    target = np.array([-0.45, -0.25, 0.30])
    r = twin(
        "plan", "warehouse", "--planner", "nmpc", "--start", HOME,
        "--goal-position", ",".join(map(str, target)), "--json", str(out),
    )  # fmt: skip
    assert r.returncode == 0, (r.stdout, r.stderr)
    data = json.loads(out.read_text())
    from twin.robot.kinematics import URArm

    tcp = URArm().fk(np.array(data["q"][-1]))[:3, 3]
    assert data["status"] == "success" and np.linalg.norm(tcp - target) <= 0.03  # the task's transfer tolerance


@pytest.mark.parametrize("goal", [["--goal", NEAR_HOME], ["--goal-pose", "-0.45,-0.25,0.3,3.14159,0,0"]])
def test_a_position_tolerance_without_a_position_goal_is_a_usage_error(goal: list[str]) -> None:
    r = twin("plan", "warehouse", "--planner", "ruckig.movej", "--start", HOME, *goal, "--position-tolerance", "0.01")
    assert_one_line_usage_error(r, "--position-tolerance goes with --goal-position")


def test_goal_options_exclude_each_other() -> None:
    r = twin("plan", "warehouse", "--planner", "nmpc", "--start", HOME, "--goal", HOME, "--goal-position", "0,0,0.3")
    assert_one_line_usage_error(r, "not allowed with argument")


# ---- twin run's exit code ------------------------------------------------------------------------------


def _summary(planner: str, *, placed: tuple[bool, ...]) -> RunSummary:
    objects = tuple(
        ObjectOutcome(
            f"cube_{i}", "warehouse_cube", "red", "drop", p, None if p else "grasp: nothing between the fingers"
        )
        for i, p in enumerate(placed)
    )
    return RunSummary("warehouse", 0, planner, objects, sim_time_s=10.0, wall_time_s=1.0, timings={"physics": 1.0})


@pytest.mark.parametrize(("placed", "code"), [((True, True), 0), ((True, False), 1)], ids=["all-placed", "one-not"])
def test_run_exits_1_when_an_object_was_not_placed(
    placed: tuple[bool, ...], code: int, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(twin_tasks, "run_task", lambda settings, **kw: _summary("nmpc", placed=placed))
    assert main(["run", "warehouse"]) == code
    assert f"placed {sum(placed)}/{len(placed)}" in capsys.readouterr().out
