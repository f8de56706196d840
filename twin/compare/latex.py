"""A comparison as a table for a paper: booktabs LaTeX (`twin report RESULTS --latex OUT.tex`, `twin compare
--latex OUT.tex`).

One block per scenario (its name on a line of its own, `\\midrule` between blocks), one row per planner:
the runs n, the success rate with its 95 % Wilson score interval, the median planning time and the median
trajectory duration, each with its 95 % percentile-bootstrap interval. The numbers are the summary's
(`twin.compare.report.summarize`, whose statistics live in `twin.compare.stats`), so the table says what
summary.md says, in the same precision; the caption names the interval methods, as `stats.INTERVALS` does.
Names are LaTeX-escaped (`ompl.rrt_connect` -> `ompl.rrt\\_connect`). The table needs
`\\usepackage{booktabs}` and nothing else.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from twin.compare.report import _fmt, summarize
from twin.compare.runner import RESULTS_FILE, SPEC_FILE, latest_rows, read_results
from twin.compare.stats import BOOTSTRAP_RESAMPLES, CONFIDENCE
from twin.compare.summary import Stat, Summary, SummaryRow
from twin.errors import ConfigError

__all__ = ["DEFAULT_LABEL", "latex_escape", "latex_report", "latex_table", "read_result_rows", "write_latex"]

DEFAULT_LABEL = "tab:planner-comparison"
_COLUMNS = 8  # planner, n, success rate and CI, planning time and CI, duration and CI
_ESCAPES = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
    "<": r"\textless{}",
    ">": r"\textgreater{}",
    "|": r"\textbar{}",
}
_NONE = "--"
_HEAD = (
    r"Planner & $n$ & \multicolumn{2}{c}{Success (\%)} & \multicolumn{2}{c}{Planning time (s)}"
    r" & \multicolumn{2}{c}{Duration (s)} \\",
    r"\cmidrule(lr){3-4} \cmidrule(lr){5-6} \cmidrule(lr){7-8}",
    r" & & rate & 95\% CI & median & 95\% CI & median & 95\% CI \\",
)


def latex_escape(text: str) -> str:
    """`text` with LaTeX's special characters escaped, to be set as it reads."""
    return "".join(_ESCAPES.get(c, c) for c in text)


def _number(v: float | None) -> str:
    """A value as summary.md writes it (`report._fmt`, 4 significant digits), e-notation as a power of ten."""
    text = _fmt(v, "s")
    m = re.fullmatch(r"(-?[\d.]+)e([+-]\d+)", text)
    return f"${m[1]}\\times10^{{{int(m[2])}}}$" if m else text


def _median_cells(st: Stat) -> list[str]:
    if not st.n:
        return [_NONE, _NONE]
    ci = _NONE if st.ci is None else f"[{_number(st.ci_low)}, {_number(st.ci_high)}]"
    return [_number(st.median), ci]


def _row(r: SummaryRow) -> str:
    rate = _NONE if r.success_rate is None else f"{100 * r.success_rate:.0f}"
    ci = _NONE if r.success_ci is None else f"[{100 * r.success_ci[0]:.0f}, {100 * r.success_ci[1]:.0f}]"
    cells = [latex_escape(r.planner), str(r.runs), rate, ci]
    cells += _median_cells(r.stats["planning_time_s"]) + _median_cells(r.stats["duration_s"])
    return " & ".join(cells) + r" \\"


def _caption(summary: Summary) -> str:
    pct = f"{100 * CONFIDENCE:.0f}\\,\\%"
    text = (
        f"Planner comparison by scenario, $n$ runs per planner: success rate with its {pct} Wilson score interval; "
        f"medians with their {pct} percentile-bootstrap intervals ({BOOTSTRAP_RESAMPLES} resamples; none from a "
        "single value), planning time over every finished plan, duration over the successful plans only."
    )
    if summary.skipped_pairs:
        text += " Not run: the planner cannot serve the scenario's goals."
    return text


