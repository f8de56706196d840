"""Summaries of a comparison: per planner (overall and per scenario) the success rate and the median and
95th percentile of every metric, as `summary.csv`, `summary.md` and a rich table for the terminal.

Beside the numbers, two things that say why they are what they are: where each planner came closest to
the cell (the robot part and body of its smallest clearance, and the pair that is closest most often),
and per scenario how many queries a straight joint motion would have solved (`straight_free`): a
comparison on queries that need no search compares retimers, not planners.

Statistics use every run that produced the value (None is "does not apply"): trajectory metrics come
from successful plans only, planning time from every finished plan (a planner that gives up quickly
is fast at giving up, and that is worth seeing), task metrics from every task run.

Whether a difference is real, three ways (the statistics themselves live in `twin.compare.stats`):

- 95 % confidence intervals, one method per kind of quantity, the same in every table, file and plot
  (`stats.INTERVALS` says so at the top of summary.md and under the terminal tables): a success rate
  k/n gets the Wilson score interval (`stats.wilson_ci`; 2/2 gives [34 %, 100 %], never [100 %, 100 %]);
  a median gets a percentile bootstrap (`stats.bootstrap_ci`, BOOTSTRAP_RESAMPLES resamples, the
  generator seeded from crc32(planner, scenario, key), so the same rows always give the same
  intervals; fewer than two values give no interval). n, the runs a number comes from, is printed
  beside every rate (k/n) and every median (n=...), and written to the CSVs (`<metric>_n`, `time_n`).
- why runs failed: counts per reason of the fixed set `metrics.FAILURES` (`row["failure"]`).
- a paired comparison against a reference planner (the first one unless told) on the same problems
  (same scenario, case and seed): wins, ties and losses, the median of the differences
  (planner - reference) and a two-sided Wilcoxon signed-rank p for `PAIRED_KEYS`; for success, the
  runs one planner solved and the other did not and an exact sign test (binomial) on them. See
  `PairedComparison` for the tie rule. p values are per comparison, not corrected for multiplicity.

A scenario with a `sweep` (see `twin.compare.spec`) is also summarised along each swept key
(`SweepPoint`, `sweep.csv`, a table per axis in summary.md): per planner and level the success rate with
its 95 % Wilson score interval (as every success rate), for task runs the mean share of objects placed, and
the median cycle time per placed object (task runs) or trajectory duration (queries) with n and its
bootstrap interval. The nominal point's runs count on every axis.

summary.md (and summary.html) opens with what ran (`Provenance`): the config's name and file, when the sweep
started, twin's commit and the machine (CPU, cores, host) as the sweep recorded them (`twin.environment`):
a planning time means little without the code and the machine it came from.
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.compare.metrics import FAILURES, MetricDef
from twin.compare.stats import (
    INTERVALS,
    MIN_DISCORDANT,
    SIGNIFICANCE,
)
from twin.compare.summary import (
    ALL,
    METRIC_DEFS,
    PAIRED_KEYS,
    SUCCESS,
    Provenance,
    Stat,
    Summary,
    SummaryRow,
    SweepPoint,
    summary_of,
)
from twin.compare.verdicts import p_text, verdicts
from twin.errors import ConfigError

if TYPE_CHECKING:
    from rich.table import Table

__all__ = [
    "summarize",
    "summary_markdown",
    "summary_table",
    "sweep_tables",
    "write_summary",
]

_TABLE_KEYS = (
    "planning_time_s",
    "duration_s",
    "min_clearance_m",
    "max_vel_ratio",
    "max_acc_ratio",
    "max_jerk",
    "contacts",
    "goal_error_m",
)


def summarize(
    rows: Iterable[dict[str, Any]],
    *,
    planners: Sequence[str] | None = None,
    skipped: Sequence[tuple[str, str]] = (),
    reference: str | None = None,
    skipped_pairs: dict[tuple[str, str], int] | None = None,
    provenance: Provenance | None = None,
) -> Summary:
    """`twin.compare.summary.summary_of` (rows grouped by planner and scenario, intervals, failure counts, the
    paired comparison with `reference`), with who leads on what (`twin.compare.verdicts`)."""
    rows = list(rows)
    summary = summary_of(
        rows,
        planners=planners,
        skipped=skipped,
        reference=reference,
        skipped_pairs=skipped_pairs,
        provenance=provenance,
    )
    summary.verdicts.extend(verdicts(summary, [r for r in rows if r.get("status") != "skipped"]))
    return summary


def _fmt(v: float | None, unit: str = "") -> str:
    if v is None:
        return "-"
    if unit == "" and float(v).is_integer():
        return f"{int(v)}"
    a = abs(v)
    if a != 0 and (a < 1e-3 or a >= 1e5):
        return f"{v:.3g}"
    return f"{v:.4g}" if a < 100 else f"{v:.1f}"


def _signed(v: float | None, unit: str = "") -> str:
    return "-" if v is None else ("+" if v > 0 else "") + _fmt(v, unit)


def _p(p: float | None) -> str:
    return "-" if p is None else "<0.001" if p < 1e-3 else f"{p:.3f}"


def _rate(r: SummaryRow | SweepPoint) -> str:
    """'83% (10/12) [55, 95]': a success rate, successes/runs and its 95 % Wilson interval in percent; the
    one format of a rate in every table (overall, per scenario, per sweep level)."""
    if r.success_rate is None:
        return "-"
    ci = "" if r.success_ci is None else f" [{100 * r.success_ci[0]:.0f}, {100 * r.success_ci[1]:.0f}]"
    return f"{100 * r.success_rate:.0f}% ({r.successes}/{r.runs}){ci}"


def _sweep_time(p: SweepPoint) -> str:
    return _median_ci(p.time, "s", symbol=" s") if p.time.n else "-"


def _median_ci(st: Stat, unit: str, *, symbol: str = "") -> str:
    """'0.84 s (n=12) [0.71, 0.95]': the median of a Stat with values, `symbol` after it (a unit where no
    column names it), the number of values and its 95 % bootstrap interval (none below two values)."""
    ci = "" if st.ci is None else f" [{_fmt(st.ci_low, unit)}, {_fmt(st.ci_high, unit)}]"
    return f"{_fmt(st.median, unit)}{symbol} (n={st.n}){ci}"


def _csv_float(v: float | None) -> str:
    return "" if v is None else repr(v)


_PAIRED_COLUMNS = (
    "planner",
    "reference",
    "scenario",
    "metric",
    "n",
    "wins",
    "ties",
    "losses",
    "median_diff",
    "p_value",
)


_SWEEP_COLUMNS = (
    "scenario",
    "key",
    "value",
    "planner",
    "runs",
    "successes",
    "success_rate",
    "success_ci_low",
    "success_ci_high",
    "errors",
    "placed_mean",
    "time_metric",
    "time_n",
    "time_median",
    "time_ci_low",
    "time_ci_high",
)


def _write_sweep_csv(summary: Summary, path: Path) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(_SWEEP_COLUMNS)
        for p in summary.sweeps:
            ci = ["", ""] if p.success_ci is None else [f"{v:.6g}" for v in p.success_ci]
            w.writerow(
                [
                    p.scenario,
                    p.key,
                    json.dumps(p.value),
                    p.planner,
                    p.runs,
                    p.successes,
                    "" if p.success_rate is None else f"{p.success_rate:.6g}",
                    *ci,
                    p.errors,
                    _csv_float(p.placed),
                    p.time_key,
                    p.time.n,
                    _csv_float(p.time.median),
                    _csv_float(p.time.ci_low),
                    _csv_float(p.time.ci_high),
                ]
            )


def write_summary(summary: Summary, out_dir: str | Path) -> list[Path]:
    """Write DIR/summary.csv (every metric, median and p95, per planner overall and per scenario, then the
    95 % intervals (`stats.INTERVALS`), the number of values of each metric and failure counts),
    DIR/summary.md and DIR/paired.csv (the paired comparison, one row per planner, scenario and metric),
    and, when a scenario has a sweep, DIR/sweep.csv (one row per scenario, swept key, level and planner:
    `SweepPoint`); returns the paths."""
    out = Path(out_dir)
    csv_path, md_path, paired_path = out / "summary.csv", out / "summary.md", out / "paired.csv"
    keys = [d.key for d in METRIC_DEFS]
    try:
        with open(csv_path, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            # new columns go before the last three, which readers take as the last three
            w.writerow(
                ["planner", "scenario", "runs", "successes", "success_rate", "errors"]
                + [f"{k}_{s}" for k in keys for s in ("median", "p95")]
                + ["success_ci_low", "success_ci_high"]
                + [f"{k}_median_ci_{s}" for k in keys for s in ("low", "high")]
                + [f"{k}_n" for k in keys]
                + ["failures"]
                + ["closest_pair", "common_closest_pair", "straight_free_rate"]
            )
            for r in summary.overall + summary.by_scenario:
                rate = "" if r.success_rate is None else f"{r.success_rate:.6g}"
                stats = [_csv_float(v) for k in keys for v in (r.stats[k].median, r.stats[k].p95)]
                cis = [_csv_float(v) for k in keys for v in (r.stats[k].ci_low, r.stats[k].ci_high)]
                sci = ["", ""] if r.success_ci is None else [f"{v:.6g}" for v in r.success_ci]
                free = "" if r.straight_free_rate is None else f"{r.straight_free_rate:.6g}"
                w.writerow(
                    [
                        r.planner,
                        r.scenario,
                        r.runs,
                        r.successes,
                        rate,
                        r.errors,
                        *stats,
                        *sci,
                        *cis,
                        *[r.stats[k].n for k in keys],
                        ";".join(f"{k}={n}" for k, n in r.failures.items()),
                        r.closest_pair or "",
                        r.common_pair or "",
                        free,
                    ]
                )
        with open(paired_path, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(_PAIRED_COLUMNS)
            for c in summary.paired:
                w.writerow(
                    [
                        c.planner,
                        c.reference,
                        c.scenario,
                        c.metric,
                        c.n,
                        c.wins,
                        c.ties,
                        c.losses,
                        _csv_float(c.median_diff),
                        _csv_float(c.p_value),
                    ]
                )
        md_path.write_text(summary_markdown(summary), encoding="utf-8")
        if summary.sweeps:
            _write_sweep_csv(summary, out / "sweep.csv")
    except OSError as e:
        raise ConfigError(f"cannot write the summary in {out}: {e.strerror}") from None
    return [csv_path, md_path, paired_path] + ([out / "sweep.csv"] if summary.sweeps else [])


_REPLAYS_LISTED = 3  # failed rows per planner whose replay command summary.md lists


def summary_markdown(summary: Summary) -> str:
    """summary.md's text (also the body of summary.html)."""
    defs = {d.key: d for d in METRIC_DEFS}
    keys = summary.metric_keys()
    planners = [r.planner for r in summary.overall]
    lines = ["# Planner comparison", ""]
    if summary.provenance is not None:
        lines += [f"- {line}" for line in summary.provenance.lines()] + [""]
    lines += [INTERVALS]
    lines += _verdicts_markdown(summary)
    lines += ["", "## Success", ""]
    lines += ["| planner | runs | success (runs) [95% CI] | errors |", "|---|---:|---:|---:|"]
    lines += [f"| {r.planner} | {r.runs} | {_rate(r)} | {r.errors} |" for r in summary.overall]
    reasons = [k for k in FAILURES if any(k in r.failures for r in summary.overall)]
    reasons += sorted({k for r in summary.overall for k in r.failures} - set(FAILURES))
    if reasons:
        lines += ["", "## Failures: runs per reason", ""]
        lines += ["| planner | " + " | ".join(reasons) + " |", "|---|" + "---:|" * len(reasons)]
        for r in summary.overall:
            lines.append(f"| {r.planner} | " + " | ".join(str(r.failures.get(k, 0)) for k in reasons) + " |")
        lines += [""] + [f"- `{k}`: {FAILURES.get(k, 'a reason outside the fixed set')}" for k in reasons]
    if any(r.task_failed_in_planner or r.task_failed_elsewhere for r in summary.overall):
        lines += ["", "## Task runs that failed: where", ""]
        lines += [
            "In a stage the planner under test planned (its transfer, physics during it included: an object "
            "dropped in its transfer is its failure) or elsewhere (the fixed stages, perception, grasping), by "
            "the first object not placed; the stages name the planner that planned them.",
            "",
            "| planner | task runs failed | in its stages | elsewhere | failed stages |",
            "|---|---:|---:|---:|---|",
        ]
        for r in summary.overall:
            n = r.task_failed_in_planner + r.task_failed_elsewhere
            if n:
                where = ", ".join(f"{k} x{v}" for k, v in r.task_failed_stages.items())
                counts = f"{n} | {r.task_failed_in_planner} | {r.task_failed_elsewhere}"
                lines.append(f"| {r.planner} | {counts} | {where} |")
    lines += ["", "## Metrics: median (n = runs with a value) [95% CI] / p95", ""]
    lines += ["| metric | unit | " + " | ".join(planners) + " |", "|---|---|" + "---:|" * len(planners)]
    for k in keys:
        d = defs[k]
        cells = []
        for r in summary.overall:
            st = r.stats[k]
            cells.append("-" if not st.n else f"{_median_ci(st, d.unit)} / {_fmt(st.p95, d.unit)}")
        lines.append(f"| {k} | {d.unit} | " + " | ".join(cells) + " |")
    if any(r.closest_pair for r in summary.overall):
        lines += ["", "## Closest approach to the cell", ""]
        lines += [
            "| planner | min clearance (m) | closest pair there | closest pair most often |",
            "|---|---:|---|---|",
        ]
        for r in summary.overall:
            st = r.stats["min_clearance_m"]
            low = _fmt(r.min_clearance_m, "m")
            often = f"{r.common_pair} ({r.common_pair_runs}/{st.n})" if r.common_pair else "-"
            lines.append(f"| {r.planner} | {low} | {r.closest_pair or '-'} | {often} |")
    scen = list(dict.fromkeys(r.scenario for r in summary.by_scenario))
    difficulty = _straight_by_scenario(summary, scen)
    if difficulty:
        lines += ["", "## Query difficulty: straight joint motion from start to goal collision-free", ""]
        lines += ["| scenario | free | share |", "|---|---:|---:|"]
        lines += [f"| {s} | {free}/{n} | {100 * free / n:.0f}% |" for s, (free, n) in difficulty.items()]
    if scen:
        lines += ["", "## Success by scenario [95% CI]", ""]
        lines += ["| planner | " + " | ".join(scen) + " |", "|---|" + "---:|" * len(scen)]
        cell = {(r.planner, r.scenario): _rate(r) for r in summary.by_scenario}
        for p in planners:
            lines.append(f"| {p} | " + " | ".join(cell.get((p, s), "-") for s in scen) + " |")
    if summary.sweeps:
        lines += _sweep_markdown(summary)
    if summary.paired:
        lines += _paired_markdown(summary, defs)
    if summary.skipped:
        lines += ["", "## Skipped", ""] + [f"- `{rid}`: {why}" for rid, why in summary.skipped]
    if any(r.failed_runs for r in summary.overall):
        lines += ["", "## See why a run failed", ""]
        lines += [
            f"From this folder, `twin replay` runs a failed row again and writes a Rerun recording of it (open it with"
            f" `rerun OUT.rrd`); the first {_REPLAYS_LISTED} failed rows of each planner:",
            "",
        ]
        for r in summary.overall:
            for rid in r.failed_runs[:_REPLAYS_LISTED]:
                name = re.sub(r"[^A-Za-z0-9]+", "_", rid.rsplit("|", 1)[0]).strip("_")
                lines.append(f"- {r.planner}: `twin replay results.jsonl '{rid}' --rerun {name}.rrd`")
    lines += ["", "## Metric definitions", ""]
    lines += [f"- `{d.key}` ({d.unit or 'count'}): {d.description}" for d in METRIC_DEFS if d.key in keys]
    return "\n".join(lines) + "\n"


