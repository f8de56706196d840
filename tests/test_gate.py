"""The regression gate (`twin compare --baseline`), issue 38: a check regresses only when its value is beyond
the tolerance AND the paired runs are significantly worse, and a check with too few runs says "not enough
runs". Two runs of the same commit pass on three configs even with a busy machine's timing noise on both,
a doctored 2x slowdown and a lost success rate fail, a p95 of 4 runs is not judged; unpaired runs are
counted and never fail, a sweep that shares no run with its baseline and a file that is no baseline are
one-line ConfigErrors."""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from twin.compare import compare_spec_from_dict, read_results, run_comparison
from twin.compare.gate import (
    MIN_P95_RUNS,
    MIN_SUCCESS_RUNS,
    GateCheck,
    GateReport,
    Tolerance,
    check_shares_runs,
    gate,
    load_baseline,
    load_baseline_environment,
)
from twin.errors import ConfigError

N = 25  # runs per planner in `sweep()`: at least MIN_P95_RUNS, so every check is judged


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
    """Two planners x 25 runs: 'a' solves all, 'b' 20 of 25 (not runs 4, 9, ...); times vary by run."""
    rows = [row("a", i, planning_time_s=0.001 * (1 + i), duration_s=1.0 + 0.1 * i) for i in range(N)]
    rows += [
        row("b", i, success=i % 5 != 4, planning_time_s=0.1 + 0.01 * i, duration_s=3.0 + 0.2 * i) for i in range(N)
    ]
    return rows


def solved_all() -> list[dict[str, Any]]:
    """`sweep()` as a baseline in which 'b' solved its five failures as well."""
    return [r for r in sweep() if r["planner"] == "a"] + [
        row("b", i, planning_time_s=0.1 + 0.01 * i, duration_s=3.0 + 0.2 * i) for i in range(N)
    ]


def check(report: GateReport, planner: str, quantity: str) -> GateCheck:
    [c] = [c for c in report.checks if c.planner == planner and c.quantity == quantity]
    return c


def regressed(report: GateReport) -> set[tuple[str, str]]:
    return {(c.planner, c.quantity) for c in report.checks if c.verdict == "regressed"}


def scaled(rows: list[dict[str, Any]], planner: str, group: str, key: str, factor: float) -> list[dict[str, Any]]:
    """A copy of `rows` with `planner`'s `group.key` values multiplied by `factor` (a doctored sweep)."""
    out = copy.deepcopy(rows)
    for r in out:
        if r["planner"] == planner and r[group].get(key) is not None:
            r[group][key] *= factor
    return out


def lose(rows: list[dict[str, Any]], planner: str, runs: Callable[[int], bool]) -> list[dict[str, Any]]:
    """A copy of `rows` where `planner` fails the runs (its k-th run, counted from 0) that `runs` picks."""
    out = copy.deepcopy(rows)
    k = 0
    for r in out:
        if r["planner"] != planner:
            continue
        if runs(k):
            r.update(success=False, status="no_solution")
            r["metrics"]["duration_s"] = None
        k += 1
    return out


# ---- the verdict ----------------------------------------------------------------------------------
def test_the_same_sweep_passes_with_a_check_per_planner_and_quantity():
    report = gate(sweep(), sweep())
    assert report.passed and regressed(report) == set() and report.not_judged == []
    assert (report.matched, report.only_new, report.only_baseline) == (50, 0, 0)
    assert [(c.planner, c.quantity) for c in report.checks] == [
        (p, q) for p in ("a", "b") for q in ("success_rate", "planning_time_p95_s", "duration_p95_s")
    ]
    b = check(report, "b", "success_rate")
    assert (b.baseline, b.now, b.limit, b.n, b.worse, b.better, b.p_value) == (0.8, 0.8, 0.8, 25, 0, 0, None)
    assert check(report, "b", "duration_p95_s").n == 20  # successful runs only
    assert all(c.verdict == "ok" for c in report.checks)
    assert "regression gate: passed, none of 6 checks regressed\n" in report.render()
    assert json.loads(json.dumps(report.to_json()))["passed"] is True


