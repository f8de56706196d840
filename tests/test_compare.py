"""`twin compare`: a sweep writes one row per run with every metric, is deterministic, survives a kill
(resume finishes it with each run exactly once), gives the same rows on Ray, and reports bad configs in
one line."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import yaml

from twin.compare import expand_runs, load_compare_config, read_results, run_comparison
from twin.compare.metrics import METRIC_KEYS, TIMING_KEYS
from twin.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent
TRAJECTORY_KEYS = ("duration_s", "joint_path_length_rad", "tcp_path_length_m", "max_jerk", "min_clearance_m",
                   "contacts", "contact_time_s", "goal_error_m", "goal_error_rad")

# 2 planners x 3 random queries x 2 seeds = 12 runs
SWEEP: dict[str, Any] = {
    "name": "test-sweep",
    "seeds": [0, 1],
    "planners": ["ruckig.movej", "toppra.movel"],
    "scenarios": [
        {"name": "warehouse", "scene": str(ROOT / "configs/warehouse.yaml"), "random": {"count": 3, "goal": "pose"}},
    ],
}


def write_spec(path: Path, data: dict[str, Any]) -> Path:
    path.write_text(yaml.safe_dump(data))
    return path


def twin(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "twin", *args]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=timeout)


def assert_one_line_usage_error(r: subprocess.CompletedProcess, *needles: str) -> None:
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    for n in needles:
        assert n in lines[0], lines[0]


def by_id(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    out = {r["run_id"]: r for r in rows}
    assert len(out) == len(rows), "duplicate run ids"
    return out


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Any]:
    """The small sweep, on the default backend (a process pool of 2 workers)."""
    d = tmp_path_factory.mktemp("compare")
    spec = write_spec(d / "sweep.yaml", SWEEP)
    return spec, run_comparison(spec, out_dir=d / "out", workers=2)


# ---- the sweep ------------------------------------------------------------------------------------
def test_a_sweep_writes_one_row_per_run_with_every_metric(sweep):
    spec_path, result = sweep
    rows = read_results(result.results_path)
    assert len(rows) == 12 and result.ran == 12
    ids = by_id(rows)
    assert set(ids) == {r.run_id for r in expand_runs(load_compare_config(spec_path))}
    assert {r["planner"] for r in rows} == {"ruckig.movej", "toppra.movel"} and {r["seed"] for r in rows} == {0, 1}
    for r in rows:
        assert set(r["metrics"]) == set(METRIC_KEYS) and set(r["timing"]) == set(TIMING_KEYS), r["run_id"]
        assert r["status"] and r["status"] != "error", (r["run_id"], r["reason"])
        assert r["timing"]["planning_time_s"] > 0 and r["timing"]["wall_time_s"] > 0
        assert len(r["query"]["start"]) == 6 and len(r["query"]["goal_pose"]) == 6
        if r["success"]:
            m = r["metrics"]
            assert all(m[k] is not None for k in TRAJECTORY_KEYS), r
            assert m["duration_s"] > 0 and m["tcp_path_length_m"] > 0.05 and m["min_clearance_m"] > 0
            assert m["contacts"] == 0 and m["goal_error_m"] < 1e-3  # planned collision-free, tracked closely
    assert sum(r["success"] for r in rows if r["planner"] == "ruckig.movej") == 6


def test_the_sweep_writes_summary_tables(sweep):
    _, result = sweep
    out = result.out_dir
    for name in ("summary.csv", "summary.md"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    lines = (out / "summary.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert header[:5] == ["planner", "scenario", "runs", "successes", "success_rate"]
    assert "duration_s_median" in header and "planning_time_s_p95" in header and "min_clearance_m_p95" in header
    overall = {row.split(",")[0]: row.split(",") for row in lines[1:] if row.split(",")[1] == "all"}
    assert set(overall) == {"ruckig.movej", "toppra.movel"}
    assert float(overall["ruckig.movej"][header.index("success_rate")]) == 1.0
    md = (out / "summary.md").read_text()
    assert "| ruckig.movej | 6 | 100% (6/6)" in md and "duration_s" in md


def test_the_sweep_writes_plots(sweep):
    pytest.importorskip("matplotlib", reason="plots need matplotlib (the `twin[plots]` extra)")
    _, result = sweep
    for name in ("planning_time.png", "duration.png", "clearance.png", "success.png"):
        p = result.out_dir / name
        assert p.is_file() and p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
        assert p in result.files


def test_the_same_sweep_twice_gives_identical_metrics(sweep, tmp_path):
    spec_path, first = sweep
    second = run_comparison(spec_path, out_dir=tmp_path / "again", workers=0, plots=False)  # in-process this time
    a, b = by_id(first.rows), by_id(second.rows)
    assert set(a) == set(b)
    for rid in a:
        for key in ("status", "reason", "success", "query", "metrics", "contact_pairs", "clearance_pair"):
            assert a[rid][key] == b[rid][key], (rid, key)


# ---- crash and resume -----------------------------------------------------------------------------
def test_killed_in_the_middle_and_resumed_each_run_is_there_exactly_once(tmp_path):
    spec = write_spec(tmp_path / "sweep.yaml", SWEEP)
    out = tmp_path / "out"
    results = out / "results.jsonl"
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin", "compare", str(spec), "--out", str(out), "--workers", "1"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if results.is_file() and results.read_bytes().count(b"\n") >= 2:
                break
            time.sleep(0.01)
        os.killpg(proc.pid, signal.SIGKILL)  # the CLI and its workers, as a crash or a power cut would
    finally:
        proc.wait(timeout=30)
    before = results.read_bytes()
    n_before = before.count(b"\n")
    assert 2 <= n_before < 12, f"the sweep was not killed in the middle ({n_before} rows)"
    with open(results, "ab") as f:  # and a line cut short by the crash
        f.write(b'{"run_id": "ruckig.movej|warehouse#1|se')

    result = run_comparison(spec, out_dir=out, workers=2, resume=True, plots=False)
    assert result.resumed == n_before and result.ran == 12 - n_before
    data = results.read_bytes()
    assert data.startswith(before)  # finished rows were kept as they were
    rows = read_results(results)
    assert len(rows) == 12 and len(by_id(rows)) == 12
    assert {r["run_id"] for r in rows} == {r.run_id for r in expand_runs(load_compare_config(spec))}

    again = run_comparison(spec, out_dir=out, workers=0, resume=True, plots=False)
    assert again.ran == 0 and again.resumed == 12 and results.read_bytes() == data


def test_results_reader_drops_only_a_truncated_last_line(tmp_path):
    p = tmp_path / "results.jsonl"
    good = [json.dumps({"run_id": f"r{i}"}) for i in range(3)]
    p.write_text("\n".join(good) + '\n{"run_id": "r3", "met')
    assert [r["run_id"] for r in read_results(p)] == ["r0", "r1", "r2"]
    read_results(p, repair=True)
    assert p.read_text() == "\n".join(good) + "\n"
    p.write_text(good[0] + "\n{broken\n" + good[1] + "\n")
    with pytest.raises(ConfigError, match="line 2"):
        read_results(p)


def test_an_existing_sweep_is_not_overwritten_without_resume(sweep):
    spec_path, result = sweep
    with pytest.raises(ConfigError, match="--resume"):
        run_comparison(spec_path, out_dir=result.out_dir, workers=0)


def test_task_scenarios_are_skipped_when_twin_tasks_is_missing(tmp_path, monkeypatch):
    monkeypatch.setattr("twin.compare.runner.tasks_available", lambda: False)
    data = {
        "name": "mixed", "planners": ["ruckig.movej"], "seeds": [0],
        "scenarios": [
            {"name": "q", "scene": str(ROOT / "configs" / "robocup.yaml"),
             "queries": [{"start": [0, -1.6, 1.5, -1.5, -1.57, 0], "goal": [0.3, -1.4, 1.2, -1.4, -1.57, 0.2]}]},
            {"name": "sorting", "task": str(ROOT / "configs" / "robocup.yaml"), "seeds": [2]},
        ],
    }
    result = run_comparison(write_spec(tmp_path / "mixed.yaml", data), out_dir=tmp_path / "out", workers=0, plots=False)
    assert [r["run_id"] for r in read_results(result.results_path)] == ["ruckig.movej|q#0|seed=0"]
    assert result.skipped == [("ruckig.movej|sorting|seed=2", "skipped: twin.tasks not available")]
    assert "skipped: twin.tasks not available" in (result.out_dir / "summary.md").read_text()


# ---- Ray ------------------------------------------------------------------------------------------
def test_the_ray_backend_gives_the_same_rows_as_the_local_one(tmp_path):
    pytest.importorskip("ray", reason="ray is not installed (the `twin[ray]` extra); CI installs it")
    small = dict(SWEEP, seeds=[0], scenarios=[dict(SWEEP["scenarios"][0], random={"count": 2, "goal": "pose"})])
    spec = write_spec(tmp_path / "small.yaml", small)
    local = run_comparison(spec, out_dir=tmp_path / "local", workers=0, plots=False)
    remote = run_comparison(spec, out_dir=tmp_path / "ray", workers=2, backend="ray", plots=False)
    a, b = by_id(local.rows), by_id(read_results(remote.results_path))
    assert len(a) == 4 and set(a) == set(b)
    for rid in a:
        for key in ("status", "success", "query", "metrics", "contact_pairs"):
            assert a[rid][key] == b[rid][key], (rid, key)


# ---- config errors --------------------------------------------------------------------------------
def test_spec_errors_name_the_key(tmp_path):
    scenario = SWEEP["scenarios"][0]
    bad = dict(SWEEP, scenarios=[dict(scenario, bogus=1)])
    with pytest.raises(ConfigError, match=r"unknown key 'scenarios\.0\.bogus'"):
        load_compare_config(write_spec(tmp_path / "a.yaml", bad))
    with pytest.raises(ConfigError, match="labels must be unique"):
        twice = dict(SWEEP, planners=["ruckig.movej", {"name": "ruckig.movej"}])
        load_compare_config(write_spec(tmp_path / "b.yaml", twice))
    with pytest.raises(ConfigError, match="config file not found"):
        load_compare_config(write_spec(tmp_path / "c.yaml", dict(SWEEP, scenarios=[dict(scenario, scene="nope.yaml")])))
    with pytest.raises(ConfigError, match="exactly one of `queries`"):
        no_queries = dict(SWEEP, scenarios=[{"name": "x", "scene": scenario["scene"]}])
        load_compare_config(write_spec(tmp_path / "d.yaml", no_queries))
    child = tmp_path / "child.yaml"
    child.write_text("extends: e.yaml\nseeds: [5]\n")
    write_spec(tmp_path / "e.yaml", SWEEP)
    assert load_compare_config(child, ["planners=[ruckig.movej]"]).seeds == [5]


def test_cli_reports_a_bad_compare_config_in_one_line(tmp_path):
    spec = write_spec(tmp_path / "bad.yaml", dict(SWEEP, planners=["ruckig.movej", "toppra.movl"]))
    r = twin("compare", str(spec), "--out", str(tmp_path / "out"))
    assert_one_line_usage_error(r, "planners.1", "'toppra.movl' is not registered", "Did you mean 'toppra.movel'")
    assert not (tmp_path / "out").exists()  # checked before any run started

    spec = write_spec(tmp_path / "bad2.yaml", dict(SWEEP, seed=3))
    assert_one_line_usage_error(twin("compare", str(spec)), "unknown key 'seed'")
