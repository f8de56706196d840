"""The statistics of a comparison summary on synthetic rows (no PyBullet): bootstrap intervals of medians,
Wilson intervals of success rates, failure counts per reason, and the paired comparison against a
reference planner, in the summary files and the plots (tests/test_compare_intervals.py: the same interval
everywhere)."""

from __future__ import annotations

import csv
import re
from typing import Any

import numpy as np
import pytest

from twin.compare.metrics import METRIC_KEYS, TIMING_KEYS
from twin.compare.report import summarize, summary_table, write_summary
from twin.compare.stats import MIN_DISCORDANT, bootstrap_ci, is_tie, wilson_ci
from twin.compare.summary import ALL, Stat
from twin.errors import ConfigError


def row(
    planner: str,
    case: int,
    *,
    scenario: str = "wall",
    seed: int = 0,
    success: bool = True,
    planning_time_s: float | None = 0.1,
    duration_s: float | None = 1.0,
    failure: Any = "absent",
    status: str | None = None,
) -> dict[str, Any]:
    """A result row shaped like the worker's; `failure="absent"` leaves the key out (rows written before it)."""
    metrics = dict.fromkeys(METRIC_KEYS)
    timing = dict.fromkeys(TIMING_KEYS)
    metrics["duration_s"] = duration_s if success else None
    timing["planning_time_s"] = planning_time_s
    r: dict[str, Any] = {
        "run_id": f"{planner}/{scenario}/{case}/{seed}",
        "planner": planner,
        "scenario": scenario,
        "case": f"{scenario}#{case}",
        "kind": "query",
        "seed": seed,
        "status": status or ("success" if success else "no_solution"),
        "reason": "",
        "success": success,
        "metrics": metrics,
        "timing": timing,
        "clearance_pair": None,
        "straight_free": None,
    }
    if failure != "absent":
        r["failure"] = failure
    return r


def spread_rows(planner: str = "a", n: int = 200, seed: int = 1) -> list[dict[str, Any]]:
    times = np.random.default_rng(seed).normal(10.0, 1.0, n)
    return [row(planner, i, planning_time_s=float(t)) for i, t in enumerate(times)]


def paired_of(summary: Any, planner: str, metric: str, scenario: str = ALL) -> Any:
    found = [c for c in summary.paired if (c.planner, c.metric, c.scenario) == (planner, metric, scenario)]
    assert len(found) == 1, summary.paired
    return found[0]


# ---- bootstrap intervals ---------------------------------------------------------------------------------
def test_the_median_interval_contains_the_sample_median_and_is_deterministic():
    rows = spread_rows()
    st = summarize(rows).overall[0].stats["planning_time_s"]
    assert st.n == 200 and st.ci is not None
    assert st.ci_low < st.median < st.ci_high
    # 200 draws of N(10, 1): the median's standard error is ~1.25/sqrt(200) = 0.089, so the 95 % interval
    # is ~0.35 wide and holds the true median
    assert 0.15 < st.ci_high - st.ci_low < 0.7
    assert st.ci_low < 10.0 < st.ci_high
    again = summarize([dict(r) for r in rows]).overall[0].stats["planning_time_s"]
    assert again == st  # the same rows give the same intervals, call after call
    values = [r["timing"]["planning_time_s"] for r in rows]
    assert bootstrap_ci(values, seed=7) == bootstrap_ci(values, seed=7)
    assert bootstrap_ci(values, seed=7) != bootstrap_ci(values, seed=8)  # the seed is what fixes it


def test_no_median_interval_below_two_values():
    assert bootstrap_ci([], seed=0) is None
    assert bootstrap_ci([2.5], seed=0) is None  # nothing to resample: [2.5, 2.5] would claim certainty
    assert bootstrap_ci([3.0, 3.0, 3.0], seed=0) == (3.0, 3.0)
    assert Stat.of([]).ci is None and Stat.of([4.0]).ci is None and Stat.of([4.0]).n == 1
    summary = summarize([row("a", 0, success=False, planning_time_s=0.2)])
    r = summary.overall[0]
    assert r.stats["duration_s"].n == 0 and r.stats["duration_s"].ci is None  # no trajectory: no interval
    assert r.stats["planning_time_s"].median == 0.2 and r.stats["planning_time_s"].ci is None
    assert r.success_ci == pytest.approx((0.0, wilson_ci(0, 1)[1]))  # type: ignore[index]
    assert r.success_ci[1] > 0.7  # type: ignore[index]  # one failure does not prove it always fails


