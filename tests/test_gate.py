"""The regression gate (`twin compare --baseline`): the same sweep twice passes, a baseline that was better
(more successes, faster p95 planning, shorter trajectories) fails with that check regressed, timing noise
within the tolerance passes, unpaired runs are counted and never fail, a sweep that shares no run with its
baseline and a file that is no baseline are one-line ConfigErrors."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import pytest

from twin.compare import compare_spec_from_dict, read_results, run_comparison
from twin.compare.gate import GateReport, Tolerance, check_shares_runs, gate, load_baseline, load_baseline_environment
from twin.errors import ConfigError


def row(
    planner: str,
    i: int,
    *,
    success: bool = True,
    planning_time_s: float | None = 0.010,
    duration_s: float | None = 2.0,
    status: str | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """A result row as the worker writes it (only the keys the gate reads, plus the identifying ones)."""
    return {
        "run_id": f"{planner}|s#{i}|seed={seed}|abcd{i:04d}",
        "planner": planner,
        "scenario": "s",
        "case": f"s#{i}",
        "seed": seed,
        "status": status or ("success" if success else "no_solution"),
        "success": success,
        "metrics": {"duration_s": duration_s if success else None},
        "timing": {"planning_time_s": planning_time_s, "wall_time_s": 0.1},
    }


def sweep() -> list[dict[str, Any]]:
    """Two planners x 10 runs: 'a' solves all, 'b' 8 of 10; planning times and durations vary by run."""
    rows = [row("a", i, planning_time_s=0.001 * (1 + i), duration_s=1.0 + 0.1 * i) for i in range(10)]
    rows += [row("b", i, success=i < 8, planning_time_s=0.1 + 0.01 * i, duration_s=3.0 + 0.2 * i) for i in range(10)]
    return rows


def check(report: GateReport, planner: str, quantity: str):
    [c] = [c for c in report.checks if c.planner == planner and c.quantity == quantity]
    return c


def regressed(report: GateReport) -> set[tuple[str, str]]:
    return {(c.planner, c.quantity) for c in report.checks if c.verdict == "regressed"}


# ---- the verdict ----------------------------------------------------------------------------------
def test_the_same_sweep_passes_with_a_check_per_planner_and_quantity():
    report = gate(sweep(), sweep())
    assert report.passed and regressed(report) == set()
    assert (report.matched, report.only_new, report.only_baseline) == (20, 0, 0)
    assert [(c.planner, c.quantity) for c in report.checks] == [
        (p, q) for p in ("a", "b") for q in ("success_rate", "planning_time_p95_s", "duration_p95_s")
    ]
    b = check(report, "b", "success_rate")
    assert (b.baseline, b.now, b.limit, b.n) == (0.8, 0.8, 0.8, 10)
    assert check(report, "b", "duration_p95_s").n == 8  # successful runs only
    assert "regression gate: passed" in report.render()
    assert json.loads(json.dumps(report.to_json()))["passed"] is True


def test_a_baseline_with_a_success_the_sweep_lost_fails_on_the_success_rate():
    base = sweep()
    base[18] = row("b", 8, planning_time_s=0.18, duration_s=4.6)  # the baseline solved b's run 8
    report = gate(sweep(), base)
    assert not report.passed and regressed(report) == {("b", "success_rate")}
    c = check(report, "b", "success_rate")
    assert (c.baseline, c.now) == (0.9, 0.8) and c.change == pytest.approx(-0.1)
    assert "REGRESSED" in report.render() and "- b: success rate 90% (9/10) -> 80% (8/10)" in report.render()
    # a tolerated drop of 10 points passes
    assert gate(sweep(), base, Tolerance(success_drop=0.1)).passed


def test_an_error_row_is_a_failure():
    new = sweep()
    new[0] = {**new[0], "status": "error", "success": False, "metrics": {"duration_s": None}, "timing": {}}
    report = gate(new, sweep())
    assert regressed(report) == {("a", "success_rate")}
    assert check(report, "a", "planning_time_p95_s").n == 9  # no planning time on both sides for run 0


def test_a_much_faster_baseline_fails_on_p95_planning_time():
    base = [
        {**r, "timing": {**r["timing"], "planning_time_s": r["timing"]["planning_time_s"] / 3}}
        if r["planner"] == "b"
        else r
        for r in sweep()
    ]
    report = gate(sweep(), base)
    assert regressed(report) == {("b", "planning_time_p95_s")}
    c = check(report, "b", "planning_time_p95_s")
    assert c.now == pytest.approx(3 * c.baseline) and c.limit == pytest.approx(2 * c.baseline + 0.005)
    assert c.change == pytest.approx(2.0)


def test_shorter_baseline_durations_fail_on_p95_duration():
    base = copy.deepcopy(sweep())
    for r in base:
        if r["planner"] == "a":
            r["metrics"]["duration_s"] *= 0.9  # the sweep's trajectories are 11 % longer
    report = gate(sweep(), base)
    assert regressed(report) == {("a", "duration_p95_s")}
    assert gate(sweep(), base, Tolerance(duration=0.12)).passed


def test_timing_noise_within_the_tolerance_passes():
    base = sweep()
    noisy = copy.deepcopy(base)
    for i, r in enumerate(noisy):
        r["timing"]["planning_time_s"] *= 1.8 if i % 2 else 0.7  # a loaded CI machine
        if r["metrics"]["duration_s"] is not None:
            r["metrics"]["duration_s"] *= 1.03  # a sampling planner's jitter
    assert gate(noisy, base).passed
    # a planner answering in ~1 ms that now takes ~3 ms is noise: within the absolute slack
    fast = [row("a", i, planning_time_s=0.001) for i in range(5)]
    slower = [row("a", i, planning_time_s=0.003) for i in range(5)]
    report = gate(slower, fast)
    assert report.passed and check(report, "a", "planning_time_p95_s").limit == pytest.approx(0.007)
    assert not gate(slower, fast, Tolerance(planning_time_abs_s=0.0)).passed


def test_unpaired_runs_are_counted_and_do_not_fail():
    base = sweep()[:15]  # b's runs 5..9 are not in the baseline
    new = sweep() + [row("c", i, success=False) for i in range(3)]  # a new planner, all failing
    base.append(row("a", 99, seed=7))  # a run this sweep no longer has
    report = gate(new, base)
    assert report.passed
    assert (report.matched, report.only_new, report.only_baseline) == (15, 8, 1)
    assert {c.planner for c in report.checks} == {"a", "b"}
    assert check(report, "b", "success_rate").n == 5
    assert "15 in both sweeps, 8 only in this sweep, 1 only in the baseline" in report.render()


def test_the_latest_row_of_a_run_counts_and_skipped_rows_are_no_runs():
    base = sweep()
    retried = sweep()
    retried.insert(0, {**retried[0], "status": "error", "success": False})  # an error row, rerun later
    retried.append(row("a", 50, status="skipped", success=False))
    report = gate(retried, base)
    assert report.passed and (report.matched, report.only_new) == (20, 0)


def test_no_shared_run_id_is_a_config_error():
    other = [{**r, "run_id": r["run_id"] + "x"} for r in sweep()]
    with pytest.raises(ConfigError, match=r"no run of this sweep is in the baseline.*another config") as e:
        gate(sweep(), other)
    assert "\n" not in str(e.value)


def test_a_baseline_that_shares_no_run_is_named_with_both_counts_before_anything_runs():
    ids = [r["run_id"] for r in sweep()]
    assert check_shares_runs(sweep()[:5], ids, baseline="old/results.jsonl") == 5
    other = [{**r, "run_id": r["run_id"] + "x"} for r in sweep()[:7]]
    other.append(sweep()[0] | {"status": "skipped"})  # a skipped row is no run, even with a shared id
    with pytest.raises(ConfigError) as e:
        check_shares_runs(other, ids, baseline="old/results.jsonl")
    text = str(e.value)
    assert "\n" not in text and text.startswith("baseline old/results.jsonl shares no run with this sweep")
    assert "none of its 7 run ids is among this sweep's 20" in text


# ---- where the sweeps ran -------------------------------------------------------------------------
def _env(**cpu: Any) -> dict[str, Any]:
    return {
        "twin": {"version": "0.1.0", "commit": "c" * 40, "dirty": False},
        "python": {"version": "3.11.7", "implementation": "CPython"},
        "packages": {"numpy": "2.4.6", "ompl": "2.0.1"},
        "cpu": {"model": "AMD EPYC", "cores": 2, "usable_cores": 2, **cpu},
        "hostname": "ci",
    }


def test_the_report_names_what_changed_where_the_sweeps_ran_and_the_verdict_stands():
    base = copy.deepcopy(sweep())
    for r in base:  # a baseline made on a faster machine: planning took a third of the time
        r["timing"]["planning_time_s"] /= 3
    slower = _env(model="Intel Celeron", cores=4)
    slower["packages"]["numpy"] = "2.5.0"
    report = gate(sweep(), base, environment=slower, baseline_environment=_env())
    assert regressed(report) == regressed(gate(sweep(), base))  # the environment never changes the verdict
    assert report.environment_compared
    assert report.environment_changes == [
        "numpy: 2.4.6 -> 2.5.0",
        "CPU: AMD EPYC -> Intel Celeron",
        "cores: 2 (2 usable) -> 4 (2 usable)",
    ]
    text = report.render()
    assert "environment changed since the baseline" in text
    assert "- CPU: AMD EPYC -> Intel Celeron" in text and "- numpy: 2.4.6 -> 2.5.0" in text
    assert json.loads(json.dumps(report.to_json()))["environment_changes"] == report.environment_changes

    same = gate(sweep(), sweep(), environment=_env(), baseline_environment=_env())
    assert same.environment_changes == [] and "environment: as the baseline's" in same.render()
    unknown = gate(sweep(), sweep(), environment=_env(), baseline_environment=None)
    assert not unknown.environment_compared and "the baseline recorded none" in unknown.render()
    assert "environment" not in gate(sweep(), sweep()).render()  # no records given: nothing said


def test_without_data_a_check_is_not_applicable():
    new = [row("a", i, success=False) for i in range(3)]
    report = gate(new, [row("a", i, success=False) for i in range(3)])
    c = check(report, "a", "duration_p95_s")
    assert report.passed and (c.verdict, c.baseline, c.now, c.n) == ("n/a", None, None, 0)


def test_render_of_a_failing_gate_is_a_table_with_the_regressions_listed():
    base = copy.deepcopy(sweep())
    for r in base:
        if r["planner"] == "b":
            r["timing"]["planning_time_s"] /= 3
    base[18] = row("b", 8, planning_time_s=0.06, duration_s=4.6)
    text = gate(sweep(), base).render()
    lines = text.splitlines()
    assert lines[0] == "regression gate: FAILED, 2 of 6 checks regressed"
    table = [ln for ln in lines if ln.startswith("|")]
    assert len(table) == 2 + 6 and len({len(ln) for ln in table}) == 1  # aligned columns
    assert [h.strip() for h in table[0].split("|")[1:-1]] == [
        "planner",
        "quantity",
        "n",
        "baseline",
        "now",
        "change",
        "limit",
        "verdict",
    ]
    assert sum("REGRESSED" in ln for ln in table) == 2
    assert "- b: p95 planning time" in text and "- b: success rate" in text


# ---- Tolerance.parse ------------------------------------------------------------------------------
def test_tolerance_parse():
    t = Tolerance.parse("success=0.05,planning_time=0.5,duration=0.1,planning_time_abs_s=0.01")
    assert t == Tolerance(success_drop=0.05, planning_time=0.5, duration=0.1, planning_time_abs_s=0.01)
    assert Tolerance.parse("") == Tolerance()
    assert Tolerance.parse(" duration = 10% ") == Tolerance(duration=0.1)
    assert Tolerance.parse("success_drop=0.1").success_drop == 0.1
    assert math.isinf(Tolerance.parse("planning_time=inf").planning_time)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("sucess=0.1", "unknown key 'sucess'"),
        ("duration=fast", "duration='fast' is not a number"),
        ("duration=-0.1", "is not a number >= 0"),
        ("duration=nan", "is not a number >= 0"),
        ("duration", "is not key=value"),
        ("duration=0.1,duration=0.2", "given twice"),
    ],
)
def test_tolerance_parse_rejects_bad_input_in_one_line(text, needle):
    with pytest.raises(ConfigError) as e:
        Tolerance.parse(text)
    msg = str(e.value)
    assert needle in msg and "\n" not in msg
    assert "success, planning_time, planning_time_abs_s, duration" in msg


# ---- load_baseline --------------------------------------------------------------------------------
def test_load_baseline(tmp_path):
    path = tmp_path / "results.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in sweep()))
    assert load_baseline(path) == sweep()
    assert load_baseline(tmp_path) == sweep()  # the output folder works too
    for bad, needle in [
        (tmp_path / "nope.jsonl", "does not exist"),
        (tmp_path / "empty.jsonl", "holds no result rows"),
        (tmp_path / "summary.csv", "is not a results.jsonl"),
        (tmp_path / "other.jsonl", "has no 'planner'"),
    ]:
        if bad.name == "empty.jsonl":
            bad.write_text("")
        elif bad.name == "summary.csv":
            bad.write_text("planner,scenario,runs\na,all,10\n")
        elif bad.name == "other.jsonl":
            bad.write_text('{"run_id": "x"}\n')
        with pytest.raises(ConfigError, match=needle) as e:
            load_baseline(bad)
        assert "\n" not in str(e.value)


# ---- real rows --------------------------------------------------------------------------------------
def test_a_rerun_of_a_real_sweep_passes_its_baseline_and_a_doctored_baseline_fails(tmp_path: Path):
    spec = compare_spec_from_dict(
        {
            "name": "gate",
            "seeds": [0],
            "execute": False,
            "planners": ["ruckig.movej"],
            "scenarios": [
                {"name": "w", "scene": "warehouse.yaml", "random": {"count": 2, "goal": "joint", "straight": "free"}}
            ],
        }
    )
    first = run_comparison(spec, out_dir=tmp_path / "first", workers=0, plots=False)
    second = run_comparison(spec, out_dir=tmp_path / "second", workers=0, plots=False)
    baseline = load_baseline(first.results_path)
    assert len(baseline) == 2 and all(r["success"] for r in baseline)

    report = gate(read_results(second.results_path), baseline)
    assert report.passed, report.render()
    assert (report.matched, report.only_new, report.only_baseline) == (2, 0, 0)
    assert {c.quantity: c.verdict for c in report.checks} == {
        "success_rate": "ok",
        "planning_time_p95_s": "ok",
        "duration_p95_s": "ok",
    }
    assert check(report, "ruckig.movej", "duration_p95_s").change == pytest.approx(0.0)  # deterministic

    # the rerun fails a run the baseline solved
    now = copy.deepcopy(read_results(second.results_path))
    now[0].update(success=False, status="no_solution")
    now[0]["metrics"]["duration_s"] = None
    assert regressed(gate(now, baseline)) == {("ruckig.movej", "success_rate")}

    # the baseline's trajectories were half as long
    shorter = copy.deepcopy(baseline)
    for r in shorter:
        r["metrics"]["duration_s"] *= 0.5
    report = gate(read_results(second.results_path), shorter)
    assert not report.passed and regressed(report) == {("ruckig.movej", "duration_p95_s")}


# ---- the command line ---------------------------------------------------------------------------------
CLI_SWEEP = """
name: gate-cli
seeds: [0]
execute: false
planners: [ruckig.movej]
scenarios:
  - {name: w, scene: warehouse, random: {count: 2, goal: joint, straight: free}}