def _verdicts_markdown(summary: Summary) -> list[str]:
    if not summary.verdicts:
        return []
    lines = ["", "## Who wins on what", ""]
    lines += [
        "Per scenario, the leader on success and, among the planners with the top success rate, on time (a "
        "planner that fails fast is no choice for speed; the fastest of all is named when it is another), and "
        "the next planner behind it, tested on the problems both ran (success: exact sign test; times: Wilcoxon "
        f"signed-rank; a lead is real below p = {SIGNIFICANCE}). Medians name their n: a duration has a value only "
        "where the plan succeeded.",
    ]
    for scenario in dict.fromkeys(v.scenario for v in summary.verdicts):
        lines += ["", f"### {'all scenarios' if scenario == ALL else scenario}", ""]
        lines += [f"- {v.text}" for v in summary.verdicts if v.scenario == scenario]
    if summary.reference is not None and summary.paired:
        lines += ["", f"Against the reference `{summary.reference}`, on the same problems (paired, below):", ""]
        lines += _against_reference(summary)
    return lines


def _against_reference(summary: Summary) -> list[str]:
    """One line per (side, metric, scenario): the planners significantly better or worse than the reference."""
    groups: dict[tuple[str, str, str], list[str]] = {}
    success = {(c.planner, c.scenario): c for c in summary.paired if c.metric == SUCCESS}
    for c in summary.paired:
        if c.p_value is not None and c.p_value < SIGNIFICANCE and c.wins != c.losses:
            side = "better" if c.wins > c.losses else "worse"
            where = "all scenarios" if c.scenario == ALL else c.scenario
            why = p_text(c.p_value)
            solved = success.get((c.planner, c.scenario))
            if side == "better" and c.metric != SUCCESS and solved is not None and solved.losses > solved.wins:
                # a planner that gives up early is quick: its time lead is no lead where it solves less
                why += f"; but it fails {solved.losses} problems the reference solves, solving {solved.wins} it fails"
            groups.setdefault((side, c.metric, where), []).append(f"`{c.planner}` ({why})")
    if not groups:
        return ["- no planner is significantly better or worse on any metric"]
    order = {m: i for i, m in enumerate((SUCCESS, *PAIRED_KEYS))}
    keys = sorted(groups, key=lambda k: (k[0] != "better", order.get(k[1], len(order)), k[2] != "all scenarios"))
    return [f"- {side} on {metric}, {where}: " + ", ".join(groups[side, metric, where]) for side, metric, where in keys]


