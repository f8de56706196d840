"""The command line of issue 16 as a user runs it: problem sets in and out, the Planner Arena export, and the
regression gate (`twin compare --baseline`), which exits 1 on a regression and 0 on an identical rerun."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from tests.cli_runner import twin

# one fast deterministic planner on seeded problems: the rerun's rows equal the first sweep's; 23 runs per
# planner, so the gate judges p95s (it needs 20: twin.compare.gate.MIN_P95_RUNS)
SWEEP = """
name: gate
seeds: [0]
execute: false
planners: [ruckig.movej, seed.quintic_movej]
scenarios:
  - {name: free, scene: warehouse, random: {count: 20, straight: free}}
  - {name: from-file, problems: PROBLEMS}
"""


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cli16")
    problems = d / "problems.json"
    r = twin("problems", "export", "robocup", "--count", "3", "--seed", "2", "--goal", "pose", "--out", str(problems))
    assert r.returncode == 0, r.stderr
    assert "3 problems, 4 objects" in r.stdout
    cfg = d / "gate.yaml"
    cfg.write_text(SWEEP.replace("PROBLEMS", str(problems)))
    first = d / "first"
    r = twin("compare", str(cfg), "--out", str(first), "--workers", "0", "--export-ompl", str(d / "arena"))
    assert r.returncode == 0, r.stderr
    return {"dir": d, "config": cfg, "first": first, "problems": problems, "arena": d / "arena"}


def test_an_identical_rerun_passes_the_gate(sweep: dict[str, Path]) -> None:
    r = twin(
        "compare",
        str(sweep["config"]),
        "--out",
        str(sweep["dir"] / "again"),
        "--workers",
        "0",
        "--baseline",
        str(sweep["first"] / "results.jsonl"),
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "regression gate: passed" in r.stdout and "46 in both sweeps" in r.stdout  # 2 planners x 23 problems


def test_a_doctored_baseline_fails_the_gate_with_a_table(sweep: dict[str, Path]) -> None:
    rows = [json.loads(line) for line in (sweep["first"] / "results.jsonl").read_text().splitlines()]
    for row in rows:  # the baseline claims shorter trajectories for ruckig.movej than it produces
        if row["planner"] == "ruckig.movej" and row["metrics"]["duration_s"] is not None:
            row["metrics"]["duration_s"] *= 0.5
    doctored = sweep["dir"] / "doctored.jsonl"
    doctored.write_text("".join(json.dumps(r) + "\n" for r in rows))
    r = twin(
        "compare",
        str(sweep["config"]),
        "--out",
        str(sweep["dir"] / "third"),
        "--workers",
        "0",
        "--baseline",
        str(doctored),
        "--tolerance",
        "duration=0.1",
    )
    assert r.returncode == 1, r.stdout + r.stderr
    assert "regression gate: FAILED" in r.stdout
    assert "ruckig.movej: p95 duration" in r.stdout and "seed.quintic_movej: p95 duration" not in r.stdout


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--baseline", "missing.jsonl"], "missing.jsonl"),
        (["--baseline", "BASE", "--tolerance", "speed=2"], "unknown key 'speed'; allowed keys: success"),
        (["--tolerance", "duration=0.1"], "--tolerance goes with --baseline"),
    ],
)
def test_bad_gate_arguments_are_one_line_before_any_run(sweep: dict[str, Path], args: list[str], needle: str) -> None:
    args = [str(sweep["first"] / "results.jsonl") if a == "BASE" else a for a in args]
    out = sweep["dir"] / "never"
    r = twin("compare", str(sweep["config"]), "--out", str(out), "--workers", "0", *args)
    assert r.returncode == 2 and needle in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (out / "results.jsonl").exists()


def test_the_planner_arena_export_has_one_experiment_per_scenario(sweep: dict[str, Path]) -> None:
    logs = sorted(p.name for p in sweep["arena"].glob("*.log"))
    assert logs == ["gate.free.log", "gate.from-file.log"]
    with sqlite3.connect(sweep["arena"] / "gate.db") as db:
        names = [n for (n,) in db.execute("SELECT name FROM experiments ORDER BY id")]
        runs = db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
        cols = {c[1] for c in db.execute("PRAGMA table_info(runs)")}
    assert names == ["gate.free", "gate.from-file"] and runs == 46
    assert {"time", "solved", "status", "solution_length", "solution_clearance", "solution_smoothness"} <= cols
    # `twin export` writes the same from the results file
    r = twin("export", str(sweep["first"]), "--out", str(sweep["dir"] / "arena2"), "--name", "gate")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (sweep["dir"] / "arena2").glob("*.log")) == logs


def test_problem_commands_report_bad_input_in_one_line(tmp_path: Path) -> None:
    for args, needle in [
        (["problems", "export", "robocup", "--count", "0", "--out", "x.json"], "positive integer"),
        (["problems", "export", "robocup", "--count", "2", "--set", "region_q=1", "--out", "x.json"], "region_q"),
        (["problems", "export", "nope", "--count", "2", "--out", "x.json"], "nope"),
        (["export", str(tmp_path), "--out", str(tmp_path / "a")], "no results file"),
    ]:
        r = twin(*args)
        assert r.returncode == 2 and needle in r.stderr and len(r.stderr.strip().splitlines()) == 1, (args, r.stderr)
    r = twin("problems", "schema")
    assert r.returncode == 0 and json.loads(r.stdout)["title"].startswith("twin problem set")