"""


def test_the_command_line_checks_the_baseline_before_the_sweep_and_names_environment_changes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
):
    from twin.cli import main
    from twin.environment import environment

    cfg = tmp_path / "gate.yaml"
    cfg.write_text(CLI_SWEEP)
    first = tmp_path / "first"
    assert main(["compare", str(cfg), "--out", str(first), "--workers", "0"]) == 0
    recorded = json.loads((first / "compare.json").read_text())["environment"]
    assert recorded["twin"] == environment()["twin"] and recorded["packages"] == environment()["packages"]
    assert load_baseline_environment(first) == load_baseline_environment(first / "results.jsonl") == recorded
    capsys.readouterr()

    # an unrelated baseline: one line, exit 2, and not one run (no results.jsonl, no progress line)
    unrelated = tmp_path / "unrelated.jsonl"
    unrelated.write_text("".join(json.dumps(r) + "\n" for r in sweep()))
    never = tmp_path / "never"
    assert main(["compare", str(cfg), "--out", str(never), "--workers", "0", "--baseline", str(unrelated)]) == 2
    out, err = capsys.readouterr()
    assert len(err.strip().splitlines()) == 1, err
    assert f"baseline {unrelated} shares no run with this sweep" in err
    assert "none of its 20 run ids is among this sweep's 2" in err
    assert not (never / "results.jsonl").exists() and "[1/" not in out

    # a dry run says how many runs the baseline shares
    base = str(first / "results.jsonl")
    assert main(["compare", str(cfg), "--dry-run", "--baseline", base]) == 0
    assert f"baseline {base}: shares 2 of this sweep's 2 runs" in capsys.readouterr().out

    # the baseline ran elsewhere: the gate passes and says what differs
    spec = json.loads((first / "compare.json").read_text())
    spec["environment"]["packages"]["numpy"] = "1.26.4"
    spec["environment"]["cpu"]["model"] = "Some Other CPU"
    (first / "compare.json").write_text(json.dumps(spec))
    assert main(["compare", str(cfg), "--out", str(tmp_path / "second"), "--workers", "0", "--baseline", base]) == 0
    out = capsys.readouterr().out
    assert "regression gate: passed" in out and "environment changed since the baseline" in out
    assert f"- numpy: 1.26.4 -> {recorded['packages']['numpy']}" in out
    assert f"- CPU: Some Other CPU -> {recorded['cpu']['model']}" in out

    # a baseline from before twin recorded its environment
    del spec["environment"]
    (first / "compare.json").write_text(json.dumps(spec))
    assert main(["compare", str(cfg), "--out", str(tmp_path / "third"), "--workers", "0", "--baseline", base]) == 0
    assert "the baseline recorded none" in capsys.readouterr().out