def test_a_lost_success_fails_only_when_the_exact_test_says_it_is_real():
    """5 of 5 differing runs lost could be chance (exact McNemar p = 0.0625); 6 of 6 is not (p = 0.031)."""
    solved = solved_all()
    report = gate(sweep(), solved)  # the baseline solved b's five failures
    c = check(report, "b", "success_rate")
    assert (c.baseline, c.now, c.worse, c.better) == (1.0, 0.8, 5, 0)
    assert c.beyond and c.p_value is None and c.verdict == "ok" and report.passed
    assert c.verdict_text == "ok: not significant" and "no test: 5 differ, fewer than 6" in c.test_text

    report = gate(lose(sweep(), "b", lambda k: k == 0), solved)  # and now one more lost
    c = check(report, "b", "success_rate")
    assert (c.worse, c.better) == (6, 0) and c.p_value == pytest.approx(2 / 2**6)
    assert not report.passed and regressed(report) == {("b", "success_rate")}
    text = report.render()
    assert "REGRESSED" in text
    assert "- b: success rate 100% (25/25) -> 76% (19/25) (limit >= 100%, n=25, 6 lost, 0 gained, exact McNemar" in text
    # a tolerated drop: real, but within what the user allows
    assert gate(lose(sweep(), "b", lambda k: k == 0), solved, Tolerance(success_drop=0.25)).passed
    # as many gained as lost is no loss, whatever the count
    swapped = lose(solved, "b", lambda k: k < 6)
    assert check(gate(swapped, sweep()), "b", "success_rate").verdict == "ok"


def test_a_complete_loss_of_success_fails_from_six_paired_runs():
    base = [row("a", i) for i in range(MIN_SUCCESS_RUNS)]
    gone = [row("a", i, success=False) for i in range(MIN_SUCCESS_RUNS)]
    c = check(gate(gone, base), "a", "success_rate")
    assert c.verdict == "regressed" and c.p_value == pytest.approx(0.03125)
    # with one run fewer, even a total loss cannot be told from chance (p = 2 / 2^5 = 0.0625)
    c = check(gate(gone[1:], base[1:]), "a", "success_rate")
    assert c.verdict == "not_enough_runs" and c.verdict_text == "not enough runs (n = 5; need >= 6)"


def test_error_rows_are_failures():
    new = sweep()
    for i in range(6):
        new[i] = {**new[i], "status": "error", "success": False, "metrics": {"duration_s": None}, "timing": {}}
    report = gate(new, sweep())
    assert regressed(report) == {("a", "success_rate")}
    assert check(report, "a", "planning_time_p95_s").n == N - 6  # no planning time on both sides for runs 0-5


def test_a_much_faster_baseline_fails_on_p95_planning_time():
    base = scaled(sweep(), "b", "timing", "planning_time_s", 1 / 3)
    report = gate(sweep(), base)
    assert regressed(report) == {("b", "planning_time_p95_s")}
    c = check(report, "b", "planning_time_p95_s")
    assert c.now == pytest.approx(3 * c.baseline) and c.limit == pytest.approx(2 * c.baseline + 0.005)
    assert c.change == pytest.approx(2.0)
    assert (c.worse, c.better, c.n) == (25, 0, 25) and c.p_value < 1e-3 and c.significant and c.beyond


def test_shorter_baseline_durations_fail_on_p95_duration():
    base = scaled(sweep(), "a", "metrics", "duration_s", 0.9)  # the sweep's trajectories are 11 % longer
    report = gate(sweep(), base)
    assert regressed(report) == {("a", "duration_p95_s")}
    tolerated = check(gate(sweep(), base, Tolerance(duration=0.12)), "a", "duration_p95_s")
    assert tolerated.verdict == "ok" and tolerated.verdict_text == "ok: within tolerance"  # real, but small


