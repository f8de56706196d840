"""PNG plots of a comparison: box plots of planning time, duration and clearance per planner,
success-rate bars per planner and scenario, and for a sweep, per swept key, success and time against the
level (`sweep_<key>.png`). The only module of twin that imports matplotlib (Agg, so it
works headless), and only when called.

The plots show how sure the numbers are with the intervals of the summary (`report.summarize`, the
same methods, seeds and numbers as summary.md; `stats.INTERVALS`): each box carries a marker at its median
with the median's 95 % percentile-bootstrap interval as an error bar beside it and its number of values
under the planner's name, each success bar the 95 % Wilson interval of its success rate, each sweep line
the band of its 95 % interval (Wilson for a success rate, the bootstrap for a median time;
`report.SweepPoint`).

"Best first" is the same order everywhere (`best_first`): the most successful planner first, then the
fastest (in a box plot, the best value of its metric) — a planner that fails fast is never on top. Log axes
label decades and, over a narrow range, 2 and 5 between them as plain numbers, never every minor tick.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.compare.report import summarize
from twin.compare.summary import ALL
from twin.errors import ConfigError, DependencyMissing

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from twin.compare.summary import Stat, Summary, SummaryRow, SweepPoint

__all__ = ["BOX_PLOTS", "BoxPlot", "best_first", "comparison_figures", "sweep_figures", "write_plots"]

log = logging.getLogger("twin")


@dataclass(frozen=True)
class BoxPlot:
    """A box-plot figure: a panel per scenario that has values of its metric (`keys`: run kind -> metric
    key, so task scenarios show the task's own number), planners sorted best first."""

    stem: str
    keys: dict[str, str]
    log_scale: bool = False
    higher_is_better: bool = False


BOX_PLOTS: tuple[BoxPlot, ...] = (
    BoxPlot("planning_time", {"query": "planning_time_s", "task": "task_planning_time_s"}, log_scale=True),
    BoxPlot("duration", {"query": "duration_s"}),
    BoxPlot("clearance", {"query": "min_clearance_m"}, higher_is_better=True),
    BoxPlot("cycle_time", {"task": "cycle_time_s"}),
)
_AXIS = {
    "planning_time_s": "planning time per query (s)",
    "task_planning_time_s": "planning time per motion in the task (s)",
    "duration_s": "trajectory duration (s), successful plans",
    "min_clearance_m": "minimum clearance to the cell (m), successful plans",
    "cycle_time_s": "cycle time per placed object (s)",
}
_CI_OFFSET = 0.33  # the median's interval is drawn this far below its box (boxes are 0.5 high)
_DODGE = 0.012  # sweep lines are shifted sideways by this share of the x range per planner, so equal ones show
_MARKERS = "osD^vP*Xh<>p"
_TIME_LABELS = {"cycle_time_s": "cycle time per placed object (s)", "duration_s": "trajectory duration (s)"}
_SKIPPED = "not run (skipped)"
_ROW_IN = 0.3  # inches per planner in a panel of horizontal boxes or bars
_ALIKE_M = 1e-6  # values of one query closer than this are the same value (a shared closest point)
_TIME_KEYS = ("planning_time_s", "task_planning_time_s")


def _pyplot() -> Any:
    try:
        import matplotlib as mpl
    except ImportError as e:
        raise DependencyMissing("plots need matplotlib; install it with `pip install 'twin[plots]'`") from e
    mpl.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _value(row: dict[str, Any], key: str) -> float | None:
    v = row.get("metrics", {}).get(key)
    if v is None:
        v = row.get("timing", {}).get(key)
    return None if v is None else float(v)


def _median_time(row: SummaryRow | None) -> float:
    """The median planning time of a summary row (per query, else per motion of its task runs); inf without."""
    for key in _TIME_KEYS:
        st = row.stats.get(key) if row is not None else None
        if st is not None and st.median is not None:
            return st.median
    return math.inf


def best_first(row: SummaryRow | None, value: float | None = None) -> tuple[float, float]:
    """The sort key of "best first": the success rate (highest first; no runs last), then `value` (lower
    first: a time, or a negated value where higher is better), by default the median planning time."""
    rate = row.success_rate if row is not None and row.runs and row.success_rate is not None else -1.0
    then = _median_time(row) if value is None else value
    return (-rate, then if math.isfinite(then) else math.inf)


def _log_ticks(axis: Any) -> None:
    """Label a log axis so no two labels collide: the decades, and between them 2 and 5 when it spans at
    most two decades (every integer multiple below 0.6 of one), as plain numbers ('0.002', '0.05'); the
    other minor ticks stay unlabelled. A range with fewer than two such ticks is widened to the nearest."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter

    lo, hi = sorted(axis.get_view_interval())
    if not (lo > 0 and hi > lo):
        return
    span = math.log10(hi / lo)
    subs = (1.0,) if span > 2.0 else (1.0, 2.0, 5.0) if span > 0.6 else tuple(float(k) for k in range(1, 10))
    decades = range(math.floor(math.log10(lo)) - 1, math.ceil(math.log10(hi)) + 2)
    ticks = sorted(k * 10.0**d for d in decades for k in subs)
    inside = [t for t in ticks if lo * (1 - 1e-9) <= t <= hi * (1 + 1e-9)]
    if len(inside) < 2:  # too narrow to hold two: widen to the neighbouring ticks
        below = max((t for t in ticks if t <= lo), default=lo)
        above = min((t for t in ticks if t >= hi), default=hi)
        axis.set_view_interval(below, above, ignore=True)
        inside = [t for t in ticks if below <= t <= above]
    axis.set_major_locator(FixedLocator(inside))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_locator(LogLocator(subs=tuple(float(k) for k in range(2, 10))))
    axis.set_minor_formatter(NullFormatter())


def _panels(plt: Any, heights: Sequence[float], *, width: float = 7.0) -> tuple[Figure, list[Axes]]:
    """A figure of len(heights) panels, two per row (one if there is one), each row as tall as its
    tallest panel needs."""
    n = len(heights)
    cols = 1 if n == 1 else 2
    rows = math.ceil(n / cols)
    row_h = [max(heights[i * cols : (i + 1) * cols]) for i in range(rows)]
    fig, axes = plt.subplots(
        rows,
        cols,
        figsize=(width * cols, sum(row_h) + 0.4),
        squeeze=False,
        gridspec_kw={"height_ratios": row_h},
    )
    flat = [ax for line in axes for ax in line]
    for ax in flat[n:]:
        ax.set_axis_off()
    return fig, flat[:n]


def _scenarios(rows: Sequence[dict[str, Any]], summary: Summary) -> list[tuple[str, str]]:
    """(scenario, kind of its runs) in the order the rows show them, skipped-only scenarios included."""
    kinds = {r["scenario"]: str(r.get("kind") or "query") for r in rows}
    names = list(dict.fromkeys([*(r["scenario"] for r in rows), *(s for _, s in summary.skipped_pairs)]))
    return [(s, kinds.get(s, "query")) for s in names]


@dataclass(frozen=True)
class _Entry:
    """One planner's row in a box panel: its values of the metric, their statistics and its summary row
    on the scenario (for its success rate)."""

    planner: str
    values: list[float]
    stat: Stat | None
    row: SummaryRow | None


def _box_panel(ax: Axes, title: str, key: str, entries: list[_Entry], box: BoxPlot, note: str | None) -> None:
    """Horizontal boxes best first (`best_first`: success, then the median), the success rate and `n`
    beside each name, the median's bootstrap interval under its box; a planner that ran here without a
    value of `key` keeps its row (n=0). `note` is written over the panel (why its values are alike)."""

    def rank(e: _Entry) -> tuple[float, float, float]:
        med = float(f"{np.median(e.values):.9g}") if e.values else math.inf  # equal to 9 digits: a tie
        return (*best_first(e.row, -med if box.higher_is_better and e.values else med), _median_time(e.row))

    entries = sorted(entries, key=rank)
    data = [e.values or [math.nan] for e in entries]
    ys = list(range(1, len(entries) + 1))
    ax.boxplot(data, positions=ys, orientation="horizontal", widths=0.5, showfliers=True)
    ax.set_yticks(ys, [f"{e.planner}  {_rate_text(e.row)}  n={len(e.values)}" for e in entries], fontsize="small")
    ax.set_ylim(len(entries) + 0.5, 0.5 - (1.5 if note else 0.0))  # best on top; room for the note
    x, y, lo, hi = [], [], [], []
    for i, e in zip(ys, entries, strict=True):
        st = e.stat
        if st is not None and st.median is not None and st.ci is not None:
            x.append(st.median)
            y.append(i + _CI_OFFSET)
            lo.append(st.median - st.ci[0])
            hi.append(st.ci[1] - st.median)
    if x:
        ax.errorbar(x, y, xerr=[lo, hi], fmt="D", ms=3, color="C3", capsize=2.5, lw=1.1)
    values = [v for e in entries for v in e.values]
    if box.log_scale and values and all(v > 0 for v in values):
        ax.set_xscale("log")
        _log_ticks(ax.xaxis)
    else:
        ax.set_xlim(left=min(0.0, *values) if values else 0.0)
    for i, e in zip(ys, entries, strict=True):
        if not e.values:
            ax.text(
                0.01, i, "no value", transform=ax.get_yaxis_transform(), va="center", fontsize="x-small", color="0.4"
            )
    if note:
        ax.text(
            0.02,
            0.97,
            note,
            transform=ax.transAxes,
            ha="left",
            va="top",
            fontsize="x-small",
            color="0.15",
            bbox={"boxstyle": "round,pad=0.3", "fc": "#fff6d5", "ec": "0.6", "lw": 0.6},
        )
    ax.set_xlabel(_AXIS.get(key, key))
    ax.set_title(title, fontsize="medium")
    ax.grid(axis="x", alpha=0.3)


def _rate_text(row: SummaryRow | None) -> str:
    """'100% ok' (the planner's success rate on the scenario) or '' without runs."""
    if row is None or not row.runs or row.success_rate is None:
        return ""
    return f"{100 * row.success_rate:.0f}% ok"


def _alike_note(rows: list[dict[str, Any]], key: str, kind: str) -> str | None:
    """A line when every planner has the same value of `key` on each query of a scenario (two or more
    planners with a value on it): then the plot shows no difference between planners, only between
    queries. For clearance that is a shared closest point: the query's start or goal (a grasp near the
    table), or the same path, when the straight joint motion is free and the planners return it."""
    by_case: dict[str, list[float]] = {}
    free: dict[str, bool] = {}
    for r in rows:
        if (v := _value(r, key)) is not None:
            case = str(r.get("case") or r.get("run_id"))
            by_case.setdefault(case, []).append(v)
            free[case] = bool(r.get("straight_free"))
    shared = {c: vs for c, vs in by_case.items() if len(vs) > 1}
    if not shared or any(max(vs) - min(vs) > _ALIKE_M for vs in shared.values()):
        return None
    n = len(shared)
    what = ("query", "queries") if kind == "query" else ("problem", "problems")
    line = f"the same value for every planner on each of its {n} {what[n != 1]}"
    if key == "min_clearance_m":
        k = sum(free[c] for c in shared)
        line += (
            f":\nthe paths share their closest point (the start or goal, or the\nstraight joint line, which is free"
            f" on {k} of {n})"
        )
    return line


def _box_figures(plt: Any, rows: list[dict[str, Any]], summary: Summary, order: list[str]) -> dict[str, Figure]:
    figs: dict[str, Figure] = {}
    scenarios = _scenarios(rows, summary)
    for box in BOX_PLOTS:
        panels = []
        for scenario, kind in scenarios:
            key = box.keys.get(kind)
            if key is None:
                continue
            here = [r for r in rows if r["scenario"] == scenario]
            entries = []
            for p in order:
                mine = [r for r in here if r["planner"] == p]
                if mine:
                    row = summary.row(p, scenario)
                    vals = [v for r in mine if (v := _value(r, key)) is not None]
                    entries.append(_Entry(p, vals, row.stats.get(key) if row is not None else None, row))
            if any(e.values for e in entries):
                panels.append((scenario, key, entries, _alike_note(here, key, kind)))
        if not panels:
            continue  # no empty plot files
        fig, axes = _panels(plt, [_ROW_IN * len(e) + 1.3 + 0.5 * bool(n) for _, _, e, n in panels])
        for ax, (scenario, key, entries, note) in zip(axes, panels, strict=True):
            _box_panel(ax, scenario, key, entries, box, note)
        fig.suptitle(
            "best first: most successful, then best median; n: runs with a value\n"
            "box: quartiles, whiskers 1.5 IQR; red: the median with its 95 % bootstrap CI",
            fontsize="small",
            y=1 - 0.08 / fig.get_figheight(),
            va="top",
        )
        fig.tight_layout()  # it leaves room for the suptitle
        figs[box.stem] = fig
    return figs


def _success_order(summary: Summary, order: list[str]) -> list[str]:
    """Planners best first over all scenarios (`best_first`: success, then median planning time; config
    order among equals; no runs last)."""
    return sorted(order, key=lambda p: best_first(summary.row(p)))


def _heatmap(plt: Any, summary: Summary, order: list[str], scenarios: list[str]) -> Figure:
    """Success per planner (rows, best overall first) and scenario (columns, then all of them): the rate
    as colour and 'rate\nk/n' in the cell; a skipped pair hatched grey and labelled, never a 0 %."""
    from matplotlib.patches import Rectangle

    planners = _success_order(summary, order)
    cols = [*scenarios, ALL] if len(scenarios) > 1 else list(scenarios)
    grid = np.full((len(planners), len(cols)), np.nan)
    fig, ax = plt.subplots(figsize=(3.2 + 1.45 * len(cols), 0.42 * len(planners) + 1.6))
    cmap = plt.get_cmap("RdYlGn").with_extremes(bad="white")
    for i, p in enumerate(planners):
        for j, s in enumerate(cols):
            row = summary.row(p, s)
            if row is not None and row.runs:
                grid[i, j] = row.success_rate
    im = ax.imshow(grid, cmap=cmap, vmin=0.0, vmax=1.0, aspect="auto")
    for i, p in enumerate(planners):
        for j, s in enumerate(cols):
            row = summary.row(p, s)
            skipped = summary.skipped_pairs.get((p, s), 0) if s != ALL else 0
            if row is not None and row.runs:
                rate = row.success_rate or 0.0
                text = f"{100 * rate:.0f}%\n{row.successes}/{row.runs}"
                if skipped:
                    text += f" (+{skipped} skipped)"
                color = "white" if rate < 0.15 or rate > 0.85 else "black"
                ax.text(j, i, text, ha="center", va="center", fontsize="x-small", color=color)
            elif skipped:
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, facecolor="0.93", edgecolor="0.6", hatch="///", lw=0))
                ax.text(j, i, "skipped", ha="center", va="center", fontsize="x-small", color="0.25")
            else:
                ax.text(j, i, "-", ha="center", va="center", fontsize="x-small", color="0.5")
    ax.set_xticks(range(len(cols)), ["all scenarios" if s == ALL else s for s in cols], rotation=20, ha="right")
    ax.set_yticks(range(len(planners)), planners, fontsize="small")
    ax.set_title("success rate (successes/runs); hatched: not run here")
    fig.colorbar(im, ax=ax, fraction=0.04, pad=0.02, label="success rate")
    fig.tight_layout()
    return fig


