"""Summaries of a comparison: per planner (overall and per scenario) the success rate and the median and
95th percentile of every metric, as `summary.csv`, `summary.md` and a rich table for the terminal.

Beside the numbers, two things that say why they are what they are: where each planner came closest to
the cell (the robot part and body of its smallest clearance, and the pair that is closest most often),
and per scenario how many queries a straight joint motion would have solved (`straight_free`): a
comparison on queries that need no search compares retimers, not planners.

Statistics use every run that produced the value (None is "does not apply"): trajectory metrics come
from successful plans only, planning time from every finished plan (a planner that gives up quickly
is fast at giving up, and that is worth seeing), task metrics from every task run.
"""

from __future__ import annotations

import csv
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.compare.metrics import METRICS, TIMINGS, MetricDef
from twin.errors import ConfigError

if TYPE_CHECKING:
    from rich.table import Table

__all__ = ["ALL", "Stat", "Summary", "SummaryRow", "summarize", "summary_table", "write_summary"]

ALL = "all"  # the scenario column of a planner's overall row
_DEFS: tuple[MetricDef, ...] = METRICS + TIMINGS
_TABLE_KEYS = ("planning_time_s", "duration_s", "min_clearance_m", "max_jerk", "contacts", "goal_error_m")


@dataclass(frozen=True)
class Stat:
    """Median and 95th percentile (linear interpolation) of n values."""

    n: int
    median: float | None
    p95: float | None

    @classmethod
    def of(cls, values: Sequence[float]) -> Stat:
        if not values:
            return cls(0, None, None)
        a = np.asarray(values, dtype=float)
        return cls(int(a.size), float(np.median(a)), float(np.percentile(a, 95)))


@dataclass(frozen=True)
class SummaryRow:
    """One planner on one scenario (or on all of them: scenario == ALL)."""

    planner: str
    scenario: str
    runs: int
    successes: int
    errors: int
    stats: dict[str, Stat]
    min_clearance_m: float | None = None  # the smallest min_clearance_m of any run
    closest_pair: str | None = None  # 'robot_part->body' of that run
    common_pair: str | None = None  # the closest pair seen most often over the successful runs
    common_pair_runs: int = 0  # ... in how many of them
    straight_free: int = 0  # query runs whose straight joint motion was collision-free
    straight_known: int = 0  # query runs that recorded it

    @property
    def success_rate(self) -> float | None:
        return self.successes / self.runs if self.runs else None

    @property
    def straight_free_rate(self) -> float | None:
        return self.straight_free / self.straight_known if self.straight_known else None


@dataclass(frozen=True)
class Summary:
    """Overall rows (one per planner, in config order) and per-scenario rows; skipped runs with reasons."""

    overall: list[SummaryRow]
    by_scenario: list[SummaryRow]
    skipped: list[tuple[str, str]] = field(default_factory=list)

    def metric_keys(self) -> list[str]:
        """Metrics that have at least one value (the others would be empty columns)."""
        return [d.key for d in _DEFS if any(r.stats[d.key].n for r in self.overall)]


def _value(row: dict[str, Any], key: str) -> float | None:
    v = row.get("metrics", {}).get(key)
    if v is None:
        v = row.get("timing", {}).get(key)
    return None if v is None else float(v)


def _summarize(rows: list[dict[str, Any]], planner: str, scenario: str) -> SummaryRow:
    stats = {d.key: Stat.of([v for r in rows if (v := _value(r, d.key)) is not None]) for d in _DEFS}
    with_pair = [
        (v, r["clearance_pair"])
        for r in rows
        if (v := _value(r, "min_clearance_m")) is not None and r.get("clearance_pair")
    ]
    closest = min(with_pair, key=lambda vp: vp[0]) if with_pair else (None, None)
    counts = Counter(p for _, p in with_pair)
    common, n_common = counts.most_common(1)[0] if counts else (None, 0)
    known = [r["straight_free"] for r in rows if r.get("straight_free") is not None]
    return SummaryRow(
        planner=planner,
        scenario=scenario,
        runs=len(rows),
        successes=sum(1 for r in rows if r.get("success")),
        errors=sum(1 for r in rows if r.get("status") == "error"),
        stats=stats,
        min_clearance_m=closest[0],
        closest_pair=closest[1],
        common_pair=common,
        common_pair_runs=n_common,
        straight_free=sum(1 for v in known if v),
        straight_known=len(known),
    )


def summarize(
    rows: Iterable[dict[str, Any]], *, planners: Sequence[str] | None = None, skipped: Sequence[tuple[str, str]] = ()
) -> Summary:
    """Group result rows by planner (in `planners` order, then any others) and by planner x scenario."""
    rows = [r for r in rows if r.get("status") != "skipped"]
    order = list(planners or [])
    order += sorted({r["planner"] for r in rows} - set(order))
    scenarios: list[str] = []
    for r in rows:
        if r["scenario"] not in scenarios:
            scenarios.append(r["scenario"])
    overall = [_summarize([r for r in rows if r["planner"] == p], p, ALL) for p in order]
    by_scenario = [
        _summarize(sel, p, s)
        for s in scenarios
        for p in order
        if (sel := [r for r in rows if r["planner"] == p and r["scenario"] == s])
    ]
    return Summary(overall, by_scenario, list(skipped))


