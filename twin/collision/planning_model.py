"""The planning model: the robot's sphere cover against the scene's primitives, all compiled, no FCL.

Why: a sampling planner asks about tens of thousands of configurations; FCL behind Python costs ~50 us
each, the compiled sphere check ~1-4 us and nothing per call when the planner itself is compiled. Here
"touching" means "in collision": a configuration is free only when the spheres prove it free, so every
configuration this model calls free FCL calls free too (the covers enclose their shapes,
`twin.robot.sphere_cover`); the converse is not true. What the model costs is its overshoot: a cover reaches
at most `overshoot_bound_m` beyond the shape it covers (a box cell's sphere (sqrt(3) - 1) / 2 of the cell
side beyond the cell's face, a cylinder slab's `SLACK_M`), so a configuration closer than that to
something may be refused although it is free.

The judge does not move: every path planned on this model is re-checked by the exact FCL scene before it
counts (`twin.planning.checked.CheckedPlanner`'s final check). Start and goal states are the caller's to
check exactly: a state FCL calls free that the model calls touching is for the planner to leave along an
exactly checked way (`leave_cover`).

A model is a snapshot of its scene (the held object, the finger opening and the boxes as they were when it
was made: `PlanningScene.sphere_model`). Compiled planners call the kernels with `kernel` and `scratch`
directly (`twin.plugin`: `sphere_evaluate`, `first_touch_on_motion`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from twin.errors import InvalidRequestError
from twin.robot.sphere_cover import CELL_M, SLACK_M

__all__ = ["CONTINUOUS_FLOOR_M", "OVERSHOOT_BOUND_M", "SphereModel", "leave_cover"]

# how far a cover reaches beyond its shape at most: a box cell's circumscribed sphere beyond the middle of the
# cell's face (cell side <= CELL_M), a cylinder slab's sphere beyond the cylinder (SLACK_M); m
OVERSHOOT_BOUND_M = max(0.5 * (math.sqrt(3.0) - 1.0) * CELL_M, SLACK_M)
# a continuous motion check calls a motion touching where the spheres come this close (the advancement's
# steps shrink with the distance: closer, it would crawl), m
CONTINUOUS_FLOOR_M = 1e-4


class SphereModel:
    """Collision queries on the sphere model alone (see the module docstring). One caller at a time: the
    scratch arrays are shared with the scene that made the model."""

    overshoot_bound_m = OVERSHOOT_BOUND_M

    def __init__(self, kernel: tuple[Any, ...], scratch: tuple[Any, ...]):
        from twin.collision import sphere_kernel  # lazy: numba (compiled on first use)

        self.kernel = kernel
        self.scratch = scratch
        self._evaluate = sphere_kernel.sphere_evaluate
        self._flags = sphere_kernel.flag_configurations
        self._first = sphere_kernel.first_flagged
        self._motion = sphere_kernel.first_flagged_motion
        self._continuous = sphere_kernel.first_touch_on_motion
        self._polyline = sphere_kernel.first_unproven_on_polyline
        self._distance_bounds = sphere_kernel.clearance_bounds

    def with_touch(self, touch_m: float) -> SphereModel:
        """The same model calling a sphere touching within `touch_m` of anything (default `TOUCH_M`, 10 um):
        a search on it keeps its states that far from touching, so a continuous check of the motions
        between them (which refuses within `CONTINUOUS_FLOOR_M`) does not start from a state it refuses."""
        if not (math.isfinite(touch_m) and touch_m > 0):
            raise InvalidRequestError(f"touch_m must be > 0, got {touch_m}")
        from twin.collision.sphere_kernel import TOUCH_SLOT  # lazy: numba (compiled on first use)

        k = self.kernel
        return SphereModel((*k[:TOUCH_SLOT], float(touch_m), *k[TOUCH_SLOT + 1 :]), self.scratch)

    def in_collision(self, q: np.ndarray) -> bool:
        """True unless the spheres prove q (6,) free."""
        return bool(self._evaluate(self.kernel, self.scratch, _vector(q))[0])

    def in_collision_batch(self, qs: np.ndarray) -> np.ndarray:
        """(n,) bool for (n, 6) configurations, as `in_collision`."""
        qs = np.array(qs, dtype=float, order="C", ndmin=2)
        if qs.ndim != 2 or qs.shape[1] != 6:
            raise InvalidRequestError(f"qs must be (n, 6) joint angles, got shape {qs.shape}")
        out = np.empty(qs.shape[0], dtype=bool)
        self._flags(self.kernel, self.scratch, qs, out)
        return out

    def first_collision(self, qs: np.ndarray) -> int | None:
        """Index of the first configuration of (n, 6) qs the model calls touching (in their order, early
        exit), or None: `PlanningScene.first_collision` on the model."""
        qs = np.array(qs, dtype=float, order="C", ndmin=2)
        if qs.ndim != 2 or qs.shape[1] != 6:
            raise InvalidRequestError(f"qs must be (n, 6) joint angles, got shape {qs.shape}")
        i = int(self._first(self.kernel, self.scratch, qs))
        return None if i < 0 else i

    def first_collision_on_motion(self, a: np.ndarray, b: np.ndarray, resolution_rad: float) -> float | None:
        """The straight joint motion a -> b checked every `resolution_rad` (max-abs; b included, a not),
        coarse to fine in one compiled call: the fraction of the motion where a configuration touches, or
        None when the whole motion is free."""
        if not (math.isfinite(resolution_rad) and resolution_rad > 0):
            raise InvalidRequestError(f"resolution_rad must be > 0, got {resolution_rad}")
        a, b = _vector(a), _vector(b)
        k = self._motion(self.kernel, self.scratch, a, b, float(resolution_rad))
        if k == 0:
            return None
        n = max(1, math.ceil(float(np.abs(b - a).max()) / resolution_rad - 1e-9))
        return k / n

    def motion_free(self, a: np.ndarray, b: np.ndarray, resolution_rad: float) -> bool:
        """True when every configuration of a -> b, `resolution_rad` apart, is free in the model."""
        return self.first_collision_on_motion(a, b, resolution_rad) is None

    def distance_bounds(self, qs: np.ndarray, parts: np.ndarray) -> np.ndarray:
        """(n,) lower bounds on the distance from the robot's parts `parts` (int64 indices, as the kernels number
        them) to the environment at each configuration of (n, 6) qs, capped at 0.25 m; -inf where the covers
        touch. Exact distances (FCL's) are never below them."""
        qs = np.array(qs, dtype=float, order="C", ndmin=2)
        out = np.empty(qs.shape[0])
        self._distance_bounds(self.kernel, self.scratch, qs, np.asarray(parts, dtype=np.int64), out)
        return out

    def first_unproven_segment(self, qs: np.ndarray, floor_m: float = CONTINUOUS_FLOOR_M) -> int | None:
        """The polyline through (n, 6) configurations (a timed trajectory's samples) checked continuously in
        one pass (each evaluated configuration's distance bounds spent along as many segments as they cover):
        None when the spheres prove all of it free (then FCL agrees at any point of it), else the index of the
        first segment they cannot prove."""
        if not (math.isfinite(floor_m) and floor_m > 0):
            raise InvalidRequestError(f"floor_m must be > 0, got {floor_m}")
        qs = np.array(qs, dtype=float, order="C", ndmin=2)
        if qs.ndim != 2 or qs.shape[1] != 6 or not np.isfinite(qs).all():
            raise InvalidRequestError(f"qs must be finite (n, 6) joint angles, got shape {qs.shape}")
        i = int(self._polyline(self.kernel, self.scratch, qs, float(floor_m)))
        return None if i < 0 else i

    def first_touch_continuous(self, a: np.ndarray, b: np.ndarray, floor_m: float = CONTINUOUS_FLOOR_M) -> float | None:
        """The straight joint motion a -> b checked continuously (conservative advancement: every
        configuration on it, a and b included, proven free by the distance bounds of the configurations
        evaluated): None when it is free, else the fraction of the motion where the spheres come within
        `floor_m` of touching. A motion this calls free FCL calls free at any resolution."""
        if not (math.isfinite(floor_m) and floor_m > 0):
            raise InvalidRequestError(f"floor_m must be > 0, got {floor_m}")
        t = self._continuous(self.kernel, self.scratch, _vector(a), _vector(b), float(floor_m))
        return None if t < 0 else float(t)


def leave_cover(
    q: np.ndarray,
    toward: np.ndarray,
    model: SphereModel,
    exact_free: Callable[[np.ndarray], bool],
    resolution_rad: float,
    *,
    max_rad: float = 0.5,
) -> np.ndarray | None:
    """A configuration the model calls free on the straight way from q toward `toward`, every configuration
    up to it free by `exact_free` (FCL) checked `resolution_rad` apart; None when there is none within
    `max_rad` (max-abs) of q, or when q itself is not free by `exact_free`.

    Why: a start (or goal) FCL calls free may lie closer to something than the cover's overshoot, where the
    model calls it touching; a planner on the model could never leave it. The way out is judged by the exact
    model, and the planner starts (or ends) beyond it."""
    q, toward = _vector(q), _vector(toward)
    d = toward - q
    span = float(np.abs(d).max())
    if span == 0.0 or not exact_free(q):
        return None
    reach = min(1.0, max_rad / span)
    n = max(1, math.ceil(reach * span / resolution_rad - 1e-9))
    for k in range(1, n + 1):
        p = q + (reach * k / n) * d
        if not exact_free(p):
            return None
        if not model.in_collision(p):
            return p
    return None


def _vector(q: np.ndarray) -> np.ndarray:
    """q as a writeable C-contiguous float64 (6,) (one compiled specialisation)."""
    v = np.array(q, dtype=float, order="C").reshape(-1)
    if v.shape != (6,):
        raise InvalidRequestError(f"a configuration is 6 joint angles, got shape {np.shape(q)}")
    if not np.isfinite(v).all():
        raise InvalidRequestError(f"joint angles must be finite, got {v.tolist()}")
    return v
