"""PNG plots of a comparison: box plots of planning time, duration and clearance per planner, and
success-rate bars per planner and scenario. The only module of twin that imports matplotlib (Agg, so it
works headless), and only when called.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from twin.errors import ConfigError, DependencyMissing

__all__ = ["BOX_PLOTS", "write_plots"]

log = logging.getLogger("twin")

# file stem, metric key, axis label, log scale
BOX_PLOTS: tuple[tuple[str, str, str, bool], ...] = (
    ("planning_time", "planning_time_s", "planning time (s)", True),
    ("duration", "duration_s", "trajectory duration (s)", False),
    ("clearance", "min_clearance_m", "minimum clearance to the environment (m)", False),
)


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


def write_plots(
    rows: Iterable[dict[str, Any]], out_dir: str | Path, *, planners: Sequence[str] | None = None
) -> list[Path]:
    """Write DIR/planning_time.png, duration.png, clearance.png (box plots; a planner with no value is
    shown empty) and DIR/success.png; returns the paths written."""
    plt = _pyplot()
    rows = [r for r in rows if r.get("status") != "skipped"]
    order = list(planners or [])
    order += sorted({r["planner"] for r in rows} - set(order))
    out = Path(out_dir)
    written: list[Path] = []
    width = max(6.0, 1.2 * len(order) + 2.0)
    try:
        for stem, key, label, log_scale in BOX_PLOTS:
            data = [[v for r in rows if r["planner"] == p and (v := _value(r, key)) is not None] for p in order]
            fig, ax = plt.subplots(figsize=(width, 4.5))
            if any(data):
                ax.boxplot([d or [float("nan")] for d in data], showfliers=True)
                ax.set_xticks(range(1, len(order) + 1), order, rotation=20, ha="right")
                if log_scale and all(v > 0 for d in data for v in d):
                    ax.set_yscale("log")
            else:
                ax.text(0.5, 0.5, "no values", ha="center", va="center", transform=ax.transAxes)
            ax.set_ylabel(label)
            ax.set_title(f"{label.split(' (')[0]} per planner")
            ax.grid(axis="y", alpha=0.3)
            fig.tight_layout()
            path = out / f"{stem}.png"
            fig.savefig(path, dpi=110)
            plt.close(fig)
            written.append(path)

        scenarios = list(dict.fromkeys(r["scenario"] for r in rows))
        fig, ax = plt.subplots(figsize=(width, 4.5))
        n = max(1, len(scenarios))
        bar = 0.8 / n
        for j, s in enumerate(scenarios):
            rates = []
            for p in order:
                sel = [r for r in rows if r["planner"] == p and r["scenario"] == s]
                rates.append(100.0 * sum(1 for r in sel if r.get("success")) / len(sel) if sel else 0.0)
            ax.bar([i - 0.4 + bar * (j + 0.5) for i in range(len(order))], rates, width=bar, label=s)
        ax.set_xticks(range(len(order)), order, rotation=20, ha="right")
        ax.set_ylim(0, 119)  # room above 100 % for the legend
        ax.set_yticks(range(0, 101, 20))
        ax.set_ylabel("success rate (%)")
        ax.set_title("success rate per planner and scenario")
        if scenarios:
            ax.legend(fontsize="small", loc="upper center", ncol=min(len(scenarios), 4), frameon=False)
        ax.grid(axis="y", alpha=0.3)
        fig.tight_layout()
        path = out / "success.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    except OSError as e:
        raise ConfigError(f"cannot write plots in {out}: {e.strerror}") from None
    return written
