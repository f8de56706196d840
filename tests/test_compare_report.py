"""The comparison report a person reads: the success heatmap says what the summary says (and marks the pairs
that did not run apart from a 0 %), "who wins on what" names the leader and tests it against the next
planner on the same problems, summary.html carries the text, the plots and the replay commands, and no
plot file is written without values."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.test_compare_stats import row
from twin.compare.report import ALL, summarize, write_summary
from twin.compare.stats import MIN_DISCORDANT
from twin.compare.verdicts import verdicts


def _rows() -> list[dict[str, Any]]:
    """'fast' solves 12/12 on 'wall' quickly; 'slow' 6/12 slowly; 'pose-only' runs only on 'shelf'."""
    rows = []
    for i in range(12):
        rows.append(row("fast", i, planning_time_s=0.01 + 0.001 * i))
        rows.append(row("slow", i, success=i % 2 == 0, planning_time_s=0.5 + 0.01 * i, duration_s=2.0))
    for i in range(3):
        rows.append(row("fast", i, scenario="shelf"))
        rows.append(row("pose-only", i, scenario="shelf", success=i != 0))
    return rows


def _cell_texts(ax: Any) -> dict[tuple[int, int], str]:
    return {(round(t.get_position()[1]), round(t.get_position()[0])): t.get_text() for t in ax.texts}


def test_the_heatmap_cells_are_the_summary_rates_and_skipped_pairs_are_marked() -> None:
    pytest.importorskip("matplotlib", reason="plots need matplotlib (the `twin[plots]` extra)")
    import matplotlib.pyplot as plt

    from twin.compare.plots import comparison_figures

    planners = ["slow", "fast", "pose-only"]
    rows = _rows()
    summary = summarize(rows, planners=planners, skipped_pairs={("pose-only", "wall"): 12, ("slow", "shelf"): 3})
    figs = comparison_figures(rows, planners=planners, summary=summary)
    try:
        ax = figs["success_heatmap"].axes[0]
        ylabels = [t.get_text() for t in ax.get_yticklabels()]
        xlabels = [t.get_text() for t in ax.get_xticklabels()]
        assert xlabels == ["wall", "shelf", "all scenarios"]
        assert ylabels == ["fast", "pose-only", "slow"]  # best overall success first
        grid = np.ma.getdata(ax.images[0].get_array())
        texts = _cell_texts(ax)
        for i, planner in enumerate(ylabels):
            for j, scenario in enumerate(["wall", "shelf", ALL]):
                r = summary.row(planner, scenario)
                if r is None:  # no runs here: the two skipped pairs, hatched and named, no colour
                    assert (planner, scenario) in summary.skipped_pairs
                    assert texts[(i, j)] == "skipped" and np.isnan(grid[i, j])
                    continue
                assert grid[i, j] == pytest.approx(r.success_rate)  # the colour is the summary's rate
                assert texts[(i, j)] == f"{100 * r.success_rate:.0f}%\n{r.successes}/{r.runs}"  # type: ignore[operator]
        assert texts[(2, 0)] == "50%\n6/12" and texts[(0, 2)] == "100%\n15/15"
        hatched = [p for p in ax.patches if p.get_hatch()]
        assert len(hatched) == 2
        # the per-scenario bars: a skipped pair is drawn apart, not as a 0 % bar
        wall, shelf = figs["success"].axes
        assert [t.get_text() for t in wall.get_yticklabels()] == ["fast", "slow", "pose-only"]
        assert "not run (skipped)" in [t.get_text() for t in wall.texts]
        assert [t.get_text() for t in shelf.get_yticklabels()] == ["fast", "pose-only", "slow"]
    finally:
        for fig in figs.values():
            plt.close(fig)


def test_who_wins_names_the_leader_and_tests_it_on_the_same_problems() -> None:
    summary = summarize(_rows(), planners=["slow", "fast", "pose-only"])
    found = {(v.scenario, v.metric): v for v in summary.verdicts}
    assert set(found) == {
        ("wall", "success"),
        ("wall", "planning_time_s"),
        ("wall", "duration_s"),
        ("shelf", "success"),
        ("shelf", "planning_time_s"),
        ("shelf", "duration_s"),
        (ALL, "success"),
    }
    success = found[("wall", "success")]
    assert success.leaders == ("fast",) and success.runner_up == "slow"
    assert success.test is not None and (success.test.wins, success.test.losses) == (6, 0)
    assert success.significant  # 6 of 6 discordant problems one way: sign test p = 2/64 < 0.05
    assert "`fast` leads with 100% (12/12); next `slow`: 50% (6/12)" in success.text and "a real lead" in success.text
    timing = found[("wall", "planning_time_s")]  # only 'fast' has the top success rate: no one to test it against
    assert timing.leaders == ("fast",) and timing.runner_up is None and timing.test is None
    assert "no other planner has its success rate" in timing.text
    shelf = found[("shelf", "success")]
    assert shelf.leaders == ("fast",) and shelf.test is not None and shelf.test.n == 3
    assert not shelf.significant and f"fewer than {MIN_DISCORDANT}" in shelf.text  # 1 differing problem
    # the same verdicts from the public function, and in summary.md under its heading
    assert verdicts(summary, _rows()) == summary.verdicts


def test_summary_md_and_html_say_who_wins(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib", reason="plots need matplotlib (the `twin[plots]` extra)")
    from twin.compare.html_report import write_html
    from twin.compare.plots import write_plots

    rows = _rows()
    rows[1]["run_id"] = "slow|wall#0|seed=0|abc"  # a failed row's id, as the runner writes them
    rows[3]["run_id"], rows[3]["success"] = "slow|wall#1|seed=0|def", False
    summary = summarize(rows, planners=["slow", "fast", "pose-only"], skipped_pairs={("pose-only", "wall"): 12})
    write_summary(summary, tmp_path)
    md = (tmp_path / "summary.md").read_text()
    section = md.split("## Who wins on what")[1].split("\n## ")[0]
    assert "### wall" in section and "### all scenarios" in section
    assert "- **success**: `fast` leads with 100% (12/12)" in section
    plots = write_plots(rows, tmp_path, planners=["slow", "fast", "pose-only"], summary=summary)
    page = write_html(summary, tmp_path, plots=plots, title="demo").read_text()
    assert page.startswith("<!DOCTYPE html>") and "<title>demo</title>" in page
    assert page.index("Who wins on what") < page.index('id="success_heatmap"') < page.index("<h2>Success</h2>")
    assert page.count("data:image/png;base64,") == len(plots)  # embedded: the page travels alone
    assert "<table>" in page and "twin replay results.jsonl" in page
    assert not re.search(r"<script", page)


def test_task_rows_show_their_planning_time_and_no_plot_is_empty(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib", reason="plots need matplotlib (the `twin[plots]` extra)")
    from twin.compare.plots import write_plots

    rows = []
    for i in range(4):
        for planner, t in (("a", 0.02), ("b", 0.2)):
            r = row(planner, i, scenario="sorting", planning_time_s=None, duration_s=None)
            r["kind"] = "task"
            r["timing"]["task_planning_time_s"] = t * (1 + 0.1 * i)
            r["metrics"]["cycle_time_s"] = 9.0 + i
            rows.append(r)
    summary = summarize(rows, planners=["a", "b"])
    names = [p.name for p in write_plots(rows, tmp_path, planners=["a", "b"], summary=summary)]
    # a task-only comparison: its planning time per motion and its cycle time; no duration or clearance file
    assert names == ["success_heatmap.png", "success.png", "tradeoff.png", "planning_time.png", "cycle_time.png"]
    found = {(v.scenario, v.metric): v for v in summary.verdicts}
    assert found[("sorting", "task_planning_time_s")].leaders == ("a",)
    assert ("sorting", "cycle_time_s") in found


def test_a_time_lead_is_among_the_most_successful_and_names_a_faster_planner_that_fails() -> None:
    rows = []
    for i in range(8):
        rows.append(row("quick", i, success=False, planning_time_s=0.001))  # fails at once, every time
        rows.append(row("solid", i, planning_time_s=0.02 + 0.001 * i))
        rows.append(row("solid2", i, planning_time_s=0.05 + 0.001 * i))
    summary = summarize(rows, planners=["quick", "solid", "solid2"])
    (v,) = [v for v in summary.verdicts if v.metric == "planning_time_s"]
    assert v.leaders == ("solid",) and v.runner_up == "solid2"
    assert v.test is not None and (v.test.wins, v.test.n) == (8, 8) and v.significant  # Wilcoxon, 8 of 8 lower
    assert "among the 2 planners at the top success rate, 100%" in v.text
    assert "fastest of all: `quick` 1 ms (n=8) at 0% (0/8) success" in v.text


def test_a_time_lead_over_the_reference_says_when_the_planner_solves_less(tmp_path: Path) -> None:
    """Against the reference, a planner that gives up quickly is 'better on planning time': the line says what
    it fails (the cage of MotionBenchMaker: bitstar stops at its work budget on 95 of 100 problems)."""
    rows = []
    for i in range(10):
        rows.append(row("ref", i, planning_time_s=2.0 + 0.01 * i))
        rows.append(row("quitter", i, success=i < 2, planning_time_s=0.3))  # solves 2, fails 8 fast
        rows.append(row("faster", i, planning_time_s=1.0 + 0.01 * i))  # solves all, faster: a plain lead
    write_summary(summarize(rows, planners=["ref", "quitter", "faster"]), tmp_path)
    section = (tmp_path / "summary.md").read_text().split("Against the reference `ref`")[1].split("\n## ")[0]
    (line,) = [ln for ln in section.splitlines() if ln.startswith("- better on planning_time_s, all scenarios")]
    assert "`faster` (p = 0.002)" in line
    assert "`quitter` (p = 0.002; but it fails 8 problems the reference solves, solving 0 it fails)" in line
