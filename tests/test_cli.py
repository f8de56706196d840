"""The `twin` CLI: user mistakes are one line and exit 2; plugins show up; `twin plan` writes JSON."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from cli_runner import twin

ROOT = Path(__file__).resolve().parent.parent
START = "0,-1.6,1.5,-1.5,-1.57,0"
GOAL = "0.3,-1.4,1.2,-1.4,-1.57,0.2"


def assert_one_line_usage_error(r: subprocess.CompletedProcess, *needles: str) -> None:
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    for n in needles:
        assert n in lines[0], lines[0]


def assert_plan_ran(r: subprocess.CompletedProcess, out: Path) -> dict:
    """A real plan: exit 0 (success) or 1 (no solution), its JSON written; never a usage error."""
    assert r.returncode in (0, 1), (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    return json.loads(out.read_text())


def test_help_lists_commands():
    r = twin("--help")
    assert r.returncode == 0
    for cmd in ("planners", "scene", "plan"):
        assert cmd in r.stdout


def test_planners_lists_builtins_and_a_third_party_plugin(acme_plugin):
    r = twin("planners", extra_path=acme_plugin)
    assert r.returncode == 0, r.stderr
    assert "acme.straight" in r.stdout and "acme-twin-plugin" in r.stdout
    assert "ruckig.movej" in r.stdout and "one-shot planner" in r.stdout and "retimer" in r.stdout


def test_plan_with_a_third_party_plugin_from_the_command_line(acme_plugin, tmp_path):
    out = tmp_path / "plan.json"
    r = twin(
        "plan",
        "configs/robocup.yaml",
        "--planner",
        "acme.straight",
        "--start",
        START,
        "--goal",
        GOAL,
        "--json",
        str(out),
        extra_path=acme_plugin,
    )
    assert r.returncode == 0, r.stderr
    data = json.loads(out.read_text())
    assert data["status"] == "success" and len(data["q"]) == len(data["t"]) > 1
    assert data["q"][-1] == pytest.approx([float(v) for v in GOAL.split(",")])


def test_unknown_planner_name_lists_the_names():
    r = twin("plan", "configs/robocup.yaml", "--planner", "ruckig.movjj", "--start", START, "--goal", GOAL)
    assert_one_line_usage_error(r, "'ruckig.movjj' is not registered", "Did you mean 'ruckig.movej'", "toppra.movel")


def test_unknown_config_key_names_the_dotted_path(tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("extends: %s\nworld:\n  fixtures_typo: []\n" % (ROOT / "configs/robocup.yaml"))
    r = twin("plan", str(cfg), "--planner", "ruckig.movej", "--start", START, "--goal", GOAL)
    assert_one_line_usage_error(r, "unknown key 'world.fixtures_typo'")


def test_bad_value_type_in_an_override():
    r = twin(
        "plan",
        "configs/robocup.yaml",
        "--set",
        "robot.max_joint_vel=fast",
        "--planner",
        "ruckig.movej",
        "--start",
        START,
        "--goal",
        GOAL,
    )
    assert_one_line_usage_error(r, "robot.max_joint_vel")


def test_missing_config_file():
    r = twin("plan", "configs/nope.yaml", "--planner", "ruckig.movej", "--start", START, "--goal", GOAL)
    assert_one_line_usage_error(r, "config file not found")


def test_malformed_joint_vector():
    r = twin("plan", "configs/robocup.yaml", "--planner", "ruckig.movej", "--start", "1,2,x", "--goal", GOAL)
    assert_one_line_usage_error(r, "--start")


def test_no_solution_exits_1(tmp_path):
    # the goal puts the arm straight down through the table
    out = tmp_path / "p.json"
    r = twin(
        "plan",
        "configs/robocup.yaml",
        "--planner",
        "ruckig.movej",
        "--start",
        START,
        "--goal",
        "0,0.6,0,0,0,0",
        "--json",
        str(out),
    )
    assert r.returncode == 1, (r.stdout, r.stderr)
    data = json.loads(out.read_text())
    assert data["status"] != "success" and data["reason"] and data["q"] == []


# ---- vectors as users type them: a leading minus sign ------------------------------------------------
NEG_START = "-0.5,-1.5708,1.5708,-1.5708,-1.5708,0"
NEG_GOAL = "-0.3,-1.4,1.2,-1.4,-1.57,0.2"


def test_start_and_goal_may_begin_with_a_minus_sign(tmp_path):
    out = tmp_path / "p.json"
    r = twin(
        "plan",
        "configs/robocup.yaml",
        "--planner",
        "ruckig.movej",
        "--start",
        NEG_START,
        "--goal",
        NEG_GOAL,
        "--json",
        str(out),
    )
    data = assert_plan_ran(r, out)
    assert data["status"] == "success", data["reason"]
    assert data["q"][0] == pytest.approx([float(v) for v in NEG_START.split(",")])
    assert data["q"][-1] == pytest.approx([float(v) for v in NEG_GOAL.split(",")])


def test_goal_pose_may_begin_with_a_minus_sign(tmp_path):
    out = tmp_path / "p.json"
    r = twin(
        "plan",
        "configs/robocup.yaml",
        "--planner",
        "ruckig.movej",
        "--start",
        NEG_START,
        "--goal-pose",
        "-0.45,-0.2,0.3,-3.14159,0,-0.5",
        "--json",
        str(out),
    )
    data = assert_plan_ran(r, out)
    assert data["planner"] == "ruckig.movej" and data["reason"] is not None


def test_equals_form_and_abbreviations_still_work(tmp_path):
    out = tmp_path / "p.json"
    r = twin(
        "plan",
        "configs/robocup.yaml",
        "--planner",
        "ruckig.movej",
        f"--start={NEG_START}",
        "--goal-posi",  # --goal-position (--goal-p is ambiguous: --goal-pose too)
        "-0.45,0.2,0.3",
        "--json",
        str(out),
    )
    assert_plan_ran(r, out)


def test_a_bad_vector_with_a_minus_sign_is_one_line_naming_the_option():
    r = twin(
        "plan",
        "configs/robocup.yaml",
        "--planner",
        "ruckig.movej",
        "--start",
        "-0.5,-1.5708,1.5708",
        "--goal",
        NEG_GOAL,
    )
    assert_one_line_usage_error(r, "--start", "6 comma-separated")
    r = twin(
        "plan",
        "configs/robocup.yaml",
        "--planner",
        "ruckig.movej",
        "--start",
        NEG_START,
        "--goal",
        "-0.3,-1.4,1.2,-1.4,-1.57,-inf",
    )
    assert_one_line_usage_error(r, "--goal", "finite")


def test_vector_values_are_joined_only_for_vector_options():
    from twin.cli import build_parser

    args = build_parser().parse_args(
        ["plan", "c.yaml", "--planner", "x", "--start", NEG_START, "--goal-pose", "-1,-2,-3,-4,-5,-6"]
    )
    assert args.start == [float(v) for v in NEG_START.split(",")] and args.goal_pose == [
        -1.0,
        -2.0,
        -3.0,
        -4.0,
        -5.0,
        -6.0,
    ]
    # a comparison's --set value that looks like numbers is left alone (it is not a vector option)
    args = build_parser().parse_args(["compare", "c.yaml", "--set", "seeds=[0]"])
    assert args.overrides == ["seeds=[0]"]


# ---- configs that are not UTF-8, not YAML, empty or binary: one line, exit 2 ----------------------------
@pytest.mark.parametrize(
    ("content", "needle"),
    [
        (b"seed: 3\nname: caf\xe9\n", "not UTF-8"),
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x01", "binary"),
        (b"", "the config is empty"),
        (b"# only a comment\n", "the config is empty"),
        (b"world:\n  fixtures: [\n    {name: table\n", "not valid YAML at line"),
        (b"robot:\n  urdf: a\n bad_indent: 1\n", "not valid YAML at line"),
        (b"seed: 1\x07\n", "not valid YAML at line 1"),
        (b"- just\n- a list\n", "mapping"),
    ],
    ids=["latin1", "binary", "empty", "comment-only", "unclosed", "indent", "control-char", "list"],
)
def test_unreadable_configs_are_one_line_errors(tmp_path, content, needle):
    cfg = tmp_path / "bad.yaml"
    cfg.write_bytes(content)
    r = twin("plan", str(cfg), "--planner", "ruckig.movej", "--start", START, "--goal", GOAL)
    assert_one_line_usage_error(r, needle, "bad.yaml")


@pytest.mark.parametrize(
    ("override", "needle"),
    [
        ("robot.max_joint_vel=.nan", "finite"),
        ("robot.max_joint_vel=.inf", "finite"),
        ("seed=1" + "0" * 40, "too large"),
        ("world.fixtures={a: 1}", "world.fixtures"),
        ("robot.home=" + "[" * 60 + "]" * 60, "robot.home"),
        ("planners.newgroup.params.x=1", "unknown key 'planners.newgroup'"),
        ('camera.mount="fix\\ned"', "camera.mount"),
    ],
    ids=["nan", "inf", "huge", "mapping-for-list", "deep", "no-name", "newline-value"],
)
def test_odd_overrides_are_one_line_errors(override, needle):
    r = twin(
        "plan", "configs/robocup.yaml", "--set", override, "--planner", "ruckig.movej", "--start", START, "--goal", GOAL
    )
    assert_one_line_usage_error(r, needle)


# ---- twin planners: what can be created here ------------------------------------------------------------
def test_planners_lists_availability_with_the_reason(tmp_path):
    out = tmp_path / "planners.json"
    r = twin("planners", "--json", str(out))
    assert r.returncode == 0, r.stderr
    assert "available" in r.stdout
    rows = {row["name"]: row for row in json.loads(out.read_text())}
    assert rows["ruckig.movej"]["available"] is True and rows["ruckig.movej"]["unavailable_reason"] is None
    for row in rows.values():
        assert isinstance(row["available"], bool)
        assert row["available"] or (row["unavailable_reason"] and "\n" not in row["unavailable_reason"])
    try:
        import ompl.geometric as og
    except ImportError:
        return
    if not hasattr(og, "LazyPRMstar"):
        row = rows["ompl.lazyprmstar"]
        assert row["available"] is False and "LazyPRMstar" in row["unavailable_reason"]
        assert "no: planner 'ompl.lazyprmstar'" in r.stdout.replace("\n", " ") or "no:" in r.stdout
