"""`twin compare`: a sweep writes one row per run with every metric, is deterministic, survives a kill
(resume finishes it with each run exactly once, reruns error rows, refuses a changed config unless
forced), gives the same rows on Ray, runs what was asked (the whole planner block, also in task runs),
compares planners on queries where they must search, dry-runs every shipped config, and reports bad
configs in one line."""

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
from cli_runner import twin

from twin.compare import (
    compare_spec_from_dict,
    expand_runs,
    latest_rows,
    load_compare_config,
    plan_comparison,
    read_results,
    run_comparison,
)
from twin.compare.metrics import METRIC_KEYS, TIMING_KEYS
from twin.config import load_config
from twin.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent
TRAJECTORY_KEYS = (
    "duration_s",
    "joint_path_length_rad",
    "tcp_path_length_m",
    "max_jerk",
    "min_clearance_m",
    "contacts",
    "contact_time_s",
    "goal_error_m",
    "goal_error_rad",
)

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
    for name in ("planning_time.png", "duration.png", "clearance.png", "success.png", "success_heatmap.png"):
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
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        # poll until two rows are written (or it ended); the bound only stops a sweep that hangs (a fresh CLI and
        # its worker take seconds to start, minutes on a busy machine)
        give_up = time.monotonic() + 600
        while time.monotonic() < give_up:
            if proc.poll() is not None or (results.is_file() and results.read_bytes().count(b"\n") >= 2):
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
        "name": "mixed",
        "planners": ["ruckig.movej"],
        "seeds": [0],
        "scenarios": [
            {
                "name": "q",
                "scene": str(ROOT / "configs" / "robocup.yaml"),
                "queries": [{"start": [0, -1.6, 1.5, -1.5, -1.57, 0], "goal": [0.3, -1.4, 1.2, -1.4, -1.57, 0.2]}],
            },
            {"name": "sorting", "task": str(ROOT / "configs" / "robocup.yaml"), "seeds": [2]},
        ],
    }
    result = run_comparison(write_spec(tmp_path / "mixed.yaml", data), out_dir=tmp_path / "out", workers=0, plots=False)
    [row] = read_results(result.results_path)
    assert row["run_id"].startswith("ruckig.movej|q#0|seed=0|")
    [(rid, why)] = result.skipped
    assert rid.startswith("ruckig.movej|sorting|seed=2|") and why == "skipped: twin.tasks not available"
    assert "skipped: twin.tasks not available" in (result.out_dir / "summary.md").read_text()
    assert result.summary.skipped_pairs == {("ruckig.movej", "sorting"): 1}  # what the heatmap hatches
    page = (result.out_dir / "summary.html").read_text()  # written without plots too
    assert "Who wins on what" in page and "skipped: twin.tasks not available" in page


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
    twice = dict(SWEEP, planners=["ruckig.movej", {"name": "ruckig.movej"}])
    with pytest.raises(ConfigError, match="labels must be unique"):
        load_compare_config(write_spec(tmp_path / "b.yaml", twice))
    with pytest.raises(ConfigError, match="config file not found"):
        load_compare_config(write_spec(tmp_path / "c.yaml", dict(SWEEP, scenarios=[dict(scenario, scene="nope.yaml")])))
    no_queries = dict(SWEEP, scenarios=[{"name": "x", "scene": scenario["scene"]}])
    with pytest.raises(ConfigError, match="exactly one of `queries`"):
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


# ---- what was asked is what ran ---------------------------------------------------------------------
QUINTIC = "seed.quintic_movej"
ONE_QUERY = {"start": [0, -1.6, 1.5, -1.5, -1.57, 0], "goal": [0.3, -1.4, 1.2, -1.4, -1.57, 0.2]}


def variants_spec(min_duration_s: float = 3.0) -> dict[str, Any]:
    """One planner twice: as registered, and slowed down by a param under its own label."""
    return {
        "name": "variants",
        "seeds": [0],
        "planners": [QUINTIC, {"name": QUINTIC, "params": {"min_duration_s": min_duration_s}, "label": "quintic-slow"}],
        "scenarios": [{"name": "q", "scene": str(ROOT / "configs" / "robocup.yaml"), "queries": [ONE_QUERY]}],
    }