def test_timing_noise_within_the_tolerance_passes():
    base = sweep()
    noisy = copy.deepcopy(base)
    for i, r in enumerate(noisy):
        r["timing"]["planning_time_s"] *= 1.8 if i % 2 else 0.7  # a loaded CI machine
        if r["metrics"]["duration_s"] is not None:
            r["metrics"]["duration_s"] *= 1.03  # a sampling planner's jitter
    assert gate(noisy, base).passed
    # a planner answering in ~1 ms that now takes ~3 ms is noise: within the absolute slack
    fast = [row("a", i, planning_time_s=0.001) for i in range(N)]
    slower = [row("a", i, planning_time_s=0.003) for i in range(N)]
    report = gate(slower, fast)
    c = check(report, "a", "planning_time_p95_s")
    assert report.passed and c.limit == pytest.approx(0.007) and c.significant  # real, within the slack
    assert not gate(slower, fast, Tolerance(planning_time_abs_s=0.0)).passed


def test_a_p95_beyond_its_limit_from_a_few_slow_runs_is_not_significant():
    """The issue's failure: a few runs a busy neighbour slowed move the p95 far beyond the limit, while most
    runs are as fast as before: not significant, so not a regression."""
    base = sweep()
    busy = scaled(base, "b", "timing", "planning_time_s", 1.0)
    for r in busy[-3:]:  # b's three slowest runs took 4x as long
        r["timing"]["planning_time_s"] *= 4
    c = check(gate(busy, base), "b", "planning_time_p95_s")
    assert c.beyond and (c.worse, c.better) == (3, 0) and c.p_value is None and c.verdict == "ok"


def test_unpaired_runs_are_counted_and_do_not_fail():
    base = sweep()[: N + 15]  # b's runs 15..24 are not in the baseline
    new = sweep() + [row("c", i, success=False) for i in range(3)]  # a new planner, all failing
    base.append(row("a", 99, seed=7))  # a run this sweep no longer has
    report = gate(new, base)
    assert report.passed
    assert (report.matched, report.only_new, report.only_baseline) == (N + 15, 13, 1)
    assert {c.planner for c in report.checks} == {"a", "b"}
    assert check(report, "b", "success_rate").n == 15
    assert check(report, "b", "planning_time_p95_s").verdict == "not_enough_runs"  # 15 paired runs of b
    assert "40 in both sweeps, 13 only in this sweep, 1 only in the baseline" in report.render()


def test_the_latest_row_of_a_run_counts_and_skipped_rows_are_no_runs():
    base = sweep()
    retried = sweep()
    retried.insert(0, {**retried[0], "status": "error", "success": False})  # an error row, rerun later
    retried.append(row("a", 50, status="skipped", success=False))
    report = gate(retried, base)
    assert report.passed and (report.matched, report.only_new) == (50, 0)


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
    assert "none of its 7 run ids is among this sweep's 50" in text


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
    new = [row("a", i, success=False) for i in range(N)]
    report = gate(new, [row("a", i, success=False) for i in range(N)])
    c = check(report, "a", "duration_p95_s")
    assert report.passed and (c.verdict, c.baseline, c.now, c.n, c.p_value) == ("n/a", None, None, 0, None)


def test_render_of_a_failing_gate_is_a_table_with_n_p_and_the_regressions_listed():
    base = scaled(solved_all(), "b", "timing", "planning_time_s", 1 / 3)
    now = lose(sweep(), "b", lambda k: k == 0)  # b lost 6 runs the baseline solved
    text = gate(now, base).render()
    lines = text.splitlines()
    # b's p95 duration has 19 paired runs (successful in both): not judged
    assert lines[0] == "regression gate: FAILED, 2 of 6 checks regressed (1 not judged: not enough runs)"
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
        "worse/better",
        "p",
        "verdict",
    ]
    cells = {(c[0], c[1]): c for c in ([x.strip() for x in ln.split("|")[1:-1]] for ln in table[2:])}
    assert cells["b", "success_rate"][2:] == [
        "25",
        "100% (25/25)",
        "76% (19/25)",
        "-24 pp",
        ">= 100%",
        "6/0",
        "0.031",
        "REGRESSED",
    ]
    assert cells["b", "planning_time_p95_s"][7:] == ["25/0", "<0.001", "REGRESSED"]
    assert cells["a", "success_rate"][7:] == ["0/0", "-", "ok"]
    assert "judged from 6 paired runs (success) and 20 (a p95) on" in text
    assert "- b: p95 planning time" in text and "Wilcoxon signed-rank on log-ratios p < 0.001" in text
    assert "- b: success rate" in text and "6 lost, 0 gained, exact McNemar p = 0.031" in text
    report = json.loads(json.dumps(gate(now, base).to_json()))
    assert {(c["planner"], c["quantity"]): (c["n"], c["p_value"]) for c in report["checks"]}["b", "success_rate"] == (
        25,
        pytest.approx(0.03125),
    )


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


