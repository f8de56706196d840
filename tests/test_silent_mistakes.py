"""No silent mistakes (issue 38): every mistake a user reported running silently is refused in one line
(exit 2), a plugin that raises is named with its exception (exit 3, the run goes on), and a run's result
says what ran."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from tests.cli_runner import twin
from twin.config import load_config
from twin.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent


def _one_line_error(r, *, code: int = 2) -> str:
    assert r.returncode == code, (r.returncode, r.stdout[-2000:], r.stderr[-2000:])
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("twin ")]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    return lines[0]


# ---- planner groups are schema fields ---------------------------------------------------------------
def test_a_misspelt_planner_group_is_refused_with_the_group_meant() -> None:
    with pytest.raises(ConfigError) as e:
        load_config("robocup", ["planners.transfr.name=ompl.rrtconnect"])
    msg = str(e.value)
    assert "unknown key 'planners.transfr'" in msg
    assert "Did you mean 'transfer'?" in msg and "movej, movel, transfer" in msg
    assert msg.startswith("override 'planners.transfr.name=ompl.rrtconnect' (on ")  # the --set, not the file


def test_the_command_line_refuses_a_misspelt_group_before_anything_runs() -> None:
    r = twin("run", "configs/robocup.yaml", "--set", "planners.transfr.name=ompl.rrtconnect")
    line = _one_line_error(r)
    assert "Did you mean 'transfer'?" in line, line


def test_planner_groups_dump_as_the_mapping_of_the_groups_given() -> None:
    """Run ids hash the loaded config's dump: the groups a config leaves out are not in it."""
    s = load_config("robocup", ["planners.transfer.name=ompl.rrtconnect"])
    assert s.planners.transfer is not None and s.planners.transfer.name == "ompl.rrtconnect"
    dumped = s.model_dump(mode="json")["planners"]
    assert set(dumped) == {g for g in ("movej", "movel", "transfer") if s.planners.get(g) is not None}
    with pytest.raises(KeyError, match="the groups are movej, movel, transfer"):
        s.planners.get("transfr")


# ---- unknown keys, and which override is wrong ------------------------------------------------------
@pytest.mark.parametrize(
    ("override", "meant", "allowed"),
    [
        ("camera.nosie.scale=2", "noise", "extrinsic_error"),
        ("robot.modle=ur5", "model", "max_joint_vel"),
        ("sed=3", "seed", "perception"),
    ],
)
def test_an_unknown_key_gets_the_key_meant_and_the_keys_allowed(override: str, meant: str, allowed: str) -> None:
    with pytest.raises(ConfigError) as e:
        load_config("robocup", [override])
    assert f"Did you mean {meant!r}?" in str(e.value) and allowed in str(e.value)


def test_an_unknown_key_in_a_file_names_the_file(tmp_path: Path) -> None:
    cfg = tmp_path / "mine.yaml"
    cfg.write_text("extends: robocup\ngriper: {force_n: 50}\n")
    with pytest.raises(ConfigError) as e:
        load_config(cfg)
    assert str(e.value).startswith(f"{cfg}: unknown key 'griper'. Did you mean 'gripper'?")


def test_a_bad_value_given_by_set_names_the_override_not_the_shipped_file() -> None:
    with pytest.raises(ConfigError) as e:
        load_config("robocup", ["seed=1", "camera.noise.scale=abc"])
    assert str(e.value).startswith("override 'camera.noise.scale=abc' (on "), str(e.value)
    with pytest.raises(ConfigError) as e:
        load_config("robocup", ["robot.urdf=nowhere.urdf"])
    assert str(e.value).startswith("override 'robot.urdf=nowhere.urdf'"), str(e.value)


def test_a_bad_value_in_the_file_still_names_the_file(tmp_path: Path) -> None:
    cfg = tmp_path / "mine.yaml"
    cfg.write_text("extends: robocup\ncamera: {noise: {scale: abc}}\n")
    with pytest.raises(ConfigError) as e:
        load_config(cfg, ["seed=1"])  # an override elsewhere is not blamed
    assert str(e.value).startswith(f"{cfg}: camera.noise.scale"), str(e.value)


def test_an_unknown_key_of_a_comparison_gets_the_key_meant() -> None:
    from twin.compare.spec import compare_spec_from_dict

    spec = {"name": "x", "planners": ["ruckig.movej"], "scenarios": [{"name": "a", "task": "robocup", "overides": []}]}
    with pytest.raises(ConfigError, match=r"unknown key 'scenarios\.0\.overides'\. Did you mean 'overrides'\?"):
        compare_spec_from_dict(spec, source="c.yaml", base_dir=ROOT / "configs")


# ---- a planner that refuses an arm: skipped, never a failure ----------------------------------------
def _arm_comparison(tmp_path: Path) -> Path:
    spec = {
        "name": "arms",
        "planners": ["ruckig.movej", "nmpc"],
        "seeds": [0, 1],
        "scenarios": [
            {"name": "ur5e", "task": str(ROOT / "configs" / "warehouse.yaml")},
            {"name": "ur10e", "task": str(ROOT / "configs" / "warehouse.yaml"), "overrides": ["robot.model=ur10e"]},
        ],
    }
    path = tmp_path / "arms.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def test_a_pair_on_an_arm_the_planner_does_not_plan_for_is_skipped_in_the_dry_run(tmp_path: Path) -> None:
    pytest.importorskip("casadi")
    from twin.compare import plan_comparison

    dry = plan_comparison(_arm_comparison(tmp_path))
    assert dry.total == 6  # 8 runs less nmpc's two on the UR10e
    reasons = {r for _, r in dry.skipped}
    assert reasons == {"nmpc does not plan for robot.model ur10e; it plans for ur5e"}
    assert len(dry.skipped) == 2
    r = twin("compare", str(_arm_comparison(tmp_path)), "--dry-run")
    assert r.returncode == 0, r.stderr
    assert "arms.yaml: 6 runs (2 planners, 4 cases, 2 pairs skipped)" in r.stdout, r.stdout
    assert "would skip 2 runs: nmpc does not plan for robot.model ur10e" in r.stdout, r.stdout


