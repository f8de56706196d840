"""One interval method per kind of quantity, everywhere a comparison reports it (synthetic rows, no
PyBullet): a success rate gets its Wilson score interval in the terminal table, summary.md, summary.csv,
the sweep tables and sweep.csv, so 2/2 is never [100, 100]; a median gets n beside it and a bootstrap
interval; every report says which method is which."""

from __future__ import annotations

import csv
import re
from pathlib import Path
from typing import Any

import pytest

from twin.compare.report import summarize, summary_table, sweep_tables, write_summary
from twin.compare.stats import INTERVALS, wilson_ci
from twin.compare.summary import Summary


def run(planner: str, seed: int, *, success: bool, level: int = 1, duration_s: float = 1.0) -> dict[str, Any]:
    """A query row of scenario 's' at level `level` of a swept key 'k' (a single-level sweep: every run is
    on the nominal point, so the sweep point and the scenario row count the same runs)."""
    return {
        "run_id": f"{planner}|s#{seed}|{level}",
        "planner": planner,
        "scenario": "s",
        "case": f"s@k={level}",
        "kind": "query",
        "seed": seed,
        "status": "success" if success else "no_solution",
        "success": success,
        "sweep": {"k": level},
        "sweep_axes": ["k"],
        "metrics": {"duration_s": duration_s + 0.1 * seed if success else None},
        "timing": {"planning_time_s": 0.2 + 0.01 * seed},
    }


def pct(ci: tuple[float, float] | None) -> str:
    assert ci is not None
    return f"[{100 * ci[0]:.0f}, {100 * ci[1]:.0f}]"


def terminal(summary: Summary) -> str:
    from rich.console import Console

    console = Console(width=250, record=True)
    console.print(summary_table(summary))
    for t in sweep_tables(summary):
        console.print(t)
    return console.export_text()


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture
def summary() -> Summary:
    """'sure' solved 2 of 2 runs; 'shaky' solved 3 of 4."""
    rows = [run("sure", i, success=True) for i in range(2)]
    rows += [run("shaky", i, success=i != 1) for i in range(4)]
    return summarize(rows, planners=["sure", "shaky"])


def test_two_of_two_is_not_certainty_anywhere(summary: Summary, tmp_path: Path) -> None:
    sure = summary.row("sure")
    assert sure is not None and sure.success_ci == wilson_ci(2, 2)
    lo, hi = sure.success_ci  # type: ignore[misc]
    assert hi == 1.0 and lo == pytest.approx(0.3424, abs=1e-4)  # Wilson: 2 / (2 + 1.96^2)
    cell = "100% (2/2) [34, 100]"

    text = terminal(summary)
    assert cell in text and "[100, 100]" not in text

    write_summary(summary, tmp_path)
    md = (tmp_path / "summary.md").read_text()
    assert f"| sure | 2 | {cell} | 0 |" in md  # the success table
    assert "[100, 100]" not in md  # nor per scenario, nor per sweep level
    line = next(r for r in read_csv(tmp_path / "summary.csv") if (r["planner"], r["scenario"]) == ("sure", "all"))
    assert float(line["success_ci_low"]) == pytest.approx(lo, abs=1e-5) and float(line["success_ci_high"]) == 1.0
    swept = next(r for r in read_csv(tmp_path / "sweep.csv") if r["planner"] == "sure")
    assert float(swept["success_ci_low"]) == pytest.approx(lo, abs=1e-5)


def test_the_main_and_the_sweep_tables_give_one_interval_for_the_same_counts(summary: Summary, tmp_path: Path) -> None:
    shaky = summary.row("shaky")
    (point,) = [p for p in summary.sweeps if p.planner == "shaky"]
    assert shaky is not None and (shaky.successes, shaky.runs) == (point.successes, point.runs) == (3, 4)
    assert shaky.success_ci == point.success_ci == wilson_ci(3, 4)
    cell = f"75% (3/4) {pct(wilson_ci(3, 4))}"  # [30, 95]

    text = terminal(summary)
    assert text.count(cell) == 2  # the planner table and the sweep table

    write_summary(summary, tmp_path)
    md = (tmp_path / "summary.md").read_text()
    assert f"| shaky | 4 | {cell} | 0 |" in md  # success
    assert f"| shaky | {cell} |" in md  # success by scenario
    assert f"| shaky | {cell}; " in md  # the sweep level
    main = next(r for r in read_csv(tmp_path / "summary.csv") if (r["planner"], r["scenario"]) == ("shaky", "all"))
    swept = next(r for r in read_csv(tmp_path / "sweep.csv") if r["planner"] == "shaky")
    assert (main["success_ci_low"], main["success_ci_high"]) == (swept["success_ci_low"], swept["success_ci_high"])