def _sweep_markdown(summary: Summary) -> list[str]:
    lines = ["", "## Sweeps: success by level", ""]
    lines += [
        "One swept key at a time, the other swept keys at their first (nominal) value; the nominal runs count "
        "on every axis. Cells: success rate (successes/runs) [95% CI]; for task runs the mean share of objects "
        "placed; the median cycle time per placed object (task runs) or trajectory duration (queries) "
        "(n = runs with a value) [95% CI].",
    ]
    for scenario, key in summary.sweep_axes():
        pts = [p for p in summary.sweeps if p.scenario == scenario and p.key == key]
        levels = list(dict.fromkeys(p.value_text for p in pts))
        planners = list(dict.fromkeys(p.planner for p in pts))
        cell = {(p.planner, p.value_text): p for p in pts}
        lines += ["", f"### {scenario}: {key}", ""]
        head = [f"{lv} (nominal)" if i == 0 else lv for i, lv in enumerate(levels)]
        lines += ["| planner | " + " | ".join(head) + " |", "|---|" + "---:|" * len(levels)]
        for planner in planners:
            cells = []
            for lv in levels:
                p = cell.get((planner, lv))
                if p is None:
                    cells.append("-")
                    continue
                placed = "" if p.placed is None else f"; placed {100 * p.placed:.0f}%"
                cells.append(f"{_rate(p)}{placed}; {_sweep_time(p)}")
            lines.append(f"| {planner} | " + " | ".join(cells) + " |")
    return lines