def _success_bars(plt: Any, summary: Summary, order: list[str], scenarios: list[str]) -> Figure:
    """Per scenario, horizontal bars of the success rate with its 95 % Wilson interval, best first, k/n at
    each bar (a 0 % has its label at 0); skipped pairs last, hatched across the axis and labelled."""
    heights = []
    for s in scenarios:
        k = sum(1 for p in order if summary.row(p, s) is not None or summary.skipped_pairs.get((p, s)))
        heights.append(_ROW_IN * k + 1.2)
    fig, axes = _panels(plt, heights, width=6.5)
    for ax, s in zip(axes, scenarios, strict=True):
        ran = [r for p in order if (r := summary.row(p, s)) is not None and r.runs]
        ran.sort(key=best_first)
        skipped = [p for p in order if summary.row(p, s) is None and summary.skipped_pairs.get((p, s))]
        ys = list(range(len(ran)))
        rates = [100.0 * (r.success_rate or 0.0) for r in ran]
        lo = [100.0 * ((r.success_rate or 0.0) - r.success_ci[0]) if r.success_ci else 0.0 for r in ran]
        hi = [100.0 * (r.success_ci[1] - (r.success_rate or 0.0)) if r.success_ci else 0.0 for r in ran]
        ax.barh(
            ys,
            rates,
            height=0.6,
            xerr=[lo, hi],
            color="C0",
            capsize=2.0,
            error_kw={"elinewidth": 0.9, "ecolor": "0.25"},
        )
        for y, r, rate, up in zip(ys, ran, rates, hi, strict=True):
            ax.text(rate + up + 1.5, y, f"{r.successes}/{r.runs}", va="center", fontsize="x-small")
        sy = [len(ran) + i for i in range(len(skipped))]
        if skipped:
            ax.barh(sy, [100.0] * len(skipped), height=0.6, color="0.95", edgecolor="0.6", hatch="///", lw=0.5)
            for y in sy:
                ax.text(50, y, _SKIPPED, ha="center", va="center", fontsize="x-small", color="0.25")
        ax.set_yticks(ys + sy, [r.planner for r in ran] + skipped, fontsize="small")
        ax.invert_yaxis()
        ax.set_xlim(0, 118)
        ax.set_xticks(range(0, 101, 20))
        ax.set_xlabel("success rate (%), 95 % Wilson CI")
        ax.set_title(s, fontsize="medium")
        ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    return fig