def test_n_stands_beside_every_median(summary: Summary, tmp_path: Path) -> None:
    write_summary(summary, tmp_path)
    md = (tmp_path / "summary.md").read_text()
    metrics = md.split("## Metrics")[1].split("\n## ")[0]
    row = next(line for line in metrics.splitlines() if line.startswith("| duration_s |"))
    sure, shaky = row.split(" | ")[2:4]
    # the median, then its n, then its bootstrap interval, then the p95
    assert re.fullmatch(r"1\.05 \(n=2\) \[1, 1\.1\] / 1\.095", sure), sure
    assert re.fullmatch(r"1\.2 \(n=3\) \[1, 1\.3\] / 1\.29", shaky.rstrip(" |")), shaky
    swept = md.split("### s: k")[1]
    assert "; 1.2 s (n=3) [1, 1.3] |" in swept  # the sweep level's median duration

    text = terminal(summary)
    lines = text.splitlines()
    for median, n in (("1.05 (1.095)", "n=2"), ("1.2 (1.29)", "n=3")):  # duration_s in the planner table
        i = next(i for i, line in enumerate(lines) if median in line)
        end = lines[i].index(median) + len(median)
        assert lines[i + 1][end - len(n) : end] == n  # right under it, in the same cell
    assert "1.2 s (n=3) [1, 1.3]" in text  # the sweep table

    line = next(r for r in read_csv(tmp_path / "summary.csv") if (r["planner"], r["scenario"]) == ("shaky", "all"))
    assert (line["duration_s_n"], line["planning_time_s_n"], line["solves_n"]) == ("3", "4", "0")
    swept_csv = next(r for r in read_csv(tmp_path / "sweep.csv") if r["planner"] == "shaky")
    assert (swept_csv["time_metric"], swept_csv["time_n"]) == ("duration_s", "3")


def test_a_single_value_gets_n_and_no_interval(tmp_path: Path) -> None:
    summary = summarize([run("once", 0, success=True)])
    write_summary(summary, tmp_path)
    md = (tmp_path / "summary.md").read_text()
    assert "| duration_s | s | 1 (n=1) / 1 |" in md  # no [1, 1]: one run has no spread to resample
    line = read_csv(tmp_path / "summary.csv")[0]
    assert (line["duration_s_median_ci_low"], line["duration_s_n"]) == ("", "1")
    assert f"100% (1/1) {pct(wilson_ci(1, 1))}" in md  # [21, 100]


def test_every_report_names_its_interval_methods(summary: Summary, tmp_path: Path) -> None:
    assert "Wilson score" in INTERVALS and "percentile bootstrap" in INTERVALS
    write_summary(summary, tmp_path)
    md = (tmp_path / "summary.md").read_text()
    assert md.splitlines()[2] == INTERVALS  # under the title
    flat = " ".join(terminal(summary).split())
    assert flat.count(" ".join(INTERVALS.split())) == 2  # the caption of the planner table and the sweep table


def test_the_box_plots_show_n_beside_each_median(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib", reason="plots need matplotlib (the `twin[plots]` extra)")
    import matplotlib.pyplot as plt

    from twin.compare.plots import comparison_figures

    rows = [run("sure", i, success=True) for i in range(2)] + [run("shaky", i, success=i != 1) for i in range(4)]
    figs = comparison_figures(rows, planners=["sure", "shaky"])
    try:
        ticks = [t.get_text() for t in figs["duration"].axes[0].get_yticklabels()]
        assert ticks == ["sure  100% ok  n=2", "shaky  75% ok  n=3"]  # most successful first, each with its n
        assert "Wilson" in figs["success"].axes[0].get_xlabel()
    finally:
        for fig in figs.values():
            plt.close(fig)