def test_run_ids_name_the_run_and_hash_its_whole_definition(tmp_path):
    spec = compare_spec_from_dict(variants_spec())
    a, b = expand_runs(spec)
    assert a.run_id.startswith(f"{QUINTIC}|q#0|seed=0|") and b.run_id.startswith("quintic-slow|q#0|seed=0|")
    assert [r.run_id for r in expand_runs(compare_spec_from_dict(variants_spec()))] == [a.run_id, b.run_id]
    # a changed param is a different run; the unchanged planner keeps its id
    c, d = expand_runs(compare_spec_from_dict(variants_spec(min_duration_s=4.0)))
    assert c.run_id == a.run_id and d.run_id != b.run_id and d.key == b.key
    # so is a changed retimer, scenario setting, seed or scene config ...
    other_seed = compare_spec_from_dict(dict(variants_spec(), seeds=[1]))
    assert expand_runs(other_seed)[0].run_id.split("|")[-1] != a.run_id.split("|")[-1]
    scene = tmp_path / "robocup-slow.yaml"
    scene.write_text(f"extends: {ROOT / 'configs' / 'robocup.yaml'}\nrobot: {{max_joint_vel: 1.0}}\n")
    moved = variants_spec()
    moved["scenarios"][0]["scene"] = str(scene)
    assert expand_runs(compare_spec_from_dict(moved))[0].run_id != a.run_id
    # ... but more queries leave the earlier ones with their ids
    more = variants_spec()
    more["scenarios"][0]["queries"] = [ONE_QUERY, dict(ONE_QUERY, goal=[0.2, -1.4, 1.2, -1.4, -1.57, 0.2])]
    assert [r.run_id for r in expand_runs(compare_spec_from_dict(more))][:2] == [a.run_id, b.run_id]


def test_two_variants_of_one_planner_give_their_own_rows(tmp_path):
    result = run_comparison(compare_spec_from_dict(variants_spec()), out_dir=tmp_path / "out", workers=0, plots=False)
    plain, slow = result.rows
    assert plain["planner"] == QUINTIC and slow["planner"] == "quintic-slow" and slow["planner_name"] == QUINTIC
    assert plain["success"] and slow["success"]
    assert plain["metrics"]["duration_s"] < 3.0 <= slow["metrics"]["duration_s"]


def test_task_runs_take_the_whole_planner_block_as_transfer_planner(monkeypatch):
    """Params and retimer reach the task (no name-only override), so task rows of two variants differ."""
    import twin.tasks
    from twin.compare.worker import execute_run
    from twin.types import RunSummary

    seen: list[tuple[Any, dict[str, Any]]] = []

    def fake_run_task(settings: Any, **kw: Any) -> RunSummary:
        seen.append((settings, kw))
        return RunSummary(
            config="robocup.yaml",
            seed=kw["seed"],
            planner=settings.planners.transfer.name,
            objects=(),
            sim_time_s=1.0,
            wall_time_s=0.1,
        )

    monkeypatch.setattr(twin.tasks, "run_task", fake_run_task)
    block = {"name": "ompl.rrtconnect", "params": {"range": 0.5}, "retimer": "ruckig", "retimer_params": {}}
    spec = compare_spec_from_dict(
        {
            "planners": [dict(block, label="rrtc-ruckig")],
            "scenarios": [{"name": "sorting", "task": str(ROOT / "configs" / "robocup.yaml"), "seeds": [2]}],
        }
    )
    [task] = expand_runs(spec)
    row = execute_run(task)
    assert row["status"] != "error", row["reason"]
    [(settings, kw)] = seen
    assert settings.planners.transfer.model_dump() == block
    assert kw.get("planner") is None and kw["seed"] == 2
    assert settings.planners.movej == load_config(ROOT / "configs" / "robocup.yaml").planners.movej


