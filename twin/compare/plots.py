"""PNG plots of a comparison: box plots of planning time, duration and clearance per planner, and
success-rate bars per planner and scenario. The only module of twin that imports matplotlib (Agg, so it
works headless), and only when called.

The plots show how sure the numbers are with the intervals of the summary (`report.summarize`, the
same percentile bootstrap, seeds and numbers as summary.md): each box carries a marker at its median
with the median's 95 % interval as an error bar beside it, each success bar the 95 % interval of its
success rate.
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

    from twin.compare.report import Summary

__all__ = ["BOX_PLOTS", "comparison_figures", "write_plots"]

log = logging.getLogger("twin")

# file stem, metric key, axis label, log scale
BOX_PLOTS: tuple[tuple[str, str, str, bool], ...] = (
    ("planning_time", "planning_time_s", "planning time (s)", True),
    ("duration", "duration_s", "trajectory duration (s)", False),
    ("clearance", "min_clearance_m", "minimum clearance to the environment (m)", False),
)
_CI_OFFSET = 0.33  # the median's interval is drawn this far right of its box (boxes are 0.5 wide)


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
            ax.set_xticks(range(1, len(order) + 1), order, rotation=20, ha="right")
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
                    x, med, yerr=[lo, hi], fmt="D", ms=3.5, color="C3", capsize=3, lw=1.2, label="median, 95 % CI"
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
    ax.set_ylabel("success rate (%), 95 % CI")
    ax.set_title("success rate per planner and scenario")
    if scenarios:
        ax.legend(fontsize="small", loc="upper center", ncol=min(len(scenarios), 4), frameon=False)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    figs["success"] = fig
    return figs


def write_plots(
    rows: Iterable[dict[str, Any]],
    out_dir: str | Path,
    *,
    planners: Sequence[str] | None = None,
    summary: Summary | None = None,
) -> list[Path]:
    """Write DIR/planning_time.png, duration.png, clearance.png (box plots with the median's 95 % interval;
    a planner with no value is shown empty) and DIR/success.png (bars with the success rate's 95 %
    interval); returns the paths written. Pass the `summary` of the same rows to reuse its intervals."""
    plt = _pyplot()
    out = Path(out_dir)
    figs = comparison_figures(rows, planners=planners, summary=summary)
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