def test_the_success_interval_is_wilsons_and_brackets_the_rate():
    rows = [row("a", i, success=i < 10) for i in range(12)]
    r = summarize(rows).overall[0]
    assert r.successes == 10 and r.success_ci is not None
    lo, hi = r.success_ci
    assert 0.5 < lo < 10 / 12 < hi < 1.0
    assert r.success_ci == wilson_ci(10, 12)
    # 12/12 is not certainty: Wilson's lower bound is 1 - 3.84 / 15.84 = 75.8 %
    lo, hi = summarize([row("a", i) for i in range(12)]).overall[0].success_ci  # type: ignore[misc]
    assert hi == 1.0 and lo == pytest.approx(12 / (12 + 1.959964**2), abs=1e-6)


def test_every_scenario_row_has_its_own_interval():
    rows = spread_rows(n=60)
    for i, r in enumerate(rows):
        r["scenario"] = "shelf" if i % 2 else "wall"
    summary = summarize(rows)
    (wall,) = [r for r in summary.by_scenario if r.scenario == "wall"]
    values = sorted(r["timing"]["planning_time_s"] for r in rows if r["scenario"] == "wall")
    st = wall.stats["planning_time_s"]
    assert st.n == 30 and st.median == pytest.approx(float(np.median(values)))
    assert values[0] <= st.ci_low < st.median < st.ci_high <= values[-1]


# ---- paired comparison -----------------------------------------------------------------------------------
def test_a_planner_faster_on_every_problem_wins_them_all():
    times = np.random.default_rng(3).uniform(0.05, 2.0, 20)
    rows = [row("ref", i, planning_time_s=float(t)) for i, t in enumerate(times)]
    rows += [row("fast", i, planning_time_s=float(0.8 * t)) for i, t in enumerate(times)]
    summary = summarize(rows, planners=["ref", "fast"])
    assert summary.reference == "ref"  # the first planner unless told
    c = paired_of(summary, "fast", "planning_time_s")
    assert (c.reference, c.n, c.wins, c.ties, c.losses) == ("ref", 20, 20, 0, 0)
    assert c.p_value is not None and c.p_value < 0.001
    assert c.p_value == pytest.approx(2 / 2**20)  # exact two-sided signed-rank p: all 20 ranks on one side
    assert c.median_diff == pytest.approx(float(np.median(-0.2 * times)))
    assert c.median_diff < 0
    assert paired_of(summary, "fast", "planning_time_s", "wall").wins == 20  # the only scenario
    d = paired_of(summary, "fast", "duration_s")  # equal durations: ties
    assert (d.wins, d.ties, d.losses, d.median_diff, d.p_value) == (0, 20, 0, 0.0, None)
    assert all(c.planner != "ref" for c in summary.paired)  # the reference is not compared with itself

    other = summarize(rows, planners=["ref", "fast"], reference="fast")
    c = paired_of(other, "ref", "planning_time_s")
    assert (c.wins, c.ties, c.losses) == (0, 0, 20) and c.p_value < 0.001 and c.median_diff > 0


def test_identical_values_are_all_ties_and_give_no_p():
    times = np.random.default_rng(4).uniform(0.05, 2.0, 20)
    rows = [
        row(p, i, planning_time_s=float(t), duration_s=float(3 * t)) for p in ("a", "b") for i, t in enumerate(times)
    ]
    summary = summarize(rows)
    for metric in ("planning_time_s", "duration_s", "success"):
        c = paired_of(summary, "b", metric)
        assert (c.n, c.wins, c.ties, c.losses, c.p_value) == (20, 0, 20, 0, None), c


def test_the_tie_rule():
    assert is_tie(1.0, 1.0) and is_tie(0.0, 0.0)
    assert is_tie(1.0, 1.0 + 1e-7)  # below a part per million
    assert not is_tie(1.0, 1.001)
    assert is_tie(0.0, 5e-10) and not is_tie(0.0, 1e-8)  # near zero: a nanosecond
    np.testing.assert_array_equal(is_tie(np.array([1.0, 1.0]), np.array([1.0, 1.1])), [True, False])


def test_few_non_tied_pairs_give_no_p():
    rows = [row("ref", i, planning_time_s=1.0) for i in range(20)]
    # faster on MIN_DISCORDANT - 1 problems, the same on the rest
    rows += [row("b", i, planning_time_s=0.5 if i < MIN_DISCORDANT - 1 else 1.0) for i in range(20)]
    c = paired_of(summarize(rows, planners=["ref", "b"]), "b", "planning_time_s")
    assert (c.wins, c.ties, c.losses, c.p_value) == (MIN_DISCORDANT - 1, 21 - MIN_DISCORDANT, 0, None)