def latex_table(summary: Summary, *, caption: str | None = None, label: str = DEFAULT_LABEL) -> str:
    """The summary's per-scenario rows as a booktabs `table` (a block per scenario, a row per planner in the
    summary's order); `caption` is set as given (LaTeX), default: what the columns and intervals are."""
    planners = [r.planner for r in summary.overall]
    scenarios = list(dict.fromkeys([r.scenario for r in summary.by_scenario] + [s for _, s in summary.skipped_pairs]))
    if not scenarios:
        raise ConfigError("no runs to tabulate: every run was skipped")
    lines = [
        "% written by twin (twin.compare.latex); needs \\usepackage{booktabs}",
        r"\begin{table}",
        r"\centering",
        f"\\caption{{{_caption(summary) if caption is None else caption}}}",
        f"\\label{{{label}}}",
        r"\begin{tabular}{lrrlrlrl}",
        r"\toprule",
        *_HEAD,
    ]
    for scenario in scenarios:
        lines += [r"\midrule", f"\\multicolumn{{{_COLUMNS}}}{{l}}{{\\textit{{{latex_escape(scenario)}}}}} \\\\"]
        for p in planners:
            row = summary.row(p, scenario)
            if row is not None:
                lines.append(_row(row))
            elif (p, scenario) in summary.skipped_pairs:
                lines.append(f"{latex_escape(p)} & 0 & \\multicolumn{{{_COLUMNS - 2}}}{{l}}{{not run}} \\\\")
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"


def write_latex(summary: Summary, path: str | Path, **options: Any) -> Path:
    """Write `latex_table(summary, **options)` to `path`; ConfigError (one line) when it cannot be written."""
    p = Path(path)
    try:
        p.write_text(latex_table(summary, **options), encoding="utf-8")
    except OSError as e:
        raise ConfigError(f"cannot write {p}: {e.strerror}") from None
    return p


def read_result_rows(results: str | Path) -> tuple[list[dict[str, Any]], list[str]]:
    """The latest row of each run of a sweep (`results`: its results.jsonl or the folder holding it) and the
    planners in the order its config lists them (from the compare.json beside it; else as the rows first
    show them). ConfigError, one line, for a missing file, a file that is not a results file, no rows."""
    src = Path(results)
    path = src / RESULTS_FILE if src.is_dir() else src
    if not path.is_file():
        raise ConfigError(f"no results file at {path} (give a results.jsonl of `twin compare` or its folder)")
    try:
        first = next((line for line in path.read_bytes().splitlines() if line.strip()), None)
        row = None if first is None else json.loads(first)
    except OSError as e:
        raise ConfigError(f"cannot read {path}: {e.strerror}") from None
    except ValueError:
        row = None
    if first is None:
        raise ConfigError(f"{path} holds no result rows")
    if not isinstance(row, dict) or "run_id" not in row:
        raise ConfigError(f"{path} is not a results file of `twin compare` (its first line is not a result row)")
    rows = latest_rows(read_results(path))
    order = _config_planners(path.parent / SPEC_FILE)
    return rows, order + [p for p in dict.fromkeys(str(r.get("planner")) for r in rows) if p not in order]


def _config_planners(spec_file: Path) -> list[str]:
    """The planner labels of the config a sweep recorded (compare.json), [] when there is none."""
    try:
        spec = json.loads(spec_file.read_text(encoding="utf-8")).get("spec") or {}
        return [str(p.get("label") or p["name"]) for p in spec.get("planners", [])]
    except (OSError, ValueError, AttributeError, KeyError, TypeError):
        return []


def latex_report(
    results: str | Path, out: str | Path, *, caption: str | None = None, label: str = DEFAULT_LABEL
) -> tuple[Path, Summary]:
    """Summarise a sweep's results (`read_result_rows`) and write its LaTeX table to `out`; returns the path
    and the summary."""
    rows, planners = read_result_rows(results)
    summary = summarize(rows, planners=_present(planners, rows))
    return write_latex(summary, out, caption=caption, label=label), summary


def _present(planners: Sequence[str], rows: Sequence[dict[str, Any]]) -> list[str]:
    """The planners that have rows (a config's planner without any has no line in the table)."""
    have = {r.get("planner") for r in rows}
    return [p for p in planners if p in have]
