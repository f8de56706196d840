"""OMPL benchmark logs and the Planner Arena database from `twin compare` rows (twin.compare.ompl_export).

What a user relies on: OMPL's own `ompl_benchmark_statistics` reads the logs (one experiment per
scenario, every planner, every run with its time, success, OMPL status and metrics), and the database
twin writes without OMPL is the one that script makes from those logs, table for table and value for
value. Synthetic rows: no PyBullet, no planning.
"""

from __future__ import annotations

import socket
import sqlite3
import subprocess
import sys
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest

from twin.compare.metrics import empty_metrics, empty_timing
from twin.compare.ompl_export import export_planner_arena, write_ompl_logs, write_planner_arena_db
from twin.errors import ConfigError

NAME = "smoke"
PLANNERS = ["rrt", "straight", "slow one"]  # a label with a space is written as 'slow_one'
CASES = {"alpha": ["alpha#0", "alpha#1"], "beta": ["beta#0"]}
SEEDS = [0, 1]
TIME_LIMITS = {"alpha": 1.0, "beta": 2.5}
# where the rows ran (a twin.environment record, as compare.json keeps it)
ENVIRONMENT: dict[str, Any] = {
    "twin": {"version": "0.1.0", "commit": "f" * 40, "dirty": False},
    "python": {"version": "3.11.7", "implementation": "CPython"},
    "packages": {"numpy": "2.4.6", "ompl": "1.7.0", "casadi": None},
    "platform": {"description": "Linux-6.1-x86_64-with-glibc2.36"},
    "cpu": {"model": "Test CPU 3000", "cores": 8, "usable_cores": 4, "flags": ["avx2", "fma"], "blas": "openblas 0.3"},
    "hostname": "recorded-host",
}
CPUINFO = (
    "CPU: Test CPU 3000\ncores: 8 (4 usable)\nSIMD flags: avx2 fma\nBLAS: openblas 0.3\n"
    "OS: Linux-6.1-x86_64-with-glibc2.36\n"
)
OPTIONS: dict[str, Any] = {
    "name": NAME,
    "planners": PLANNERS,
    "host": "bench-host",
    "started": datetime(2024, 5, 6, 7, 8, 9),
    "time_limit_s": TIME_LIMITS,
    "environment": ENVIRONMENT,
}

# (planner, case, seed) -> (status, failure, reason) of the runs that fail; every other run succeeds
FAILED = {
    ("straight", "alpha#0", 0): ("collision", "no_solution", "the trajectory collides"),
    ("straight", "alpha#0", 1): ("invalid_start", "start_in_collision", "start in collision"),
    ("slow one", "alpha#1", 0): ("timeout", "timeout", "time limit"),
    ("slow one", "beta#0", 1): ("error", "error", "RuntimeError: boom"),
    ("rrt", "beta#0", 0): ("invalid_goal", "ik_failure", "no IK solution"),
    ("straight", "beta#0", 0): ("invalid_goal", None, "no IK solution for the goal"),  # an old row: no `failure`
}
OLD_ROW = ("straight", "beta#0", 0)
# OMPL's status of each failure reason (None: success), as the module docstring documents it
OMPL_STATUS = {
    None: "Exact solution",
    "start_in_collision": "Invalid start",
    "goal_in_collision": "Invalid goal",
    "ik_failure": "Invalid goal",
    "timeout": "Timeout",
    "error": "Crash",
    "no_solution": "Unknown status",
}


def _row(planner: str, scenario: str, case: str, seed: int, i: int) -> dict[str, Any]:
    status, failure, reason = FAILED.get((planner, case, seed), ("success", None, "ok"))
    ok = status == "success"
    metrics, timing = empty_metrics(), empty_timing()
    timing["planning_time_s"] = None if status == "error" else 0.01 * (i + 1) + 1e-9 * i
    timing["wall_time_s"] = 0.5 + 0.1 * i
    if ok:
        metrics.update(
            duration_s=1.0 + i / 7,
            joint_path_length_rad=2.0 + i / 3,
            tcp_path_length_m=0.4 + i / 11,
            smoothness=1e-5 * (i + 1),
            max_jerk=100.0 + i,
            min_clearance_m=None if i == 0 else 0.01 * i,  # a success without a clearance
            contacts=i % 2,
            goal_error_m=1e-4 * i,
        )
        if i == 1:
            del metrics["smoothness"]  # rows written before the metric existed
    row = {
        "run_id": f"{planner}|{case}|seed={seed}|0000",
        "planner": planner,
        "planner_name": planner.replace(" ", "."),
        "scenario": scenario,
        "case": case,
        "kind": "query",
        "seed": seed,
        "status": status,
        "reason": reason,
        "success": ok,
        "failure": failure,
        "metrics": metrics,
        "timing": timing,
    }
    if (planner, case, seed) == OLD_ROW:
        del row["failure"]
    return row