def _fmt(v: float | None, unit: str = "") -> str:
    if v is None:
        return "-"
    if unit == "" and float(v).is_integer():
        return f"{int(v)}"
    a = abs(v)
    if a != 0 and (a < 1e-3 or a >= 1e5):
        return f"{v:.3g}"
    return f"{v:.4g}" if a < 100 else f"{v:.1f}"


def _rate(r: SummaryRow) -> str:
    return "-" if r.success_rate is None else f"{100 * r.success_rate:.0f}% ({r.successes}/{r.runs})"


def write_summary(summary: Summary, out_dir: str | Path) -> list[Path]:
    """Write DIR/summary.csv (every metric, median and p95, per planner overall and per scenario) and
    DIR/summary.md; returns both paths."""
    out = Path(out_dir)
    csv_path, md_path = out / "summary.csv", out / "summary.md"
    keys = [d.key for d in _DEFS]
    try:
        with open(csv_path, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(
                ["planner", "scenario", "runs", "successes", "success_rate", "errors"]
                + [f"{k}_{s}" for k in keys for s in ("median", "p95")]
                + ["closest_pair", "common_closest_pair", "straight_free_rate"]
            )
            for r in summary.overall + summary.by_scenario:
                rate = "" if r.success_rate is None else f"{r.success_rate:.6g}"
                stats = ["" if v is None else repr(v) for k in keys for v in (r.stats[k].median, r.stats[k].p95)]
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
                        r.closest_pair or "",
                        r.common_pair or "",
                        free,
                    ]
                )
        md_path.write_text(_markdown(summary), encoding="utf-8")
    except OSError as e:
        raise ConfigError(f"cannot write the summary in {out}: {e.strerror}") from None
    return [csv_path, md_path]


def _markdown(summary: Summary) -> str:
    defs = {d.key: d for d in _DEFS}
    keys = summary.metric_keys()
    planners = [r.planner for r in summary.overall]
    lines = ["# Planner comparison", "", "## Success", ""]
    lines += ["| planner | runs | success | errors |", "|---|---:|---:|---:|"]
    lines += [f"| {r.planner} | {r.runs} | {_rate(r)} | {r.errors} |" for r in summary.overall]
    lines += ["", "## Metrics: median / p95 (n = runs with a value)", ""]
    lines += ["| metric | unit | " + " | ".join(planners) + " |", "|---|---|" + "---:|" * len(planners)]
    for k in keys:
        d = defs[k]
        cells = []
        for r in summary.overall:
            st = r.stats[k]
            cells.append("-" if not st.n else f"{_fmt(st.median, d.unit)} / {_fmt(st.p95, d.unit)} (n={st.n})")
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
        lines += ["", "## Success by scenario", ""]
        lines += ["| planner | " + " | ".join(scen) + " |", "|---|" + "---:|" * len(scen)]
        cell = {(r.planner, r.scenario): _rate(r) for r in summary.by_scenario}
        for p in planners:
            lines.append(f"| {p} | " + " | ".join(cell.get((p, s), "-") for s in scen) + " |")
    if summary.skipped:
        lines += ["", "## Skipped", ""] + [f"- `{rid}`: {why}" for rid, why in summary.skipped]
    lines += ["", "## Metric definitions", ""]
    lines += [f"- `{d.key}` ({d.unit or 'count'}): {d.description}" for d in _DEFS if d.key in keys]
    return "\n".join(lines) + "\n"


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
    """A rich table: per planner the success rate and the median (p95) of the headline metrics."""
    from rich.markup import escape
    from rich.table import Table

    defs = {d.key: d for d in _DEFS}
    keys = [k for k in _TABLE_KEYS if k in summary.metric_keys()]
    keys += [k for k in ("task_success_rate", "cycle_time_s") if k in summary.metric_keys()]
    table = Table(title=title)
    table.add_column("planner")
    table.add_column("success", justify="right")
    for k in keys:
        unit = defs[k].unit
        table.add_column(escape(f"{k}\nmedian (p95)" + (f" [{unit}]" if unit else "")), justify="right")
    pairs = any(r.common_pair for r in summary.overall)
    if pairs:
        table.add_column("closest pair\n(most often)")
    for r in summary.overall:
        cells = [
            f"{_fmt(r.stats[k].median, defs[k].unit)} ({_fmt(r.stats[k].p95, defs[k].unit)})" if r.stats[k].n else "-"
            for k in keys
        ]
        if pairs:
            cells.append(escape(r.common_pair or "-"))
        table.add_row(r.planner, _rate(r), *cells)
    return table
