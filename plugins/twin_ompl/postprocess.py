"""What happens to a path OMPL found: OMPL shortcutting in bounded passes (rope shortcut, reduceVertices,
collapseCloseVertices). Retiming and the final check of the timed trajectory are every path planner's
(`twin.plugin.timed_and_checked`)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import ompl.geometric as og

if TYPE_CHECKING:
    from twin_ompl.params import OmplParams

__all__ = ["simplify"]


def simplify(si: Any, path: Any, params: OmplParams, deadline: float) -> None:
    """OMPL shortcutting of `path` (an og.PathGeometric, changed in place) in at most `simplify_passes`
    bounded passes, none started after `deadline` (no wall-clock cut inside a pass, so seeded runs repeat)."""
    steps = params.simplify_max_steps
    ps = og.PathSimplifier(si)
    for _ in range(params.simplify_passes):
        if time.perf_counter() >= deadline:
            break
        # rope shortcutting does most of the work on a raw tree path; the others tidy what is left
        changed = ps.ropeShortcutPath(path)
        if time.perf_counter() < deadline and path.getStateCount() > 2:
            changed |= ps.reduceVertices(path, steps, max(1, steps // 2), 0.33)
        if time.perf_counter() < deadline and path.getStateCount() > 2:
            changed |= ps.collapseCloseVertices(path, steps, max(1, steps // 2))
        if not changed or path.getStateCount() <= 2:
            break