def _rows() -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(all rows, the rows the export keeps): with a skipped planner and a rerun that replaced an error."""
    kept: list[dict[str, Any]] = []
    for scenario, cases in CASES.items():
        for case in cases:
            for seed in SEEDS:
                for planner in PLANNERS:
                    kept.append(_row(planner, scenario, case, seed, len(kept)))
    skipped = [
        {**_row("nmpc", "beta", "beta#0", seed, 99), "status": "skipped", "success": None, "failure": None}
        for seed in SEEDS
    ]
    first_try = {**kept[0], "status": "error", "success": False, "failure": "error", "reason": "WorkerDied"}
    return [first_try, *skipped, *kept], kept


ALL_ROWS, KEPT_ROWS = _rows()


# ---- the two ways to a database ---------------------------------------------------------------------
def _script_db(tmp_path: Path) -> Path:
    """The database OMPL's own script makes from the logs (as `ompl_benchmark_statistics *.log -d DB`)."""
    stats = pytest.importorskip("ompl._benchmark_statistics", reason="OMPL (the `ompl` extra) is not installed")
    logs = write_ompl_logs(ALL_ROWS, tmp_path / "logs", **OPTIONS)
    db = tmp_path / "ompl.db"
    stats.readBenchmarkLog(str(db), sorted(map(str, logs)), False)
    stats.computeViews(str(db), False)
    return db


def _twin_db(tmp_path: Path) -> Path:
    return write_planner_arena_db(ALL_ROWS, tmp_path / "twin.db", **OPTIONS)


def _runs(db: Path) -> dict[tuple[str, str, str, int], dict[str, Any]]:
    """Every run of the database by (experiment, planner, case, seed), its ENUMs as their labels."""
    with sqlite3.connect(db) as conn:
        conn.row_factory = sqlite3.Row
        enums: dict[tuple[str, int], str] = {
            (n, v): d for n, v, d in conn.execute("SELECT name, value, description FROM enums")
        }
        types = {r["name"]: r["type"] for r in conn.execute("PRAGMA table_info(runs)")}
        out = {}
        for r in conn.execute(
            "SELECT runs.*, e.name AS experiment, p.name AS planner FROM runs "
            "JOIN experiments e ON e.id = runs.experimentid JOIN plannerConfigs p ON p.id = runs.plannerid"
        ):
            run = dict(zip(r.keys(), r, strict=True))
            for col, t in types.items():
                if t == "ENUM" and run[col] is not None:
                    run[col] = enums[(col, run[col])]
            out[(run["experiment"], run["planner"], run["twin_case"], run["twin_seed"])] = run
    return out


@pytest.mark.parametrize("make_db", [_script_db, _twin_db], ids=["ompl-script", "twin"])
def test_the_database_holds_one_experiment_per_scenario_and_every_run(
    tmp_path: Path, make_db: Callable[[Path], Path]
) -> None:
    db = make_db(tmp_path)
    with sqlite3.connect(db) as conn:
        experiments = conn.execute(
            "SELECT name, timelimit, runcount, hostname, date, version, cpuinfo, setup FROM experiments"
        ).fetchall()
        planners = [n for (n,) in conn.execute("SELECT name FROM plannerConfigs ORDER BY id")]
        status_enum = [d for (d,) in conn.execute("SELECT description FROM enums WHERE name='status' ORDER BY value")]
        progress = conn.execute("SELECT COUNT(*) FROM progress").fetchone()[0]
    assert [e[:5] for e in experiments] == [
        ("smoke.alpha", 1.0, 4, "bench-host", "2024-05-06 07:08:09"),
        ("smoke.beta", 2.5, 2, "bench-host", "2024-05-06 07:08:09"),
    ]
    # the machine and the software come from the environment record: OMPL's version, cpuinfo, setup lines
    assert [e[5:7] for e in experiments] == [("OMPL 1.7.0", CPUINFO)] * 2
    assert all(f"twin 0.1.0 at {'f' * 40}\nPython: CPython 3.11.7\npackages: numpy 2.4.6" in e[7] for e in experiments)
    assert planners == ["rrt", "straight", "slow_one"]  # the skipped nmpc runs are no runs
    assert status_enum[:9] == [
        "Unknown status",
        "Invalid start",
        "Invalid goal",
        "Unrecognized goal type",
        "Timeout",
        "Approximate solution",
        "Exact solution",
        "Crash",
        "Abort",
    ]
    assert progress == 0

    runs = _runs(db)
    assert len(runs) == len(KEPT_ROWS) == 18
    for row in KEPT_ROWS:
        run = runs[(f"smoke.{row['scenario']}", row["planner"].replace(" ", "_"), row["case"], row["seed"])]
        key = (row["planner"], row["case"], row["seed"])
        failure = FAILED.get(key, (None, None, None))[1]
        if key == OLD_ROW:
            failure = "ik_failure"  # derived from status and reason, as the worker does now
        m, t = row["metrics"], row["timing"]
        assert run["time"] == t["planning_time_s"]  # exactly: REALs are written in full precision
        assert run["solved"] == int(row["success"])
        assert run["status"] == OMPL_STATUS[failure]
        assert run["twin_failure"] == (failure or "none")
        assert run["solution_length"] == m["joint_path_length_rad"]
        assert run["solution_clearance"] == m["min_clearance_m"]
        assert run["solution_smoothness"] == m.get("smoothness")
        assert run["twin_duration_s"] == m["duration_s"]
        assert run["twin_max_jerk"] == m["max_jerk"]
        assert run["twin_tcp_path_length_m"] == m["tcp_path_length_m"]
        assert run["twin_contacts"] == m["contacts"]
        assert run["twin_goal_error_m"] == m["goal_error_m"]
        assert run["twin_wall_time_s"] == t["wall_time_s"]
    first = runs[("smoke.alpha", "rrt", "alpha#0", 0)]
    assert first["status"] == "Exact solution"  # the rerun replaced the row of the first try
    assert first["solution_clearance"] is None  # None is NULL
    assert runs[("smoke.beta", "slow_one", "beta#0", 1)]["time"] is None