def test_runs_pair_only_on_the_same_scenario_case_and_seed():
    rows = [row("ref", i, seed=s) for i in range(4) for s in (0, 1)]
    rows += [row("b", i, seed=0, planning_time_s=0.05) for i in range(3)]  # case #3 not run
    rows += [row("b", 0, seed=7, planning_time_s=0.05)]  # a seed the reference did not run
    rows += [row("b", 0, scenario="shelf", planning_time_s=0.05)]  # nor this scenario
    summary = summarize(rows, planners=["ref", "b"])
    c = paired_of(summary, "b", "planning_time_s")
    assert (c.n, c.wins) == (3, 3)
    assert not [c for c in summary.paired if c.scenario == "shelf"]  # nothing to pair there


def test_paired_success_counts_the_discordant_problems():
    rows = [row("ref", i, success=i >= 8) for i in range(12)]  # fails #0..#7
    rows += [row("b", i, success=i != 11) for i in range(12)]  # fails #11 only
    summary = summarize(rows, planners=["ref", "b"])
    c = paired_of(summary, "b", "success")
    assert (c.n, c.wins, c.ties, c.losses, c.median_diff) == (12, 8, 3, 1, None)
    assert c.p_value == pytest.approx(2 * (1 + 9) / 2**9)  # exact sign test: 8 of 9 discordant pairs
    dur = paired_of(summary, "b", "duration_s")
    assert dur.n == 3  # duration only where both succeeded (#8..#10)


def test_an_unknown_reference_is_a_config_error():
    rows = [row("ompl.rrtconnect", 0), row("ompl.prm", 0)]
    with pytest.raises(ConfigError, match=re.escape("Did you mean 'ompl.rrtconnect'")):
        summarize(rows, reference="ompl.rrtconect")


# ---- failure counts --------------------------------------------------------------------------------------
def failing_rows() -> list[dict[str, Any]]:
    return [
        row("a", 0, failure=None),
        row("a", 1),  # an older row without the key, a success: not counted
        row("a", 2, success=False, failure="no_solution"),
        row("a", 3, success=False, failure="timeout"),
        row("a", 4, success=False, failure="timeout"),
        row("a", 5, success=False, status="error", planning_time_s=None),  # no key, status error: "error"
        row("a", 6, success=False, status="no_solution"),  # no key: derived from its status
        row("b", 0, failure=None),
    ]


def test_failures_are_counted_per_reason_in_the_fixed_order():
    summary = summarize(failing_rows(), planners=["a", "b"])
    a, b = summary.overall
    assert a.failures == {"timeout": 2, "no_solution": 2, "error": 1}
    assert list(a.failures) == ["timeout", "no_solution", "error"]  # FAILURES order
    assert b.failures == {}
    assert a.errors == 1


# ---- files -----------------------------------------------------------------------------------------------
def test_the_summary_files_carry_intervals_failures_and_the_paired_comparison(tmp_path):
    times = np.random.default_rng(5).uniform(0.05, 2.0, 20)
    rows = [row("ref", i, planning_time_s=float(t), success=i < 17) for i, t in enumerate(times)]
    rows += [row("fast", i, planning_time_s=float(0.5 * t), success=i < 17) for i, t in enumerate(times)]
    for r in rows:
        if not r["success"]:
            r["failure"] = "timeout"
    summary = summarize(rows, planners=["ref", "fast"])
    paths = write_summary(summary, tmp_path)
    assert [p.name for p in paths] == ["summary.csv", "summary.md", "paired.csv"]

    with open(tmp_path / "summary.csv", newline="") as f:
        table = list(csv.DictReader(f))
    header = list(table[0])
    assert header[:6] == ["planner", "scenario", "runs", "successes", "success_rate", "errors"]
    assert header[-3:] == ["closest_pair", "common_closest_pair", "straight_free_rate"]  # still last
    for col in ("success_ci_low", "success_ci_high", "planning_time_s_median_ci_low", "duration_s_median_ci_high"):
        assert col in header, col
    ref = next(r for r in table if r["planner"] == "ref" and r["scenario"] == ALL)
    st = summary.overall[0].stats["planning_time_s"]
    assert float(ref["planning_time_s_median_ci_low"]) == st.ci_low
    assert float(ref["planning_time_s_median_ci_high"]) == st.ci_high
    assert float(ref["success_ci_low"]) < float(ref["success_rate"]) == 0.85 < float(ref["success_ci_high"])
    assert ref["failures"] == "timeout=3"
    assert ref["solves_median_ci_low"] == ""  # no value, no interval

    with open(tmp_path / "paired.csv", newline="") as f:
        paired = list(csv.DictReader(f))
    line = next(p for p in paired if (p["planner"], p["scenario"], p["metric"]) == ("fast", ALL, "planning_time_s"))
    assert line["reference"] == "ref"
    assert (line["n"], line["wins"], line["ties"], line["losses"]) == ("20", "20", "0", "0")
    assert float(line["p_value"]) < 0.001 and float(line["median_diff"]) < 0
    succ = next(p for p in paired if (p["planner"], p["scenario"], p["metric"]) == ("fast", ALL, "success"))
    assert (succ["wins"], succ["ties"], succ["losses"], succ["p_value"], succ["median_diff"]) == (
        "0",
        "20",
        "0",
        "",
        "",
    )

    md = (tmp_path / "summary.md").read_text()
    lo, hi = summary.overall[0].success_ci
    assert f"| ref | 20 | 85% (17/20) [{100 * lo:.0f}, {100 * hi:.0f}] | 0 |" in md
    assert "## Failures" in md and "| ref | 3 |" in md
    assert "## Paired against ref" in md
    assert "| fast | all | planning_time_s | 20 | 20/0/0 |" in md and "<0.001 |" in md
    assert "| planning_time_s | s | " in md and " [" in md.split("| planning_time_s | s | ")[1].split("\n")[0]


