"""What happens to a path OMPL found: shortcutting, retiming, and the final check of the timed trajectory.

1. OMPL shortcutting in bounded passes (rope shortcut, reduceVertices, collapseCloseVertices);
2. a retimer plugin times the waypoints;
3. the trajectory is checked every `verify_resolution_rad` / `verify_resolution_m` on the planning scene.
   When it collides, the geometric path is checked at the same resolution: a straight segment that grazes
   something between the states checked while planning is reported (the planner plans that segment again),
   and when only the timing spline cuts a corner, the path is re-timed through denser waypoints
   (`twin.plugin.densify_path`, 0.02 then 0.005 rad apart).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np
import ompl.geometric as og

from twin.plugin import TwinError, colliding_pair, densify_path
from twin_ompl.validity import trajectory_check_points

if TYPE_CHECKING:
    from twin.plugin import MotionRequest, PlanningScene, Retimer, Trajectory, URArm
    from twin_ompl.params import OmplParams

__all__ = ["add_time", "path_length", "simplify", "timed_and_checked"]

# waypoint spacings (rad) tried in turn when the timed trajectory cuts a corner of a free path; None: as planned
_RETIME_SPACINGS: tuple[float | None, ...] = (None, 0.02, 0.005)


def add_time(timings: dict[str, float], key: str, since: float) -> None:
    """Add the seconds since `since` (a perf_counter reading) to `timings[key]`."""
    timings[key] = timings.get(key, 0.0) + time.perf_counter() - since


def path_length(path: np.ndarray) -> float:
    """Joint-space length of a waypoint path (m, 6): sum of the L2 norms of its segments, rad."""
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) if path.shape[0] > 1 else 0.0


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


def timed_and_checked(
    path: np.ndarray,
    retimer: Retimer,
    request: MotionRequest,
    scene: PlanningScene,
    kin: URArm,
    params: OmplParams,
    timings: dict[str, float],
) -> tuple[Trajectory | None, str, int | None]:
    """Time `path` (m, 6) with `retimer` under the request's limits and check it on `scene`.

    (trajectory, "ok", None) when the timed path passes the final check; else (None, why, segment) with
    `segment` the index of a straight path segment that itself collides (None: the path is free but its
    timing spline cuts a corner even through a denser path, or retiming failed). Adds "retime" and
    "verify" seconds to `timings`."""
    last = ""
    for spacing in _RETIME_SPACINGS:
        P = path if spacing is None else densify_path(path, spacing)
        t = time.perf_counter()
        try:
            traj = retimer.retime(P, request.limits)
        except TwinError as e:
            add_time(timings, "retime", t)
            return None, f"retiming failed: {e}", None
        add_time(timings, "retime", t)
        if params.verify_resolution_rad <= 0:
            return traj, "ok", None
        t = time.perf_counter()
        qs = trajectory_check_points(traj, kin, params.verify_resolution_rad, params.verify_resolution_m)
        hit = scene.first_collision(qs)
        if hit is None:
            add_time(timings, "verify", t)
            return traj, "ok", None
        # the path itself (missed between the states checked while planning) or the spline's corner?
        check = scene.check_path(path, resolution_rad=params.verify_resolution_rad)
        add_time(timings, "verify", t)
        if not check.free:
            assert check.segment is not None
            return None, f"path segment {check.segment} collides at {params.verify_resolution_rad:g} rad", check.segment
        last = f"the timed trajectory collides ({colliding_pair(scene, qs[hit])}) while its path is free"
    return None, last, None