# ---- two runs of the same commit on a busy machine --------------------------------------------------
# Three configs: the shipped compare-smoke (its 26 runs' real outcomes, tests/data/compare_smoke_rows.json)
# and two small real sweeps with enough runs per planner to be judged, each swept twice. Outcomes and
# durations are each sweep's own; planning time is wall-clock time, so to keep the tests deterministic both
# sides take the first sweep's measured times, each run's multiplied by a seeded factor in [1, BUSY]: the
# load of the shared 2-core machine issue 38 was reported from.
BUSY = 3.0
REAL_CONFIGS: dict[str, dict[str, Any]] = {
    # three closed-form planners on 24 free joint-goal queries: every check judged
    "joint": {
        "name": "gate-joint",
        "seeds": [0],
        "execute": False,
        "planners": ["ruckig.movej", "seed.quintic_movej", "toppra.movel"],
        "scenarios": [
            {"name": "w", "scene": "warehouse.yaml", "random": {"count": 24, "goal": "joint", "straight": "free"}}
        ],
    },
    # the warehouse wall in the way, 12 queries x 2 seeds: ruckig.movej fails all (no duration: n/a), the
    # sampling planner searches, seed.slerp_movel solves 6 (its p95 duration: not enough runs)
    "blocked": {
        "name": "gate-blocked",
        "seeds": [0, 1],
        "execute": False,
        "time_limit_s": 1.0,
        "planners": ["ruckig.movej", {"name": "ompl.rrtconnect", "retimer": "toppra"}, "seed.slerp_movel"],
        "scenarios": [
            {
                "name": "b",
                "scene": "warehouse.yaml",
                "random": {"count": 12, "goal": "position", "straight": "blocked"},
            }
        ],
    },
}
# compare-smoke's planners: their median planning time (s) in a real compare-smoke sweep (2 shared cores)
_SMOKE_TIMES = {
    "ruckig.movej": 0.0026,
    "seed.quintic_movej": 0.0022,
    "toppra.movel": 0.0134,
    "seed.slerp_movel": 0.0085,
    "ompl.rrtconnect": 0.0095,
    "ompl.bitstar": 0.051,
    "nmpc": 0.47,
}


def compare_smoke_rows() -> list[dict[str, Any]]:
    """compare-smoke's 26 runs as its sweep gives them: each run's status, success and (closed-form
    planners) duration from tests/data/compare_smoke_rows.json, a real sweep's (test_ur_models checks it
    against a fresh one); the other durations and the planning times (the planner's typical time x a factor
    per problem) seeded, the same in every call, as a rerun of the same commit gives them."""
    recorded = json.loads((Path(__file__).parent / "data" / "compare_smoke_rows.json").read_text())
    rng = np.random.default_rng(38)
    rows = []
    for key, rec in sorted(recorded.items()):
        planner, case, seed = key.split("|")
        duration = rec.get("duration_s", float(rng.uniform(0.8, 3.0)))
        rows.append(
            {
                "run_id": key,
                "planner": planner,
                "scenario": case.split("#")[0],
                "case": case,
                "seed": int(seed.removeprefix("seed=")),
                "status": rec["status"],
                "success": rec["success"],
                "metrics": {"duration_s": duration if rec["success"] else None},
                "timing": {"planning_time_s": _SMOKE_TIMES[planner] * float(rng.lognormal(0.0, 0.5))},
            }
        )
    return rows