def _pareto(points: list[tuple[str, float, float]]) -> set[str]:
    """The planners no other beats on both (at least as successful and fast, better in one); one that never
    succeeds is no trade-off, however fast."""
    front = set()
    for name, t, rate in points:
        if rate > 0 and not any(
            (t2 <= t and r2 >= rate) and (t2 < t or r2 > rate) for n2, t2, r2 in points if n2 != name
        ):
            front.add(name)
    return front


def _front_line(ax: Axes, on: list[tuple[float, float]], right: float) -> None:
    """The Pareto front as the dashed edge of what it dominates: up from 0 % at the fastest planner on it,
    across to the next one's time, up to its rate, ..., and across to the axis' right edge at the best rate
    (anything below and right of the line is beaten on both); drawn for a front of one planner too."""
    xs: list[float] = []
    ys: list[float] = []
    below = 0.0
    for t, rate in on:  # by time: each next one on the front is slower and more successful
        xs += [t, t]
        ys += [below, rate]
        below = rate
    ax.plot([*xs, max(right, xs[-1])], [*ys, below], color="0.3", lw=1, ls="--", zorder=1, label="Pareto front")


def _tradeoff(plt: Any, rows: list[dict[str, Any]], summary: Summary, order: list[str]) -> Figure | None:
    """Per scenario, success rate against median planning time (the choice a user makes): a point per
    planner with both intervals; the Pareto front (nobody both faster and at least as successful) outlined,
    named and joined by a dashed line; a planner that never succeeds is off the front, however fast, and
    the panel says so."""
    panels = []
    for scenario, kind in _scenarios(rows, summary):
        key = BOX_PLOTS[0].keys.get(kind)
        pts = []
        for p in order:
            row = summary.row(p, scenario)
            st = row.stats.get(key) if row is not None and key is not None else None
            if row is not None and row.runs and st is not None and st.median:
                pts.append((row, st))
        if pts and key is not None:
            panels.append((scenario, key, pts))
    if not panels:
        return None
    fig, axes = _panels(plt, [4.6] * len(panels), width=6.8)
    style = {p: (f"C{i % 10}", _MARKERS[(i // 10) % len(_MARKERS)]) for i, p in enumerate(order)}
    for ax, (scenario, key, pts) in zip(axes, panels, strict=True):
        front = _pareto([(r.planner, st.median or 0.0, r.success_rate or 0.0) for r, st in pts])
        on = sorted(((st.median or 0.0, 100 * (r.success_rate or 0.0)) for r, st in pts if r.planner in front))
        for r, st in pts:
            rate = 100 * (r.success_rate or 0.0)
            med = st.median or 0.0
            xerr = [[med - st.ci[0]], [st.ci[1] - med]] if st.ci else None
            yerr = [[rate - 100 * r.success_ci[0]], [100 * r.success_ci[1] - rate]] if r.success_ci else None
            color, marker = style[r.planner]
            best = r.planner in front
            ax.errorbar(
                [med],
                [rate],
                xerr=xerr,
                yerr=yerr,
                fmt=marker,
                ms=9 if best else 6,
                color=color,
                mec="black" if best else color,
                mew=1.4 if best else 0.8,
                elinewidth=0.6,
                capsize=1.5,
                alpha=0.9,
                zorder=3,
            )
            if best:
                ax.annotate(r.planner, (med, rate), xytext=(6, -12), textcoords="offset points", fontsize=7)
        ax.set_xscale("log")
        left, right = ax.get_xlim()
        if on:
            _front_line(ax, on, right)
        ax.set_xlim(left, right)
        _log_ticks(ax.xaxis)
        never = [r.planner for r, _ in pts if not r.success_rate]
        if never:
            ax.text(
                0.98,
                0.04,
                f"0 % success: off the front, however fast ({len(never)} planner{'s' if len(never) > 1 else ''})",
                transform=ax.transAxes,
                ha="right",
                va="bottom",
                fontsize="x-small",
                color="0.25",
                bbox={"boxstyle": "round,pad=0.25", "fc": "white", "ec": "0.7", "lw": 0.5},
            )
        ax.set_ylim(0, 108)
        ax.set_yticks(range(0, 101, 20))
        ax.set_xlabel("median " + _AXIS.get(key, key) + ", 95 % CI")
        ax.set_ylabel("success rate (%), 95 % Wilson CI")
        ax.set_title(scenario, fontsize="medium")
        ax.grid(alpha=0.3)
    from matplotlib.lines import Line2D

    shown = list(dict.fromkeys(r.planner for _, _, pts in panels for r, _ in pts))
    labels = {p: Line2D([], [], ls="", marker=style[p][1], color=style[p][0], ms=6) for p in shown}
    labels["Pareto front"] = Line2D([], [], color="0.3", lw=1, ls="--")
    ncol = min(len(labels), 5)
    fig.legend(list(labels.values()), list(labels), loc="lower center", ncol=ncol, frameon=False, fontsize="small")
    fig.suptitle(
        "named and outlined: on the Pareto front (dashed): no other planner is both faster and at least as "
        "successful;\na planner that never succeeds (0 %) is off the front, however fast",
        fontsize="small",
        y=1 - 0.08 / fig.get_figheight(),
        va="top",
    )
    legend_in = 0.25 + 0.2 * math.ceil(len(labels) / ncol)  # the legend's height, in inches
    fig.tight_layout(rect=(0, legend_in / fig.get_figheight(), 1, 1))
    return fig


def comparison_figures(
    rows: Iterable[dict[str, Any]], *, planners: Sequence[str] | None = None, summary: Summary | None = None
) -> dict[str, Figure]:
    """The figures write_plots saves, by file stem: 'success_heatmap', 'success' (per scenario bars),
    'tradeoff' (success against planning time) and BOX_PLOTS' stems, each only where it has values; the
    caller closes them. `summary` (of the same rows) gives the intervals and the skipped pairs; without it
    they are summarised here (and nothing is known to be skipped)."""
    plt = _pyplot()
    rows = [r for r in rows if r.get("status") != "skipped"]
    order = list(planners or [])
    order += sorted({r["planner"] for r in rows} - set(order))
    if summary is None:
        summary = summarize(rows, planners=order)
    order += [p for p, _ in summary.skipped_pairs if p not in order]
    scenarios = [s for s, _ in _scenarios(rows, summary)]
    figs: dict[str, Figure] = {}
    if scenarios:
        figs["success_heatmap"] = _heatmap(plt, summary, order, scenarios)
        figs["success"] = _success_bars(plt, summary, order, scenarios)
    trade = _tradeoff(plt, rows, summary, order)
    if trade is not None:
        figs["tradeoff"] = trade
    figs.update(_box_figures(plt, rows, summary, order))
    return figs


def _level_x(points: list[SweepPoint]) -> tuple[dict[str, float], bool]:
    """x of each level (by its text): the value itself when every level is a number, else 0, 1, 2, ..."""
    texts = list(dict.fromkeys(p.value_text for p in points))
    values = {p.value_text: p.value for p in points}
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values.values()):
        return {t: float(values[t]) for t in texts}, True
    return {t: float(i) for i, t in enumerate(texts)}, False


def sweep_figures(summary: Summary) -> dict[str, Figure]:
    """One figure per swept key, by file stem 'sweep_<key>': a column per scenario that sweeps it, the
    success rate (%) against the level on top and the median time (cycle time per placed object for task
    runs, trajectory duration for queries) below, one line per planner with its 95 % band. The caller
    closes them. No sweep, no figures."""
    plt = _pyplot()
    figs: dict[str, Figure] = {}
    planners = list(dict.fromkeys(p.planner for p in summary.sweeps))
    color = {p: f"C{i % 10}" for i, p in enumerate(planners)}
    marker = {p: _MARKERS[i % len(_MARKERS)] for i, p in enumerate(planners)}
    for key in dict.fromkeys(p.key for p in summary.sweeps):
        scenarios = list(dict.fromkeys(p.scenario for p in summary.sweeps if p.key == key))
        fig, axes = plt.subplots(
            2, len(scenarios), figsize=(5.5 * len(scenarios) + 0.5, 7.8), squeeze=False, sharex="col"
        )
        for col, scenario in enumerate(scenarios):
            pts = [p for p in summary.sweeps if p.key == key and p.scenario == scenario]
            xs, numeric = _level_x(pts)
            span = (max(xs.values()) - min(xs.values())) or 1.0
            here = list(dict.fromkeys(p.planner for p in pts))
            top, bottom = axes[0][col], axes[1][col]
            for j, planner in enumerate(here):
                mine = sorted((p for p in pts if p.planner == planner), key=lambda p: xs[p.value_text])
                shift = (j - (len(here) - 1) / 2) * _DODGE * span
                x = [xs[p.value_text] + shift for p in mine]
                rate = [100.0 * p.success_rate if p.success_rate is not None else math.nan for p in mine]
                lo = [100.0 * p.success_ci[0] if p.success_ci else math.nan for p in mine]
                hi = [100.0 * p.success_ci[1] if p.success_ci else math.nan for p in mine]
                style = {"color": color[planner], "marker": marker[planner], "ms": 5, "lw": 1.4}
                top.plot(x, rate, label=planner, **style)
                top.fill_between(x, lo, hi, color=color[planner], alpha=0.07, lw=0)
                med = [p.time.median if p.time.median is not None else math.nan for p in mine]
                tlo = [p.time.ci_low if p.time.ci_low is not None else math.nan for p in mine]
                thi = [p.time.ci_high if p.time.ci_high is not None else math.nan for p in mine]
                bottom.plot(x, med, label=planner, **style)
                bottom.fill_between(x, tlo, thi, color=color[planner], alpha=0.10, lw=0)
            top.set_ylim(-4, 104)
            top.set_yticks(range(0, 101, 20))
            top.set_title(f"{scenario}: success rate")
            top.set_ylabel("success rate (%), 95 % Wilson band")
            time_key = pts[0].time_key
            bottom.set_title(f"{scenario}: median {_TIME_LABELS.get(time_key, time_key).split(' (')[0]}")
            bottom.set_ylabel(_TIME_LABELS.get(time_key, time_key) + ", 95 % bootstrap CI")
            bottom.set_xlabel(key)
            ticks = list(xs.values())
            bottom.set_xticks(ticks, list(xs) if not numeric else [f"{v:g}" for v in ticks])
            bottom.set_ylim(bottom=0.0)  # a time is read as a ratio: from zero, so noise does not look like an effect
            for ax in (top, bottom):
                ax.grid(alpha=0.3)
        handles, labels = axes[0][0].get_legend_handles_labels()
        for ax in axes[0][1:]:
            for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
                if lab not in labels:
                    handles.append(h)
                    labels.append(lab)
        fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 6), frameon=False, fontsize="small")
        fig.suptitle(f"sweep of {key} (other swept keys at their nominal value)")
        fig.tight_layout(rect=(0, 0.05, 1, 1))
        figs[f"sweep_{key}"] = fig
    return figs


def write_plots(
    rows: Iterable[dict[str, Any]],
    out_dir: str | Path,
    *,
    planners: Sequence[str] | None = None,
    summary: Summary | None = None,
) -> list[Path]:
    """Write DIR/planning_time.png, duration.png, clearance.png (box plots with the median's 95 % bootstrap
    interval and n; a planner with no value is shown empty), DIR/success.png (bars with the success rate's
    95 % Wilson interval) and, for a sweep, DIR/sweep_<key>.png per swept key (`sweep_figures`); returns the
    paths written. Pass the `summary` of the same rows to reuse its intervals."""
    plt = _pyplot()
    out = Path(out_dir)
    rows = [r for r in rows if r.get("status") != "skipped"]
    if summary is None:
        order = list(planners or [])
        summary = summarize(rows, planners=order + sorted({r["planner"] for r in rows} - set(order)))
    figs = comparison_figures(rows, planners=planners, summary=summary)
    figs.update(sweep_figures(summary))
    written: list[Path] = []
    try:
        for stem, fig in figs.items():
            path = out / f"{stem}.png"
            fig.savefig(path, dpi=110)
            written.append(path)
    except OSError as e:
        raise ConfigError(f"cannot write plots in {out}: {e.strerror}") from None
    finally:
        for fig in figs.values():
            plt.close(fig)
    return written
