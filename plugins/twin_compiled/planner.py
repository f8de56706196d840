"""`compiled.rrtconnect`: RRT-Connect in compiled code on twin's planning model, then retimed and judged.

One `plan(request, scene)`:

1. the start and the goal as every path planner checks them (`twin.plugin.start_failure`, `goal_set`: exact,
   FCL), in the sampling bounds of `joint_range` (`twin.plugin.sampling_bounds`);
2. the planning model: the robot's sphere cover against the scene's primitives inflated by `clearance_m`
   (`PlanningScene.sphere_model`), touching = in collision, every motion proven free continuously; without
   the clearance when the start or every goal lies closer than it;
3. a start (or goal) FCL calls free but the search would not (closer to something than the cover's overshoot
   plus `search_margin_m`) is left along a straight way checked by FCL (`twin.plugin.leave_cover`), toward the
   other end first, then toward seeded random configurations; the search starts (ends) beyond it;
4. the search (with VAMP's tree balance and dynamic domain, `twin_compiled.search`) and the shortcutting,
   compiled, in calls of `iterations_per_call` iterations until they connect or the time limit, motions
   checked every `resolution_rad`;
5. every segment of the path is then proven free continuously (conservative advancement); one that cannot be
   is planned again with continuous checks inside its box widened by 0.3 rad and spliced in (`max_repairs`),
   so what reaches the judge is free in FCL everywhere, not only where it was sampled;
6. the retimer (`ruckig` by default, or the config block's `retimer:`) and the check of the timed trajectory
   (`twin.plugin.timed_and_checked`: proven free in one pass by the planning model, else checked by FCL; a
   spline that cuts a corner is timed again through denser waypoints).

Then `CheckedPlanner` judges the trajectory on the exact scene like every planner's.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.plugin import (
    MotionRequest,
    MotionResult,
    PathPlanner,
    PlanningScene,
    QueryEnds,
    Retimer,
    SphereModel,
    Status,
    URArm,
    add_time,
    jerk_limited,
    leave_cover,
    path_length,
    query_ends,
    timed_and_checked,
    warm_up_checks,
    warm_up_retimer,
)
from twin_compiled.nearest import new_index
from twin_compiled.params import CompiledParams
from twin_compiled.search import first_uncertified, grown, new_trees, rrt_connect, shortcut, tree_path

if TYPE_CHECKING:
    from twin.plugin import PluginContext

__all__ = ["CompiledRRTConnect"]


_ESCAPE_TRIES = 16  # random directions tried when the way toward the other end does not leave the cover
_ESCAPE_STEP_RAD = 0.002  # FCL checks the way out of the cover this often (max-abs joint step)
_COMPILED: list[bool] = []  # the search's compiled code is loaded in this process (once, by the first planner)
_FIRST_CAPACITY = 4096  # nodes per tree at first; doubled while the search needs more (up to max_nodes)
_REPAIR_MARGIN_RAD = 0.3  # a segment planned again is searched inside its box widened by this much per joint


class CompiledRRTConnect(PathPlanner):
    """RRT-Connect compiled end to end on the planning model (see the module docstring)."""

    Params = CompiledParams
    name = "compiled.rrtconnect"

    def __init__(self, params: CompiledParams | None, context: PluginContext):
        self.params = params if params is not None else CompiledParams()
        self.context = context
        self.kin: URArm = context.kinematics
        self._default_retimer: Retimer | None = None
        self._warm_up()

    def set_retimer(self, retimer: Retimer) -> None:
        """Use this retimer (the config block's `retimer:`) instead of `params.retimer`; warmed up at once."""
        super().set_retimer(retimer)
        self._warm_up()

    @property
    def jerk_limited(self) -> bool:
        """As jerk-limited as the retimer that times its paths."""
        return jerk_limited(self._timer())

    def _timer(self) -> Retimer:
        if self.retimer is not None:
            return self.retimer
        if self._default_retimer is None:
            self._default_retimer = self.context.registry.retimer(
                self.params.retimer, self.params.retimer_params, self.context
            )
        return self._default_retimer

    def _warm_up(self) -> None:
        """Compile (or load from numba's cache) the search and time one tiny path now, not inside a request's
        time limit (compiling takes seconds; loading ~0.1 s)."""
        if not _COMPILED:
            scene = PlanningScene(self.context.robot)  # the robot alone: every kernel's argument types
            model = scene.sphere_model()
            q = np.zeros(6)
            found = self._search(model, q, (q + 0.1)[None], np.array([[-1.0, 1.0]] * 6), 0, math.inf, 0.05)
            path = found[0] if isinstance(found[0], np.ndarray) else np.stack([q, q + 0.1])
            shortcut(model.kernel, model.scratch, path, 1, 0.05, 1e-4, new_trees(1, 0)[4])
            first_uncertified(model.kernel, model.scratch, path, 1e-4)
            _COMPILED.append(True)
        warm_up_checks(self.context.robot)  # the timed trajectory's proof (`timed_and_checked`)
        warm_up_retimer(self._timer())  # an unknown retimer name or bad retimer params fail here

    # ---- planning --------------------------------------------------------------------------------
    def plan(self, request: MotionRequest, scene: PlanningScene) -> MotionResult:
        """Plan `request` in `scene`; "no path" is a status with a reason, never an exception."""
        t0 = time.perf_counter()
        p = self.params
        limit = request.time_limit_s if p.time_limit_s is None else min(request.time_limit_s, p.time_limit_s)
        result = self._plan(request, scene, t0 + limit, limit)
        return replace(result, planning_time_s=time.perf_counter() - t0)

    def _plan(self, request: MotionRequest, scene: PlanningScene, deadline: float, limit: float) -> MotionResult:
        p, kin = self.params, self.kin
        info: dict[str, Any] = {"planner": self.name, "seed": request.seed}
        timings: dict[str, float] = {}
        ends = query_ends(kin, scene, request, p)
        if not isinstance(ends, QueryEnds):
            return MotionResult(ends[0], ends[1], info=info)
        start, bounds, goals = ends.start, ends.bounds, ends.goals

        t = time.perf_counter()
        model, clearance = self._model(scene, start, goals)
        # the search keeps search_margin_m from touching, and its ends too: an end closer than that (where the
        # continuous proof, which refuses within floor_m, could not leave it) is left along an FCL-checked way
        search_model = model.with_touch(p.search_margin_m)
        way_out = self._leave_the_cover(search_model, scene, start, goals, bounds, request.seed)
        add_time(timings, "model", t)
        if isinstance(way_out, str):
            return MotionResult(Status.NO_SOLUTION, way_out, info=_with_times(info, timings))
        head, first, lasts, tails = way_out
        info.update(
            goal_count=int(goals.shape[0]),
            clearance_m=clearance,
            escapes=int(head.shape[0] > 1) + sum(t.shape[0] > 1 for t in tails),
        )

        t = time.perf_counter()
        found = self._search(search_model, first, lasts, bounds, request.seed, deadline, p.resolution_rad)
        add_time(timings, "search", t)
        if isinstance(found[0], Status):
            return MotionResult(found[0], str(found[1]), info=_with_times(info, timings))
        middle, goal_index, rng = found
        t = time.perf_counter()
        if middle.shape[0] > 2:
            middle = shortcut(
                search_model.kernel, search_model.scratch, middle, p.shortcut_tries, p.resolution_rad, p.floor_m, rng
            )
        add_time(timings, "simplify", t)
        t = time.perf_counter()
        certified = self._certify(model, middle, bounds, request.seed, deadline, limit)
        if isinstance(certified, str) and time.perf_counter() < deadline:
            # the coarse search's path could not be proven free: search again, every motion proven as it is added
            found = self._search(model, first, lasts, bounds, request.seed + 1, deadline, 0.0)
            if isinstance(found[0], Status):
                return MotionResult(
                    Status.COLLISION, f"{certified}; {found[1]}", path=middle, info=_with_times(info, timings)
                )
            middle, goal_index, rng = found
            certified = (middle, p.max_repairs)
            info.update(searched_again=True)
        add_time(timings, "certify", t)
        if isinstance(certified, str):
            return MotionResult(Status.COLLISION, certified, path=middle, info=_with_times(info, timings))
        middle, repairs = certified
        info.update(repairs=repairs)
        path = np.vstack([head[:-1], middle, tails[goal_index][1:]])
        path[0] = start
        info.update(waypoints=int(path.shape[0]), path_length_rad=path_length(path), goal_index=goal_index)
        traj, outcome, _ = timed_and_checked(
            path, self._timer(), request, scene, kin, p.verify_resolution_rad, p.verify_resolution_m, timings
        )
        if traj is None:
            status = Status.LIMIT_VIOLATION if outcome.startswith("retiming failed") else Status.COLLISION
            return MotionResult(status, outcome, path=path, info=_with_times(info, timings))
        info = _with_times(info, timings)
        info.update(duration_s=traj.duration)
        return MotionResult(Status.SUCCESS, "ok", traj, path=path, info=info)

    def _certify(
        self, model: SphereModel, path: np.ndarray, bounds: np.ndarray, seed: int, deadline: float, limit: float
    ) -> tuple[np.ndarray, int] | str:
        """(path, repairs): every segment proven free continuously; a segment the continuous check cannot
        prove (the search checked configurations `resolution_rad` apart) is planned again with continuous
        checks and spliced in: inside its box widened by `_REPAIR_MARGIN_RAD` (a tenth of the time limit),
        then inside the whole bounds (a quarter). Or why not."""
        p = self.params
        repairs = 0
        while True:
            i = first_uncertified(model.kernel, model.scratch, path, p.floor_m)
            if i < 0:
                return path, repairs
            if repairs >= p.max_repairs:
                return f"path segment {i} is not proven free after {repairs} repairs"
            repairs += 1
            a, b = path[i], path[i + 1]
            box = np.stack(
                [
                    np.maximum(np.minimum(a, b) - _REPAIR_MARGIN_RAD, bounds[:, 0]),
                    np.minimum(np.maximum(a, b) + _REPAIR_MARGIN_RAD, bounds[:, 1]),
                ],
                axis=1,
            )
            found: tuple[Any, ...] = (Status.NO_SOLUTION, "")
            for where, share in ((box, 0.1), (bounds, 0.25)):
                until = min(deadline, time.perf_counter() + share * limit)
                found = self._search(model, a, b[None], where, seed + 7919 * repairs, until, 0.0)
                if not isinstance(found[0], Status):
                    break
            if isinstance(found[0], Status):
                return f"path segment {i} is not proven free and planning it again failed: {found[1]}"
            path = np.vstack([path[:i], found[0], path[i + 2 :]])

    def _step(self, bounds: np.ndarray) -> float:
        """The search's step (`range_rad`; None: 20% of the bounds' diagonal, as OMPL's default range)."""
        if self.params.range_rad is not None:
            return self.params.range_rad
        return 0.2 * float(np.linalg.norm(bounds[:, 1] - bounds[:, 0]))

    def _model(self, scene: PlanningScene, start: np.ndarray, goals: np.ndarray) -> tuple[SphereModel, float]:
        """The planning model with the clearance, unless the start or every goal lies closer than it."""
        c = self.params.clearance_m
        if c > 0:
            model = scene.sphere_model(c)
            if not model.in_collision(start) and not model.in_collision_batch(goals).all():
                return model, c
        return scene.sphere_model(), 0.0

    def _leave_the_cover(
        self,
        model: SphereModel,
        scene: PlanningScene,
        start: np.ndarray,
        goals: np.ndarray,
        bounds: np.ndarray,
        seed: int,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]] | str:
        """(head, first, lasts, tails): the way out of the cover from the start (head: start .. first), the
        search's goal roots (lasts (k, 6)) and the way from each back to its goal (tails[i]: lasts[i] .. goal
        i); or why an end cannot leave the cover. Ends the model frees need no way: head = [start]."""
        rng = np.random.default_rng(seed)

        def exact_free(q: np.ndarray) -> bool:
            return not scene.in_collision(q)

        def way_out(q: np.ndarray, toward: np.ndarray) -> np.ndarray | None:
            if not model.in_collision(q):
                return q
            targets = [toward] + [rng.uniform(bounds[:, 0], bounds[:, 1]) for _ in range(_ESCAPE_TRIES)]
            for target in targets:
                out = leave_cover(q, target, model, exact_free, _ESCAPE_STEP_RAD, max_rad=self.params.escape_rad)
                if out is not None:
                    return out
            return None

        first = way_out(start, goals[0])
        if first is None:
            return (
                f"the start lies within the sphere cover's overshoot ({model.overshoot_bound_m * 1e3:.1f} mm) and the "
                f"search margin of something and no straight way of {self.params.escape_rad:g} rad leaves it"
            )
        lasts, tails = [], []
        for g in goals:
            last = way_out(g, start)
            if last is not None:
                lasts.append(last)
                tails.append(np.vstack([last, g]) if last is not g else g[None])
        if not lasts:
            return (
                f"every goal lies within the sphere cover's overshoot ({model.overshoot_bound_m * 1e3:.1f} mm) and the "
                f"search margin of something and no straight way of {self.params.escape_rad:g} rad leaves it"
            )
        head = np.vstack([start, first]) if first is not start else start[None]
        return head, first, np.array(lasts), tails

    def _search(
        self,
        model: SphereModel,
        start: np.ndarray,
        goals: np.ndarray,
        bounds: np.ndarray,
        seed: int,
        deadline: float,
        resolution: float,
    ) -> tuple[np.ndarray, int, np.ndarray] | tuple[Status, str]:
        """(path start .. goal i, i, the random state) or (status, why not); motions checked every
        `resolution` rad (<= 0: continuously)."""
        p = self.params
        # what one iteration can add to a tree at most: the extension and a connect across the bounds
        span = float(np.linalg.norm(bounds[:, 1] - bounds[:, 0]))
        step = self._step(bounds)
        room = math.ceil(span / step) + 2
        capacity = min(p.max_nodes, max(_FIRST_CAPACITY, 4 * room, goals.shape[0] + room))
        nodes, parents, radii, counts, rng = new_trees(capacity, seed)
        index = new_index(capacity)
        nodes[0, :, 0] = start
        counts[0] = 1
        nodes[1, :, : goals.shape[0]] = goals.T
        counts[1] = goals.shape[0]
        lo = np.ascontiguousarray(bounds[:, 0])
        hi = np.ascontiguousarray(bounds[:, 1])
        turn = np.ones(1, dtype=np.int64)  # the tree extended last: the start tree goes first
        work = np.empty((4, 6))
        domain = p.dynamic_domain_rad
        settings = np.array(
            [
                step,
                resolution,
                p.floor_m,
                np.inf if domain is None else domain,
                p.domain_min_radius_rad,
                p.domain_alpha,
                p.tree_ratio,
            ]
        )
        calls = 0
        while True:
            status, a, b = rrt_connect(
                model.kernel,
                model.scratch,
                lo,
                hi,
                settings,
                p.iterations_per_call,
                room,
                nodes,
                parents,
                radii,
                counts,
                index,
                rng,
                turn,
                work,
            )
            calls += 1
            if status == 1:
                path = tree_path(nodes, parents, a, b)
                root = b
                while parents[1, root] >= 0:
                    root = parents[1, root]
                return path, int(root), rng
            if status < 0:
                if capacity >= p.max_nodes:
                    return Status.NO_SOLUTION, f"a tree reached max_nodes ({p.max_nodes}) without connecting"
                capacity = min(p.max_nodes, 2 * capacity)
                nodes, parents, radii = grown(nodes, parents, radii, capacity)
                index = new_index(capacity)  # built again at the next node added
                continue
            if time.perf_counter() >= deadline:
                nodes_grown = int(counts.sum())
                return (
                    Status.TIMEOUT,
                    f"no path within the time limit ({calls * p.iterations_per_call} iterations, {nodes_grown} nodes)",
                )


def _with_times(info: dict[str, Any], timings: dict[str, float]) -> dict[str, Any]:
    """info with each step's seconds as `<step>_time_s` (as the OMPL planners report theirs)."""
    return dict(info, **{f"{k}_time_s": v for k, v in timings.items()})
