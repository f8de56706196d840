"""summary.html: the comparison as one page a person reads in a browser and can mail on: summary.md's
sections (who wins on what first), the plots embedded (no files beside it needed), each with a line on
what it shows, and the replay commands. Markdown is rendered by markdown-it-py (rich's own dependency)."""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence
from pathlib import Path

from twin.compare.report import summary_markdown
from twin.compare.summary import Summary
from twin.errors import ConfigError

__all__ = ["PLOT_CAPTIONS", "write_html"]

# what a reader learns from each plot, by file stem (a sweep's stem starts with "sweep_")
PLOT_CAPTIONS = {
    "success_heatmap": "Success rate per planner (rows, best overall first) and scenario (columns): the colour is "
    "the rate, the cell says successes/runs. A hatched cell was not run (the planner cannot serve that goal), "
    "which is not a 0 %.",
    "success": "Per scenario, each planner's success rate with its 95 % Wilson interval, best first, successes/runs "
    "at the bar. Wide intervals mean few runs: two planners whose intervals overlap are not shown to differ.",
    "tradeoff": "The choice a user makes: success rate against median planning time, per scenario. Outlined and named: "
    "no other planner is both at least as successful and faster (the Pareto front, dashed). A planner that never "
    "succeeds is off the front, however fast.",
    "planning_time": "Planning time per scenario (per query; per planned motion for task runs), most successful "
    "first, then fastest, its success rate and n beside each planner, the median's 95 % bootstrap interval in red.",
    "duration": "Trajectory duration per scenario, successful plans only (n says how many): a planner that solved "
    "only the easy queries can look fast here.",
    "clearance": "The smallest distance to the cell along each successful trajectory, per scenario, most "
    "successful first, then largest. A panel where every planner has the same value on each query says so: the "
    "paths share their closest point (the start or goal, or the same straight joint line).",
    "cycle_time": "Task runs: simulated time per placed object, per scenario, most successful first, then fastest.",
}
_SWEEP_CAPTION = (
    "One swept key: success rate (top) and median time (bottom, from zero) against its level, per planner with "
    "its 95 % band; the other swept keys at their nominal value."
)
_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1250px; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 2px 6px; }
th { background: #f2f2f2; }
tr:nth-child(even) td { background: #fafafa; }
code { background: #f3f3f3; padding: 0 3px; }
figure { margin: 1.2em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { color: #444; font-size: 0.9em; max-width: 60em; }
h2 { border-bottom: 1px solid #ddd; padding-bottom: 3px; margin-top: 1.6em; }
"""


def _caption(stem: str) -> str:
    if stem.startswith("sweep_"):
        return f"Sweep of {stem[len('sweep_') :]}. {_SWEEP_CAPTION}"
    return PLOT_CAPTIONS.get(stem, stem)


def _figures(plots: Sequence[Path]) -> str:
    parts = ["<h2>Plots</h2>"]
    for p in plots:
        data = base64.b64encode(p.read_bytes()).decode("ascii")
        parts.append(
            f'<figure id="{html.escape(p.stem)}"><img alt="{html.escape(p.name)}" src="data:image/png;base64,{data}">'
            f"<figcaption><b>{html.escape(p.name)}</b>: {html.escape(_caption(p.stem))}</figcaption></figure>"
        )
    return "\n".join(parts)


def write_html(summary: Summary, out_dir: str | Path, *, plots: Sequence[Path] = (), title: str = "") -> Path:
    """Write DIR/summary.html: summary.md's text as HTML with `plots` (PNG files) embedded after the
    "Who wins on what" section, each with its caption (PLOT_CAPTIONS); returns its path."""
    from markdown_it import MarkdownIt

    md = MarkdownIt("commonmark", {"html": False}).enable("table")
    text = summary_markdown(summary)
    head, sep, rest = text.partition("\n## Success\n")
    body = md.render(head) + (_figures(plots) if plots else "") + (md.render(sep + rest) if sep else "")
    name = html.escape(title or "planner comparison")
    page = (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{name}</title>'
        f"<style>{_STYLE}</style></head>\n<body>\n{body}\n</body></html>\n"
    )
    path = Path(out_dir) / "summary.html"
    try:
        path.write_text(page, encoding="utf-8")
    except OSError as e:
        raise ConfigError(f"cannot write {path}: {e.strerror}") from None
    return path