def test_the_factory_refuses_a_planner_on_an_arm_it_does_not_plan_for() -> None:
    pytest.importorskip("casadi")
    from twin.planning import make_context, make_planner

    ctx = make_context(load_config("warehouse", ["robot.model=ur5"]))
    with pytest.raises(ConfigError, match=r"^nmpc does not plan for robot\.model ur5; it plans for ur5e$"):
        make_planner("nmpc", ctx)
    assert make_planner("ruckig.movej", ctx).name == "ruckig.movej"


# ---- command-line options that did nothing ----------------------------------------------------------
def test_speed_without_record_is_refused() -> None:
    line = _one_line_error(twin("run", "configs/robocup.yaml", "--speed", "4"))
    assert "--speed 4 goes with --record" in line


def test_the_dry_run_checks_the_workers_as_the_run_does() -> None:
    line = _one_line_error(twin("compare", "configs/compare-smoke.yaml", "--dry-run", "--workers", "-2"))
    assert "workers must be >= 0" in line


# ---- a plugin that raises ---------------------------------------------------------------------------
def test_twin_plan_names_a_plugin_that_raises_with_an_exit_code_of_its_own(acme_plugin: Path) -> None:
    args = ("plan", "robocup", "--planner", "acme.flaky", "--start", "0,-1.5708,1.5708,-1.5708,-1.5708,0")
    args += ("--goal", "0.3,-1.4,1.4,-1.5708,-1.5708,0")
    r = twin(*args, extra_path=acme_plugin)
    line = _one_line_error(r, code=3)
    assert line == "twin plan: plugin error: acme.flaky raised ZeroDivisionError in plan(): division by zero", line
    r = twin(*args, "-v", extra_path=acme_plugin)
    assert r.returncode == 3
    assert "Traceback (most recent call last)" in r.stderr and "return 1 / 0" in r.stderr, r.stderr


def test_twin_run_fails_the_object_whose_planner_raised_and_goes_on(acme_plugin: Path, tmp_path: Path) -> None:
    """The flaky transfer planner raises on its first plan() (the first object's transfer) and plans the
    rest: that stage fails with the plugin's exception, the run goes on (the task's retry, the next object),
    and the command's exit code says a plugin failed (3), even though the task recovered."""
    out = tmp_path / "run.json"
    r = twin(
        "run",
        "configs/robocup.yaml",
        "--planner",
        "acme.flaky",
        "--set",
        "world.objects.items=[{class: can}, {class: cube, color: red}]",
        "--json",
        str(out),
        extra_path=acme_plugin,
    )
    assert r.returncode == 3, (r.stdout[-3000:], r.stderr[-3000:])
    data = json.loads(out.read_text())
    assert data["plugin_errors"] == ["transfer: acme.flaky raised ZeroDivisionError in plan(): division by zero"]
    assert "acme.flaky raised ZeroDivisionError in plan()" in r.stderr  # said once, as it happened
    assert "Traceback" not in r.stderr
    assert len(data["objects"]) == 2 and any(o["placed"] for o in data["objects"]), data["objects"]
    assert "plugin errors: 1, the first: transfer: acme.flaky raised ZeroDivisionError" in r.stdout


# ---- every result names what ran ----------------------------------------------------------------------
def test_the_run_header_and_json_name_the_planner_parameters_and_overrides(acme_plugin: Path) -> None:
    """Two runs of one planner with other parameters are told apart: the JSON holds every group's block
    with the parameters the plugin ran with (defaults included) and the overrides; the header shows them."""
    from twin.tasks import run_task

    settings = load_config(
        "robocup",
        ["planners.transfer.name=acme.hasty", "planners.transfer.params.factor=1.0", "task.kind=acme.wave"],
    )
    summary = run_task(settings)
    ran = summary.to_json()["planners"]
    assert set(ran) == {"movej", "movel", "transfer"}
    assert ran["transfer"]["name"] == "acme.hasty"
    assert ran["transfer"]["params"] == {"limits": ["velocity", "acceleration", "jerk"], "factor": 1.0}
    assert ran["movej"]["name"] == settings.planners.movej.name  # type: ignore[union-attr]

    r = twin(
        "run",
        "robocup",
        "--set",
        "task.kind=acme.wave",
        "--planner",
        "acme.hasty",
        "--set",
        "planners.transfer.params.factor=1.0",
        "--json",
        str(acme_plugin / "run.json"),
        extra_path=acme_plugin,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    data = json.loads((acme_plugin / "run.json").read_text())
    assert data["overrides"] == [
        "--planner acme.hasty",
        "--set task.kind=acme.wave",
        "--set planners.transfer.params.factor=1.0",
    ]
    assert data["planners"]["transfer"]["params"]["factor"] == 1.0
    header = " ".join(r.stdout.split())
    assert "transfer acme.hasty (factor=1.0)" in header and "--set planners.transfer.params.factor=1.0" in header