def _paired_markdown(summary: Summary, defs: dict[str, MetricDef]) -> list[str]:
    lines = ["", f"## Paired against {summary.reference}", ""]
    lines += [
        "The same problems (scenario, case, seed) for both planners. W/T/L: the planner did better / the same "
        f"/ worse than {summary.reference} (lower time; for success: solved what the reference did not). "
        "Median diff: planner - reference. p: two-sided Wilcoxon signed-rank test on the non-tied pairs "
        f"(success: exact sign test on the discordant pairs), '-' below {MIN_DISCORDANT} of them; "
        "not corrected for the number of comparisons. Ties: |a - b| <= 1e-9 + 1e-6 max(|a|, |b|).",
        "",
    ]
    lines += ["| planner | scenario | metric | n | W/T/L | median diff | p |", "|---|---|---|---:|---:|---:|---:|"]
    for c in summary.paired:
        unit = defs[c.metric].unit if c.metric in defs else ""
        lines.append(
            f"| {c.planner} | {c.scenario} | {c.metric} | {c.n} | {c.wins}/{c.ties}/{c.losses} "
            f"| {_signed(c.median_diff, unit)} | {_p(c.p_value)} |"
        )
    return lines


def _straight_by_scenario(summary: Summary, scenarios: list[str]) -> dict[str, tuple[int, int]]:
    """Per scenario (free, known) over the queries, counted once: every planner ran the same ones."""
    out: dict[str, tuple[int, int]] = {}
    for s in scenarios:
        rows = [r for r in summary.by_scenario if r.scenario == s and r.straight_known]
        if rows:
            r = max(rows, key=lambda x: x.straight_known)
            out[s] = (r.straight_free, r.straight_known)
    return out


