"""The `twin` CLI: user mistakes are one line and exit 2; plugins show up; `twin plan` writes JSON."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
START = "0,-1.6,1.5,-1.5,-1.57,0"
GOAL = "0.3,-1.4,1.2,-1.4,-1.57,0.2"


def twin(*args: str, extra_path: Path | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    if extra_path is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(extra_path), env.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-m", "twin", *args], capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)


def assert_one_line_usage_error(r: subprocess.CompletedProcess, *needles: str) -> None:
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    for n in needles:
        assert n in lines[0], lines[0]


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
    r = twin("plan", "configs/robocup.yaml", "--planner", "acme.straight", "--start", START, "--goal", GOAL, "--json", str(out), extra_path=acme_plugin)
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
    r = twin("plan", "configs/robocup.yaml", "--set", "robot.max_joint_vel=fast", "--planner", "ruckig.movej", "--start", START, "--goal", GOAL)
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
    r = twin("plan", "configs/robocup.yaml", "--planner", "ruckig.movej", "--start", START, "--goal", "0,0.6,0,0,0,0", "--json", str(out))
    assert r.returncode == 1, (r.stdout, r.stderr)
    data = json.loads(out.read_text())
    assert data["status"] != "success" and data["reason"] and data["q"] == []
