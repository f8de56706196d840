"""Issue 38: a comparison as a paper's table (`twin report RESULTS --latex OUT.tex`, `twin compare --latex`),
summary.md opening with what ran (config, date, commit, machine), and `bench/bench_mbm.py`'s subset of
MotionBenchMaker's suite (`--scenes a,b --problems N`).

The table on synthetic rows (no PyBullet): a booktabs table, a block per scenario, a row per planner, the
success interval the repo's Wilson function gives, names escaped. One small sweep through the command line
shows the pieces joined: summary.md's opening lines, and `twin report` writing what `--latex` wrote.
"""

from __future__ import annotations

import importlib.util
import json
import re
from datetime import datetime, timedelta, timezone
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from tests.cli_runner import ROOT, twin
from tests.test_compare_stats import row
from twin.cli import main
from twin.compare.latex import latex_escape, latex_table, read_result_rows
from twin.compare.report import summarize, write_summary
from twin.compare.stats import wilson_ci
from twin.compare.summary import Provenance
from twin.errors import ConfigError
from twin.problems import ProblemSet
from twin.problems.problem_set import JointGoalSpec, Problem, RobotSpec

# (planner, scenario) -> (successes, runs): counts whose Wilson interval differs from the bootstrap's and the
# normal approximation's (2/2 is [34, 100] here, [100, 100] there)
COUNTS = {
    ("ompl.rrt_connect", "wall_2"): (2, 2),
    ("straight", "wall_2"): (1, 4),
    ("ompl.rrt_connect", "shelf"): (7, 9),
    ("straight", "shelf"): (0, 3),
}
PLANNERS = ["ompl.rrt_connect", "straight"]


def _rows() -> list[dict[str, Any]]:
    out = []
    for (planner, scenario), (ok, n) in COUNTS.items():
        out += [
            row(planner, i, scenario=scenario, success=i < ok, planning_time_s=0.01 * (i + 1), duration_s=1.0 + i)
            for i in range(n)
        ]
    return out


def _body(tex: str) -> list[str]:
    """The lines between \\midrule and \\bottomrule: scenario headers, planner rows and the rules between."""
    lines = tex.splitlines()
    return lines[lines.index(r"\midrule") : lines.index(r"\bottomrule")]


def test_the_table_has_a_block_per_scenario_and_a_row_per_planner() -> None:
    tex = latex_table(summarize(_rows(), planners=PLANNERS))
    for rule in (r"\toprule", r"\midrule", r"\bottomrule", r"\cmidrule(lr){3-4}"):
        assert rule in tex
    assert tex.index(r"\toprule") < tex.index(r"\midrule") < tex.index(r"\bottomrule")
    assert r"\begin{tabular}{lrrlrlrl}" in tex and tex.rstrip().endswith(r"\end{table}")
    body = _body(tex)
    # per scenario, in the rows' order: a rule, its name over all columns, then its planners in config order
    assert body == [
        r"\midrule",
        r"\multicolumn{8}{l}{\textit{wall\_2}} \\",
        *[line for line in body if line.startswith(r"ompl.rrt\_connect & 2 &")],
        *[line for line in body if line.startswith("straight & 4 &")],
        r"\midrule",
        r"\multicolumn{8}{l}{\textit{shelf}} \\",
        *[line for line in body if line.startswith(r"ompl.rrt\_connect & 9 &")],
        *[line for line in body if line.startswith("straight & 3 &")],
    ]
    assert all(line.count("&") == 7 for line in body if not line.startswith("\\"))  # eight cells a row


def test_the_success_interval_is_the_repos_wilson_interval() -> None:
    tex = latex_table(summarize(_rows(), planners=PLANNERS))
    rows = [line for line in _body(tex) if not line.startswith("\\")]
    for line, ((planner, _), (ok, n)) in zip(rows, COUNTS.items(), strict=True):
        cells = [c.strip() for c in line.removesuffix(r"\\").split("&")]
        lo, hi = wilson_ci(ok, n) or (0.0, 0.0)
        assert cells[:4] == [latex_escape(planner), str(n), f"{100 * ok / n:.0f}", f"[{100 * lo:.0f}, {100 * hi:.0f}]"]
    assert r"ompl.rrt\_connect & 2 & 100 & [34, 100] &" in tex  # 2/2 is not certainty
    assert r"straight & 3 & 0 & [0, 56] & 0.02 & [0.01, 0.03] & -- & -- \\" in tex  # no success: no duration