# ---- resume: changed configs, error rows -----------------------------------------------------------
def test_resume_with_a_changed_planner_block_names_the_change_unless_forced(tmp_path):
    spec, out = write_spec(tmp_path / "v.yaml", variants_spec()), tmp_path / "out"
    first = run_comparison(spec, out_dir=out, workers=0, plots=False)
    write_spec(spec, variants_spec(min_duration_s=4.0))
    with pytest.raises(ConfigError, match=r"planner 'quintic-slow': params\.min_duration_s 3\.0 -> 4\.0.*--force"):
        run_comparison(spec, out_dir=out, workers=0, resume=True, plots=False)
    r = twin("compare", str(spec), "--out", str(out), "--resume")
    assert_one_line_usage_error(r, "quintic-slow", "min_duration_s", "--force")
    assert len(read_results(out / "results.jsonl")) == 2  # nothing was run or lost

    forced = run_comparison(spec, out_dir=out, workers=0, resume=True, force=True, plots=False)
    assert forced.ran == 1 and forced.resumed == 1  # only the changed variant ran again
    assert len(read_results(out / "results.jsonl")) == 3  # the old row stays in the file ...
    slow = forced.rows[1]
    assert slow["run_id"] != first.rows[1]["run_id"] and slow["metrics"]["duration_s"] >= 4.0
    over = {r.planner: r for r in forced.summary.overall}["quintic-slow"]
    assert over.runs == 1 and over.stats["duration_s"].median >= 4.0  # ... but leaves the summary

    assert_one_line_usage_error(
        twin("compare", str(spec), "--out", str(tmp_path / "o2"), "--force"), "--force", "--resume"
    )


def test_rows_that_ended_in_error_are_rerun_on_resume_and_replace_the_old_row(tmp_path):
    spec, out = write_spec(tmp_path / "v.yaml", variants_spec()), tmp_path / "out"
    first = run_comparison(spec, out_dir=out, workers=0, plots=False)
    results = out / "results.jsonl"
    good = json.loads(results.read_text().splitlines()[1])
    broken = dict(good, status="error", success=False, reason="PlanningError: a crash")
    results.write_text(results.read_text().splitlines()[0] + "\n" + json.dumps(broken) + "\n")

    again = run_comparison(spec, out_dir=out, workers=0, resume=True, plots=False)
    assert again.ran == 1 and again.resumed == 1 and again.retried == 1
    rows = read_results(results)
    assert len(rows) == 3 and rows[1]["status"] == "error"  # appended, never rewritten
    latest = latest_rows(rows)
    assert len(latest) == 2 and latest[1]["status"] == "success" and latest[1]["run_id"] == broken["run_id"]
    assert [r["metrics"] for r in again.rows] == [r["metrics"] for r in first.rows]
    assert all(r.errors == 0 for r in again.summary.overall)


# ---- dry run ---------------------------------------------------------------------------------------
COMPARE_CONFIGS = sorted((ROOT / "configs").glob("compare*.yaml"))


@pytest.mark.parametrize("path", COMPARE_CONFIGS, ids=[p.name for p in COMPARE_CONFIGS])
def test_every_shipped_compare_config_dry_runs(path: Path):
    """Every planner block is validated and built (a missing backend would show), every scenario loads and
    draws its first query, and the counts add up."""
    dry = plan_comparison(path)
    spec = dry.spec
    cases = sum(s.case_count() * len(spec.seeds_for(s)) for s in spec.scenarios)
    # every (planner, case) pair runs, except those the planner declares it cannot serve (the MPCs, nmpc and
    # croc: positions only)
    mpcs = ("nmpc", "croc")
    assert dry.total + len(dry.skipped) == len(spec.planners) * cases
    assert dry.total == sum(dry.per_planner().values()) == sum(dry.per_scenario().values())
    assert all(reason.startswith(mpcs) and "cannot reach" in reason for _, reason in dry.skipped)
    assert {n for label, n in dry.per_planner().items() if not label.startswith(mpcs)} == {cases}
    assert len({r.run_id for r in dry.runs} | {rid for rid, _ in dry.skipped}) == len(spec.planners) * cases


def test_every_other_shipped_config_loads():
    others = [p for p in sorted((ROOT / "configs").glob("*.yaml")) if not p.name.startswith("compare")]
    assert others
    for p in others:
        load_config(p)


def test_cli_dry_run_counts_and_writes_nothing(tmp_path):
    r = twin("compare", "configs/compare-smoke.yaml", "--dry-run", "--out", str(tmp_path / "out"))
    assert r.returncode == 0, r.stderr
    n = plan_comparison(ROOT / "configs" / "compare-smoke.yaml").total
    assert (
        f"{n} runs" in r.stdout
        and "would skip 2 runs: nmpc cannot reach pose goals" in r.stdout
        and "ompl.rrtconnect" in r.stdout
        and "warehouse-blocked" in r.stdout
    )
    assert not (tmp_path / "out").exists()