def busy(rows: list[dict[str, Any]], times: list[dict[str, Any]], seed: int) -> list[dict[str, Any]]:
    """`rows` timed as a busy machine would: each run's planning time is its time in `times` (the same
    run ids) multiplied by a factor drawn uniformly from [1, BUSY] (seeded)."""
    rng = np.random.default_rng(seed)
    quiet = {r["run_id"]: r["timing"].get("planning_time_s") for r in times}
    out = copy.deepcopy(rows)
    for r in out:
        t = quiet.get(r["run_id"])
        r["timing"]["planning_time_s"] = None if t is None else t * float(rng.uniform(1.0, BUSY))
    return out


@pytest.fixture(scope="module")
def same_commit(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[list[dict[str, Any]], ...]]:
    """Per config: the rows of two sweeps of the same commit (baseline, rerun), as `twin compare` reads them."""
    out = {"compare-smoke": (compare_smoke_rows(), compare_smoke_rows())}
    for name, cfg in REAL_CONFIGS.items():
        spec = compare_spec_from_dict(cfg)
        d = tmp_path_factory.mktemp(name)
        first = run_comparison(spec, out_dir=d / "first", workers=0, plots=False)
        second = run_comparison(spec, out_dir=d / "second", workers=0, plots=False)
        out[name] = (load_baseline(first.results_path), read_results(second.results_path))
    return out