def _dump(db: Path) -> dict[str, Any]:
    """Everything of a database a reader sees: its objects, each table's and view's columns and rows."""
    with sqlite3.connect(db) as conn:
        objects = conn.execute("SELECT type, name, tbl_name FROM sqlite_master ORDER BY name").fetchall()
        out: dict[str, Any] = {"objects": objects}
        for kind, name, _ in objects:
            if kind in ("table", "view"):
                out[name] = (
                    conn.execute(f"PRAGMA table_info({name})").fetchall(),
                    conn.execute(f"SELECT * FROM {name}").fetchall(),
                )
    return out


def test_twins_database_is_the_one_the_ompl_script_makes_from_the_logs(tmp_path: Path) -> None:
    ours, theirs = _dump(_twin_db(tmp_path)), _dump(_script_db(tmp_path))
    assert ours["objects"] == theirs["objects"]
    assert {"experiments", "plannerConfigs", "enums", "runs", "progress"} <= set(ours)
    for name in ours:
        assert ours[name] == theirs[name], name
    columns = {c[1]: c[2] for c in ours["runs"][0]}
    assert columns["time"] == "REAL" and columns["solved"] == "BOOLEAN" and columns["status"] == "ENUM"
    assert columns["twin_seed"] == "INTEGER" and columns["twin_failure"] == "ENUM"


def test_export_writes_the_logs_and_the_database(tmp_path: Path) -> None:
    paths = export_planner_arena(ALL_ROWS, tmp_path / "arena", **OPTIONS)
    assert [p.name for p in paths] == ["smoke.alpha.log", "smoke.beta.log", "smoke.db"]
    assert _dump(paths[-1]) == _dump(_twin_db(tmp_path))
    text = paths[0].read_text()
    assert text.startswith("OMPL version ")
    # every planner lists the same run properties
    assert text.count("15 properties for each run\ntime REAL\nsolved BOOLEAN\nstatus ENUM\n") == 3


def test_without_a_record_the_host_is_this_machine_and_an_empty_record_is_unknown(tmp_path: Path) -> None:
    here = write_planner_arena_db(ALL_ROWS, tmp_path / "here.db", name=NAME)  # rows made by this process
    unknown = write_planner_arena_db(ALL_ROWS, tmp_path / "unknown.db", name=NAME, environment={})
    with sqlite3.connect(here) as a, sqlite3.connect(unknown) as b:
        host, cpuinfo = a.execute("SELECT hostname, cpuinfo FROM experiments").fetchone()
        assert b.execute("SELECT hostname, cpuinfo, version FROM experiments").fetchone() == (
            "UNKNOWN",
            None,
            "OMPL twin-export",
        )
    assert host == socket.gethostname().replace(" ", "_") and cpuinfo.startswith("CPU: ") and "cores: " in cpuinfo
    [log] = write_ompl_logs([r for r in ALL_ROWS if r["scenario"] == "beta"], tmp_path / "logs", environment={})
    assert "Running on UNKNOWN\n" in log.read_text() and log.read_text().count("<<<|") == 1  # no cpuinfo block


@pytest.mark.parametrize("write", [write_ompl_logs, write_planner_arena_db, export_planner_arena])
def test_a_bad_output_path_or_no_rows_is_a_config_error(tmp_path: Path, write: Callable[..., Any]) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    with pytest.raises(ConfigError, match="cannot write"):
        write(ALL_ROWS, blocker / "sub" / "x.db")
    with pytest.raises(ConfigError, match="no result rows"):
        write([], tmp_path / "out")
    with pytest.raises(ConfigError, match="all skipped"):
        write([r for r in ALL_ROWS if r["status"] == "skipped"], tmp_path / "out")


def test_exporting_does_not_import_ompl(tmp_path: Path) -> None:
    code = (
        "import sys\n"
        "from tests.test_ompl_export import ALL_ROWS\n"
        "from twin.compare.ompl_export import export_planner_arena\n"
        f"export_planner_arena(ALL_ROWS, {str(tmp_path)!r})\n"
        "assert not [m for m in sys.modules if m.split('.')[0] == 'ompl'], 'ompl was imported'\n"
    )
    root = Path(__file__).resolve().parent.parent
    r = subprocess.run([sys.executable, "-c", code], check=False, cwd=root, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