def summary_table(summary: Summary, *, title: str = "planner comparison") -> Table:
    """A rich table: per planner the success rate with its 95 % Wilson interval and the median (p95) of the
    headline metrics with their number of values; the caption says which interval is which (`INTERVALS`)."""
    from rich.markup import escape
    from rich.table import Table

    defs = {d.key: d for d in METRIC_DEFS}
    keys = [k for k in _TABLE_KEYS if k in summary.metric_keys()]
    keys += [k for k in ("task_success_rate", "cycle_time_s") if k in summary.metric_keys()]
    table = Table(title=title, caption=INTERVALS)
    table.add_column("planner")
    table.add_column(escape("success\n(runs) [95% CI]"), justify="right")
    for k in keys:
        unit = defs[k].unit
        table.add_column(escape(f"{k}\nmedian (p95)" + (f" [{unit}]" if unit else "") + "\nn"), justify="right")
    pairs = any(r.common_pair for r in summary.overall)
    if pairs:
        table.add_column("closest pair\n(most often)")
    for r in summary.overall:
        cells = [
            f"{_fmt(r.stats[k].median, defs[k].unit)} ({_fmt(r.stats[k].p95, defs[k].unit)})\nn={r.stats[k].n}"
            if r.stats[k].n
            else "-"
            for k in keys
        ]
        if pairs:
            cells.append(escape(r.common_pair or "-"))
        table.add_row(r.planner, escape(_rate(r)), *cells)
    return table


