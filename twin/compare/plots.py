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
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.errors import ConfigError, DependencyMissing

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from twin.compare.report import Summary, SweepPoint

__all__ = ["BOX_PLOTS", "comparison_figures", "sweep_figures", "write_plots"]

log = logging.getLogger("twin")

# file stem, metric key, axis label, log scale
BOX_PLOTS: tuple[tuple[str, str, str, bool], ...] = (
    ("planning_time", "planning_time_s", "planning time (s)", True),
    ("duration", "duration_s", "trajectory duration (s)", False),
    ("clearance", "min_clearance_m", "minimum clearance to the environment (m)", False),
)
_CI_OFFSET = 0.33  # the median's interval is drawn this far right of its box (boxes are 0.5 wide)
_DODGE = 0.012  # sweep lines are shifted sideways by this share of the x range per planner, so equal ones show
_MARKERS = "osD^vP*Xh<>p"
_TIME_LABELS = {"cycle_time_s": "cycle time per placed object (s)", "duration_s": "trajectory duration (s)"}


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


def comparison_figures(
    rows: Iterable[dict[str, Any]], *, planners: Sequence[str] | None = None, summary: Summary | None = None
) -> dict[str, Figure]:
    """The figures write_plots saves, by file stem (BOX_PLOTS' stems and 'success'); the caller closes
    them. `summary` (of the same rows) gives the intervals; without it they are summarised here."""
    from twin.compare.report import ALL, summarize

    plt = _pyplot()
    rows = [r for r in rows if r.get("status") != "skipped"]
    order = list(planners or [])
    order += sorted({r["planner"] for r in rows} - set(order))
    if summary is None:
        summary = summarize(rows, planners=order)
    figs: dict[str, Figure] = {}
    width = max(6.0, 1.2 * len(order) + 2.0)
    for stem, key, label, log_scale in BOX_PLOTS:
        data = [[v for r in rows if r["planner"] == p and (v := _value(r, key)) is not None] for p in order]
        fig, ax = plt.subplots(figsize=(width, 4.5))
        if any(data):
            ax.boxplot([d or [float("nan")] for d in data], showfliers=True)
            ticks = [f"{p}\n(n={len(d)})" for p, d in zip(order, data, strict=True)]  # n beside each median
            ax.set_xticks(range(1, len(order) + 1), ticks, rotation=20, ha="right")
            if log_scale and all(v > 0 for d in data for v in d):
                ax.set_yscale("log")
            x, med, lo, hi = [], [], [], []
            for i, p in enumerate(order, start=1):
                row = summary.row(p, ALL)
                st = row.stats[key] if row is not None else None
                if st is not None and st.median is not None and st.ci is not None:
                    x.append(i + _CI_OFFSET)
                    med.append(st.median)
                    lo.append(st.median - st.ci[0])
                    hi.append(st.ci[1] - st.median)
            if x:
                ax.errorbar(
                    x,
                    med,
                    yerr=[lo, hi],
                    fmt="D",
                    ms=3.5,
                    color="C3",
                    capsize=3,
                    lw=1.2,
                    label="median, 95 % bootstrap CI",
                )
                ax.legend(fontsize="small", loc="best", frameon=False)
        else:
            ax.text(0.5, 0.5, "no values", ha="center", va="center", transform=ax.transAxes)
        ax.set_ylabel(label)
        ax.set_title(f"{label.split(' (')[0]} per planner")
        ax.grid(axis="y", alpha=0.3)
        fig.tight_layout()
        figs[stem] = fig

    scenarios = list(dict.fromkeys(r["scenario"] for r in rows))
    fig, ax = plt.subplots(figsize=(width, 4.5))
    n = max(1, len(scenarios))
    bar = 0.8 / n
    for j, s in enumerate(scenarios):
        rates, err_lo, err_hi = [], [], []
        for p in order:
            row = summary.row(p, s)
            rate = row.success_rate if row is not None else None
            ci = row.success_ci if row is not None else None
            # no runs (a skipped pair): no bar, which a 0 % bar would misreport as a planner that failed
            rates.append(100.0 * rate if rate is not None else math.nan)
            err_lo.append(100.0 * (rate - ci[0]) if rate is not None and ci is not None else math.nan)
            err_hi.append(100.0 * (ci[1] - rate) if rate is not None and ci is not None else math.nan)
        ax.bar(
            [i - 0.4 + bar * (j + 0.5) for i in range(len(order))],
            rates,
            width=bar,
            label=s,
            yerr=[err_lo, err_hi],
            capsize=2.0,
            error_kw={"elinewidth": 0.9, "ecolor": "0.25"},
        )
    ax.set_xticks(range(len(order)), order, rotation=20, ha="right")
    ax.set_ylim(0, 119)  # room above 100 % for the legend
    ax.set_yticks(range(0, 101, 20))
    ax.set_ylabel("success rate (%), 95 % Wilson CI")
    ax.set_title("success rate per planner and scenario")
    if scenarios:
        ax.legend(fontsize="small", loc="upper center", ncol=min(len(scenarios), 4), frameon=False)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    figs["success"] = fig
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
    from twin.compare.report import summarize

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