def test_a_region_that_cannot_yield_blocked_queries_is_a_config_error_before_any_run(tmp_path):
    # the default region over the RoboCup table has nothing between start and goal
    data = {
        "planners": ["ruckig.movej"],
        "scenarios": [
            {
                "name": "nothing-in-the-way",
                "scene": str(ROOT / "configs" / "robocup.yaml"),
                "random": {"count": 1, "straight": "blocked"},
            }
        ],
    }
    spec = write_spec(tmp_path / "impossible.yaml", data)
    with pytest.raises(
        ConfigError, match=r"scenarios\.0 \(nothing-in-the-way\)\.random: .*blocked straight joint motion"
    ):
        plan_comparison(spec)
    assert_one_line_usage_error(
        twin("compare", str(spec), "--out", str(tmp_path / "out")), "nothing-in-the-way", "blocked"
    )
    assert not (tmp_path / "out").exists()


# ---- a comparison that compares ----------------------------------------------------------------------
def test_straight_option_draws_queries_of_the_asked_difficulty():
    import numpy as np

    from twin.problems.cells import cell_for
    from twin.problems.sampling import RandomQueries, sample_query, straight_free

    cell = cell_for(str(ROOT / "configs" / "warehouse.yaml"), (), "box")
    home = np.asarray(cell.settings.robot.home, dtype=float)
    for straight in ("blocked", "free"):
        for goal in ("joint", "pose"):
            spec = RandomQueries(count=1, goal=goal, straight=straight).model_dump()
            for i in range(3):
                q = sample_query(spec, np.random.default_rng([i, 7]), scene=cell.scene, kin=cell.kin, home=home)
                assert straight_free(q, scene=cell.scene, kin=cell.kin, resolution_rad=0.01) is (straight == "free"), (
                    goal,
                    i,
                )


OMPL_TRIO = ["ompl.rrtconnect", "ompl.rrtstar", "ompl.bitstar"]


def test_on_blocked_queries_ompl_planners_search_and_their_rows_differ(tmp_path):
    """Three OMPL planners on blocked queries: no row is the straight joint motion, and the planners'
    trajectories differ (the 720 identical straight-line rows of issue 12 cannot come back)."""
    pytest.importorskip("ompl", reason="the OMPL planners need the `ompl` extra")
    import numpy as np

    data = {
        "name": "blocked-trio",
        "seeds": [0],
        "time_limit_s": 0.5,
        "execute": False,
        "planners": OMPL_TRIO,
        "scenarios": [
            {
                "name": "wall",
                "scene": str(ROOT / "configs" / "warehouse.yaml"),
                "random": {"count": 3, "goal": "joint", "straight": "blocked"},
            }
        ],
    }
    result = run_comparison(compare_spec_from_dict(data), out_dir=tmp_path / "out", workers=0, plots=False)
    rows = result.rows
    assert len(rows) == 9 and all(r["status"] != "error" for r in rows), [r["reason"] for r in rows]
    assert all(r["straight_free"] is False for r in rows)
    by_case: dict[str, dict[str, dict[str, Any]]] = {}
    for r in rows:
        by_case.setdefault(r["case"], {})[r["planner"]] = r
    compared = 0
    for case, per in by_case.items():
        q = per["ompl.rrtconnect"]["query"]
        straight = float(np.linalg.norm(np.subtract(q["goal"], q["start"])))
        ok = {p: r["metrics"] for p, r in per.items() if r["success"]}
        assert "ompl.rrtconnect" in ok, per["ompl.rrtconnect"]["reason"]  # the fast one always finds a path
        for p, m in ok.items():
            assert m["joint_path_length_rad"] > 1.001 * straight, (case, p)  # not the straight motion
        fingerprints = {(round(m["joint_path_length_rad"], 9), round(m["duration_s"], 9)) for m in ok.values()}
        assert len(fingerprints) == len(ok), (case, ok)  # no two planners gave the same trajectory
        compared += len(ok) - 1
    assert compared >= 1, "the other planners never succeeded: nothing was compared"