def test_names_and_captions_are_escaped() -> None:
    assert latex_escape("a_b & 50% #1 {x} $y ~^\\") == (
        r"a\_b \& 50\% \#1 \{x\} \$y \textasciitilde{}\textasciicircum{}\textbackslash{}"
    )
    rows = [row("rrt_star", 0, scenario="bin_picking#1")]
    tex = latex_table(summarize(rows), label="tab:x")
    assert r"\textit{bin\_picking\#1}" in tex and "\nrrt\\_star & 1 & 100 &" in tex
    assert r"\label{tab:x}" in tex and "rrt_star" not in tex
    caption = next(line for line in tex.splitlines() if line.startswith(r"\caption{"))
    assert "Wilson" in caption and "bootstrap" in caption and re.search(r"(?<!\\)%", caption) is None


def test_a_results_file_is_read_back_in_its_configs_planner_order(tmp_path: Path) -> None:
    rows = _rows()
    (tmp_path / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    spec = {"spec": {"planners": [{"name": "straight"}, {"name": "rrt", "label": "ompl.rrt_connect"}]}}
    (tmp_path / "compare.json").write_text(json.dumps(spec))
    read, order = read_result_rows(tmp_path)
    assert read == rows and order == ["straight", "ompl.rrt_connect"]
    assert main(["report", str(tmp_path), "--latex", str(tmp_path / "t.tex")]) == 0
    body = [line for line in _body((tmp_path / "t.tex").read_text()) if not line.startswith("\\")]
    assert [line.split(" & ")[0] for line in body] == ["straight", r"ompl.rrt\_connect"] * 2


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        (None, "no results file at"),
        ("", "holds no result rows"),
        ('{"format": "twin-problem-set"}\n', "is not a results file"),
        ("planner,scenario\nrrt,wall\n", "is not a results file"),
    ],
)
def test_bad_results_are_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str | None, needle: str
) -> None:
    path = tmp_path / "results.jsonl"
    if content is not None:
        path.write_text(content)
    assert main(["report", str(path), "--latex", str(tmp_path / "t.tex")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("twin report: error: ") and needle in err[0], err
    assert not (tmp_path / "t.tex").exists()
    with pytest.raises(ConfigError):
        read_result_rows(path)


def test_a_missing_results_path_exits_2_in_one_line_from_the_shell(tmp_path: Path) -> None:
    r = twin("report", str(tmp_path / "nowhere"), "--latex", str(tmp_path / "t.tex"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    assert "no results file at" in r.stderr


ENVIRONMENT: dict[str, Any] = {
    "twin": {"version": "0.1.0", "commit": "c0ffee" * 6 + "beef", "dirty": True},
    "cpu": {"model": "Test CPU 3000", "cores": 8, "usable_cores": 4},
    "hostname": "lab-pc",
}


def test_summary_md_opens_with_what_ran(tmp_path: Path) -> None:
    when = datetime(2025, 3, 4, 5, 6, 7, tzinfo=timezone(timedelta(hours=1)))
    about = Provenance("smoke", "configs/compare-smoke.yaml", when, ENVIRONMENT)
    write_summary(summarize(_rows(), provenance=about), tmp_path)
    lines = (tmp_path / "summary.md").read_text().splitlines()
    assert lines[:7] == [
        "# Planner comparison",
        "",
        "- config: `smoke` (`configs/compare-smoke.yaml`)",
        "- date: 2025-03-04 05:06:07+01:00",
        f"- commit: `{ENVIRONMENT['twin']['commit']}` with uncommitted changes, twin 0.1.0",
        "- machine: Test CPU 3000, 8 cores (4 usable), host `lab-pc`",
        "",
    ]
    # a sweep from before twin recorded its environment says so, rather than guess
    assert Provenance("old").lines() == [
        "config: `old`",
        "date: not recorded",
        "commit: not recorded",
        "machine: not recorded",
    ]


SWEEP = """
name: tiny_sweep
seeds: [0]
execute: false
planners: [ruckig.movej]
scenarios:
  - {name: free_2, scene: warehouse, random: {count: 2, straight: free}}
"""


def test_a_sweep_says_what_ran_and_report_writes_its_latex_table(tmp_path: Path) -> None:
    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(SWEEP)
    out = tmp_path / "out"
    r = twin("compare", str(cfg), "--out", str(out), "--workers", "0", "--latex", str(tmp_path / "sweep.tex"))
    assert r.returncode == 0, r.stderr
    lines = (out / "summary.md").read_text().splitlines()
    assert lines[2] == f"- config: `tiny_sweep` (`{cfg}`)"
    assert re.fullmatch(r"- date: \d{4}-\d\d-\d\d \d\d:\d\d:\d\d[+-]\d\d:\d\d", lines[3]), lines[3]
    assert lines[4].startswith("- commit: ") and lines[5].startswith("- machine: ") and ", host `" in lines[5]
    page = (out / "summary.html").read_text()
    assert page.index("tiny_sweep") < page.index("<h2>Success</h2>") and "machine:" in page
    r = twin("report", str(out / "results.jsonl"), "--latex", str(tmp_path / "report.tex"))
    assert r.returncode == 0, r.stderr
    tex = (tmp_path / "report.tex").read_text()
    assert tex == (tmp_path / "sweep.tex").read_text()  # the sweep's own table and one made from its results
    assert r"\textit{free\_2}" in tex and "\nruckig.movej & 2 & " in tex


# ---- bench/bench_mbm.py: a subset of MotionBenchMaker's suite ---------------------------------------------
def _bench_mbm() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_mbm", ROOT / "bench" / "bench_mbm.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _problem_set(n: int) -> ProblemSet:
    problems = [Problem(id=f"box#{k:04d}", start=[0.0], goal=JointGoalSpec(joints=[0.1 * k])) for k in range(1, n + 1)]
    return ProblemSet(name="box", robot=RobotSpec(urdf="ur5.urdf", joint_names=["j"]), problems=problems)


def test_bench_mbm_takes_the_named_scenes_and_the_first_n_problems(tmp_path: Path) -> None:
    bench = _bench_mbm()
    args = bench.parse_args(["--scenes", "cage, box,cage", "--problems", "3"])
    assert args.scenes == ["cage", "box"] and args.problems == 3
    everything = bench.parse_args([])
    assert everything.scenes == list(bench.SCENES) and len(everything.scenes) == 7 and everything.problems is None
    ps = _problem_set(5)
    assert [p.id for p in bench.first_problems(ps, 3).problems] == ["box#0001", "box#0002", "box#0003"]
    assert bench.first_problems(ps, 5) is ps and bench.first_problems(ps, None) is ps
    full = tmp_path / "box.json"
    full.write_text(json.dumps(ps.model_dump(mode="json")))
    cut = bench.subset_sets({"box": full}, 2, tmp_path / "subsets")["box"]
    assert cut == (tmp_path / "subsets" / "box-first2.json").resolve()
    assert [p["id"] for p in json.loads(cut.read_text())["problems"]] == ["box#0001", "box#0002"]
    assert bench.subset_sets({"box": full}, 9, tmp_path / "subsets") == {"box": full}


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--scenes", "box,shelf"], "unknown scene 'shelf'; MotionBenchMaker's UR5 scenes: table_pick, "),
        (["--scenes", ","], "no scene given"),
        (["--problems", "0"], "expected a positive integer, got '0'"),
        (["--problems", "two"], "expected a positive integer, got 'two'"),
    ],
)
def test_bench_mbm_refuses_a_bad_subset_in_one_line(
    argv: list[str], needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as e:
        _bench_mbm().parse_args(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("bench_mbm.py: error: ") and needle in err[0], err
    if "scene" in needle and "no scene" not in needle:
        assert "bookshelf_thin" in err[0] and "cage" in err[0]  # every allowed name is listed