def busy_pair(
    same_commit: dict[str, tuple[list[dict[str, Any]], ...]], config: str, seed: int = 0
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(rerun, baseline) of `config`, both timed on a busy machine (independent draws)."""
    first, second = same_commit[config]
    return busy(second, first, 2 * seed + 1), busy(first, first, 2 * seed)


# checks per config with too few paired runs to judge: compare-smoke has 4 runs per planner (nmpc 2)
NOT_JUDGED = {"compare-smoke": 21, "joint": 0, "blocked": 1}


@pytest.mark.parametrize("config", ["compare-smoke", "joint", "blocked"])
def test_two_runs_of_the_same_commit_on_a_busy_machine_pass(same_commit, config: str):
    first, second = same_commit[config]
    assert {r["run_id"] for r in first} == {r["run_id"] for r in second}
    for seed in range(5):
        now, base = busy_pair(same_commit, config, seed)
        report = gate(now, base)
        assert report.passed, report.render()
        assert report.matched == len(first) and len(report.not_judged) == NOT_JUDGED[config]
        assert report.render().startswith(f"regression gate: passed, none of {len(report.checks)} checks regressed")


def test_a_p95_of_4_runs_is_not_enough_runs_and_never_a_regression(same_commit):
    """The issue's report: compare-smoke rerun on a busy machine. A p95 of 4 runs is (mostly) their maximum;
    one run a busy neighbour slowed 5x moves it beyond its limit, which the gate used to call a regression."""
    now, base = busy_pair(same_commit, "compare-smoke")
    spiked = copy.deepcopy(now)
    [slow] = [r for r in spiked if r["run_id"] == "toppra.movel|robocup#0|seed=0"]
    slow["timing"]["planning_time_s"] *= 5
    report = gate(spiked, base)
    c = check(report, "toppra.movel", "planning_time_p95_s")
    assert c.beyond and c.n == 4 < MIN_P95_RUNS  # beyond the limit: the verdict before issue 38
    assert c.verdict == "not_enough_runs" and c.verdict_text == "not enough runs (n = 4; need >= 20)"
    assert report.passed
    # even a doctored 3x slowdown of every run: the p95 of 4 runs is not judged
    report = gate(scaled(now, "ompl.rrtconnect", "timing", "planning_time_s", 3.0), base)
    assert report.passed and check(report, "ompl.rrtconnect", "planning_time_p95_s").beyond
    text = report.render()
    assert text.startswith("regression gate: passed, none of 21 checks regressed (21 not judged: not enough runs)")
    table = [ln for ln in text.splitlines() if ln.startswith("| ")][1:]
    assert len(table) == 21 and all("not enough runs (n = " in ln for ln in table)
    # p95s: of 4 runs; nmpc's 2 and the durations of the 2 or 3 runs a closed-form planner solved
    assert sum("p95" in ln and "(n = 4; need >= 20)" in ln for ln in table) == 8
    assert sum("p95" in ln and "(n = 2; need >= 20)" in ln for ln in table) == 4
    assert sum("p95" in ln and "(n = 3; need >= 20)" in ln for ln in table) == 2
    assert sum("success_rate" in ln and "(n = 4; need >= 6)" in ln for ln in table) == 6


@pytest.mark.parametrize(("config", "planner"), [("joint", "toppra.movel"), ("blocked", "ompl.rrtconnect")])
def test_a_doctored_2x_slowdown_fails_on_a_busy_machine(same_commit, config: str, planner: str):
    """Trajectories twice as long (a retimer gone slow) fail on p95 duration, whatever the load noise."""
    for seed in range(5):
        now, base = busy_pair(same_commit, config, seed)
        report = gate(scaled(now, planner, "metrics", "duration_s", 2.0), base)
        assert regressed(report) == {(planner, "duration_p95_s")}, report.render()
        c = check(report, planner, "duration_p95_s")
        assert c.n == 24 and (c.worse, c.better) == (24, 0) and c.p_value < 1e-3
        assert f"- {planner}: p95 duration" in report.render()


def test_a_doctored_2x_planning_slowdown_fails_where_the_tolerance_says_it_matters():
    """Planning time may double by default (`Tolerance`: a loaded CI machine vs the baseline's), so a 2x
    slowdown is significant but within it; at planning_time=0.5 it fails."""
    slow = scaled(sweep(), "b", "timing", "planning_time_s", 2.0)
    c = check(gate(slow, sweep()), "b", "planning_time_p95_s")
    assert c.significant and not c.beyond and c.verdict_text == "ok: within tolerance"
    report = gate(slow, sweep(), Tolerance(planning_time=0.5))
    assert regressed(report) == {("b", "planning_time_p95_s")} and not report.passed


def test_a_lost_success_rate_fails_on_a_busy_machine(same_commit):
    now, base = busy_pair(same_commit, "blocked")
    # seed.slerp_movel solved 6 of the 24 queries; it now solves none: 6 of 6 differing runs lost
    report = gate(lose(now, "seed.slerp_movel", lambda k: True), base)
    c = check(report, "seed.slerp_movel", "success_rate")
    assert regressed(report) == {("seed.slerp_movel", "success_rate")}
    assert (c.n, c.worse, c.better, c.baseline, c.now) == (24, 6, 0, 0.25, 0.0)
    assert c.p_value == pytest.approx(2 / 2**6)
    # the sampling planner loses every other run
    report = gate(lose(now, "ompl.rrtconnect", lambda k: k % 2 == 0), base)
    assert regressed(report) == {("ompl.rrtconnect", "success_rate")}
    assert check(report, "ompl.rrtconnect", "success_rate").p_value < 1e-3


def test_a_total_loss_of_success_on_compare_smoke_is_not_enough_runs(same_commit):
    """4 of 4 runs lost: the exact test's p is 0.125 (two-sided), so 4 runs cannot tell it from chance; the
    table says so and the gate does not fail (MIN_SUCCESS_RUNS: give the sweep more seeds or queries)."""
    now, base = busy_pair(same_commit, "compare-smoke")
    report = gate(lose(now, "ompl.rrtconnect", lambda k: True), base)
    c = check(report, "ompl.rrtconnect", "success_rate")
    assert (c.baseline, c.now, c.worse, c.beyond) == (1.0, 0.0, 4, True)
    assert c.verdict_text == "not enough runs (n = 4; need >= 6)" and report.passed


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
    assert "none of its 50 run ids is among this sweep's 2" in err
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