def test_summary_shows_the_closest_pair_and_the_query_difficulty(tmp_path):
    data = dict(
        SWEEP,
        seeds=[0],
        scenarios=[
            {
                "name": "wall-blocked",
                "scene": SWEEP["scenarios"][0]["scene"],
                "random": {"count": 2, "goal": "pose", "straight": "blocked"},
            },
            {
                "name": "wall-free",
                "scene": SWEEP["scenarios"][0]["scene"],
                "random": {"count": 2, "goal": "pose", "straight": "free"},
            },
        ],
    )
    result = run_comparison(compare_spec_from_dict(data), out_dir=tmp_path / "out", workers=0, plots=False)
    ok = [r for r in result.rows if r["success"]]
    assert ok and all(r["clearance_pair"] and "->" in r["clearance_pair"] for r in ok)
    md = (tmp_path / "out" / "summary.md").read_text()
    assert "## Closest approach to the cell" in md
    closest = min(ok, key=lambda r: r["metrics"]["min_clearance_m"])
    assert closest["clearance_pair"] in md
    assert "| wall-blocked | 0/2 | 0% |" in md and "| wall-free | 2/2 | 100% |" in md
    header = (tmp_path / "out" / "summary.csv").read_text().splitlines()[0].split(",")
    assert header[-3:] == ["closest_pair", "common_closest_pair", "straight_free_rate"]
    assert "fallback_steps" in METRIC_KEYS


# ---- runs that hang or crash -------------------------------------------------------------------------
def hang_or_crash(task: Any) -> dict[str, Any]:
    """Stands in for execute_run in the local workers: case #0 hangs, case #1 kills its worker."""
    if task.case.endswith("#0"):
        time.sleep(3600)
    if task.case.endswith("#1"):
        os._exit(3)
    return {"run_id": task.run_id, "status": "success"}


def test_a_run_that_hangs_or_kills_its_worker_is_an_error_row_and_the_sweep_goes_on():
    from dataclasses import replace

    from twin.compare.runner import _run_local

    spec = compare_spec_from_dict(
        dict(SWEEP, seeds=[0], planners=["ruckig.movej"], scenarios=[dict(SWEEP["scenarios"][0], random={"count": 4})])
    )
    tasks = [replace(t, timeout_s=2.0) for t in expand_runs(spec)]
    rows = {r["run_id"]: r for r in _run_local(tasks, 2, run=hang_or_crash)}
    assert set(rows) == {t.run_id for t in tasks}
    hung, crashed, *fine = (rows[t.run_id] for t in tasks)
    assert hung["status"] == "error" and hung["reason"].startswith("RunTimeout: no result after 2 s"), hung
    assert crashed["status"] == "error" and "WorkerDied" in crashed["reason"] and "exit code 3" in crashed["reason"]
    assert set(METRIC_KEYS) == set(hung["metrics"]) and hung["planner"] == "ruckig.movej"
    assert [r["status"] for r in fine] == ["success", "success"]


class SlowToStart:
    """A run function whose worker takes `start_s` to receive it (unpickling it sleeps, in the worker process
    as it starts): a stand-in for a fresh worker importing twin on a busy machine."""

    def __init__(self, start_s: float):
        self.start_s = start_s

    def __getstate__(self) -> float:
        return self.start_s

    def __setstate__(self, start_s: float) -> None:
        time.sleep(start_s)
        self.start_s = start_s

    def __call__(self, task: Any) -> dict[str, Any]:
        return {"run_id": task.run_id, "status": "success"}


def test_a_workers_start_up_is_no_part_of_a_runs_timeout():
    """Each worker takes 8 s to start and each run has 5 s (for a run that returns at once: generous on any
    machine): the timeout counts from when the worker starts the run, so every run succeeds (counted from when
    it was sent, every run was stopped before its worker started)."""
    from dataclasses import replace

    from twin.compare.runner import _run_local

    spec = compare_spec_from_dict(
        dict(SWEEP, seeds=[0], planners=["ruckig.movej"], scenarios=[dict(SWEEP["scenarios"][0], random={"count": 2})])
    )
    tasks = [replace(t, timeout_s=5.0) for t in expand_runs(spec)]
    rows = list(_run_local(tasks, 2, run=SlowToStart(8.0)))
    assert sorted(r["run_id"] for r in rows) == sorted(t.run_id for t in tasks)
    assert [r["status"] for r in rows] == ["success", "success"], rows