def test_the_terminal_table_shows_the_success_interval():
    from rich.console import Console

    summary = summarize([row("a", i, success=i < 10) for i in range(12)])
    console = Console(width=200, record=True)
    console.print(summary_table(summary))
    lo, hi = summary.overall[0].success_ci
    assert f"83% (10/12) [{100 * lo:.0f}, {100 * hi:.0f}]" in console.export_text()


# ---- plots -----------------------------------------------------------------------------------------------
def test_plots_show_the_intervals(tmp_path):
    pytest.importorskip("matplotlib", reason="plots need matplotlib (the `twin[plots]` extra)")
    import matplotlib.pyplot as plt
    from matplotlib.container import BarContainer, ErrorbarContainer

    from twin.compare.plots import comparison_figures, write_plots

    rows = spread_rows("a", 40, seed=1) + spread_rows("b", 40, seed=2)
    for i, r in enumerate(rows):
        r["success"] = i % 5 != 0
        r["scenario"] = "shelf" if i % 2 else "wall"
    summary = summarize(rows, planners=["a", "b"])
    figs = comparison_figures(rows, planners=["a", "b"], summary=summary)
    try:
        axes = figs["planning_time"].axes
        assert [ax.get_title() for ax in axes] == ["wall", "shelf"]  # a panel per scenario
        for ax in axes:
            (bars,) = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
            drawn = sorted(tuple(np.round(sorted(seg[:, 0]), 9)) for seg in bars.lines[2][0].get_segments())
            want = []
            for planner in ("a", "b"):
                st = summary.row(planner, ax.get_title()).stats["planning_time_s"]  # type: ignore[union-attr]
                want.append(tuple(np.round([st.ci_low, st.ci_high], 9)))
            assert drawn == sorted(want)  # the report's interval of that scenario
            # best first: the upper box has the lower median
            labels = [t.get_text().split()[0] for t in ax.get_yticklabels()]
            medians = [summary.row(p, ax.get_title()).stats["planning_time_s"].median for p in labels]  # type: ignore[union-attr]
            assert medians == sorted(medians)
            assert all(t.get_text().endswith("n=20") for t in ax.get_yticklabels())
        for ax in figs["success"].axes:
            (bars,) = [c for c in ax.containers if isinstance(c, BarContainer)]
            got = sorted(tuple(np.round(sorted(s[:, 0]), 6)) for s in bars.errorbar.lines[2][0].get_segments())
            want = sorted(
                tuple(np.round([100 * r.success_ci[0], 100 * r.success_ci[1]], 6))
                for r in summary.by_scenario
                if r.scenario == ax.get_title()
            )
            assert got == want
    finally:
        for fig in figs.values():
            plt.close(fig)

    paths = write_plots(rows, tmp_path, planners=["a", "b"])  # summarises itself: the same intervals
    names = [p.name for p in paths]
    assert names == ["success_heatmap.png", "success.png", "tradeoff.png", "planning_time.png", "duration.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in paths)  # no clearance values: no file


def test_the_comparison_names_its_reference_planner(tmp_path) -> None:
    from twin.compare import compare_spec_from_dict, run_comparison

    spec = {
        "planners": ["ruckig.movej", "seed.quintic_movej"],
        "scenarios": [{"name": "free", "scene": "warehouse", "random": {"count": 6, "straight": "free"}}],
        "execute": False,
        "reference": "seed.quintic_movej",
    }
    result = run_comparison(compare_spec_from_dict(spec), out_dir=tmp_path / "o", workers=0, plots=False)
    assert result.summary.reference == "seed.quintic_movej"
    (paired,) = [c for c in result.summary.paired if c.scenario == "all" and c.metric == "duration_s"]
    assert paired.planner == "ruckig.movej" and paired.n == 6  # the same six problems, paired
    with pytest.raises(ConfigError, match="reference 'rrt' is not a planner label"):
        compare_spec_from_dict({**spec, "reference": "rrt"})