def sweep_tables(summary: Summary) -> list[Table]:
    """Rich tables of the sweep points, one per swept key of a scenario: a row per planner, a column per
    level, each cell the success rate (runs) with its 95 % Wilson interval over the median time with n and
    its bootstrap interval (the caption: `INTERVALS`)."""
    from rich.markup import escape
    from rich.table import Table

    tables = []
    for scenario, key in summary.sweep_axes():
        pts = [p for p in summary.sweeps if p.scenario == scenario and p.key == key]
        levels = list(dict.fromkeys(p.value_text for p in pts))
        cell = {(p.planner, p.value_text): p for p in pts}
        time_key = pts[0].time_key
        table = Table(
            title=escape(f"{scenario}: success (runs) [95% CI] / median {time_key} (n) [95% CI], by {key}"),
            caption=INTERVALS,
        )
        table.add_column("planner")
        for lv in levels:
            table.add_column(escape(f"{lv}\n(nominal)" if lv == levels[0] else lv), justify="right")
        for planner in dict.fromkeys(p.planner for p in pts):
            cells = []
            for lv in levels:
                p = cell.get((planner, lv))
                cells.append("-" if p is None else escape(f"{_rate(p)}\n{_sweep_time(p)}"))
            table.add_row(planner, *cells)
        tables.append(table)
    return tables
