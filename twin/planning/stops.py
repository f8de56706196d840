"""The motion a receding-horizon MPC has commanded, and its ways to stop: the half of the loop
(`twin.planning.receding`) that does not depend on the goal or the solver.

What it keeps: the last two executed steps (the arm's velocity and acceleration, knot to knot), the last
feasible plan and where along it the arm should be, and a stop checked free from the last segment's end. What
it answers: a segment as a trajectory (`_segment`), whether knots collide in the FCL scene now or a little
ahead (`_collision`, `_collision_ahead`) or break a hard constraint of the formulation (`_violation`, which a
formulation may extend), and the ways a moving arm can come to rest: the shortest stop within the bounds
(`braking.stopping_steps`), the last plan up to where it may stop, or the kept stop (`_free_stop`,
`_stop_after`, `_stop_at_goal`, `_fallback_knots`). Why each exists is said in `twin.planning.receding`'s
docstring; this is where they live so that the loop reads as a loop.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from twin.planning.braking import can_stop_now, stopping_steps
from twin.planning.checked import colliding_pair, densify, densify_path, first_collision
from twin.planning.proxy_spheres import Box, violation
from twin.types import Trajectory

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.planning.receding_params import RecedingParams
    from twin.robot.kinematics import URArm
    from twin.types import MotionRequest

__all__ = ["WaysToStop"]

log = logging.getLogger("twin")

# the last plan beyond a segment is checked joint-linearly at this resolution (rad): a coarse early warning
# (the segment itself is checked at the configured resolution), for the knots the arm needs to stop
_LOOKAHEAD_RESOLUTION_RAD = 0.03


class WaysToStop:
    """The commanded motion of one goal and the ways to bring it to rest, checked before they are needed. The
    loop (`RecedingHorizonMPC`) sets the state below; a subclass may extend `_violation`."""

    params: RecedingParams
    kin: URArm
    name: str
    _request: MotionRequest | None
    _scene: PlanningScene | None
    _resolution: dict[str, float]  # the FCL check's (`collision.check_resolution_*`)
    _dq_prev: np.ndarray  # the last executed step (knot to knot)
    _dq_prev2: np.ndarray  # the step before it
    _plan: np.ndarray | None  # (N+1, 6) knots of the last feasible plan
    _plan_idx: int  # index of the knot the robot should be at now
    _ws_offset: int  # steps executed since the last accepted solve
    _commanded: np.ndarray | None  # the knot the arm was last commanded to (None before the first segment)
    _safe_stop: np.ndarray | None  # a checked-free stop (knots) from the last segment's end
    _track: np.ndarray  # the point that goes to the goal, TCP frame
    _target: np.ndarray  # the goal position, base frame
    _tolerance: float  # how near the goal the loop stops

    # ---- the executed motion ---------------------------------------------------------------------------

    def _tracked(self, q: np.ndarray) -> np.ndarray:
        """(3,) the point that goes to the goal (`_track`, TCP frame) at `q`, base frame: a stop is judged by it."""
        T = self.kin.fk(q, "tcp")
        return T[:3, 3] + T[:3, :3] @ self._track

    def _commit(self, knots: np.ndarray) -> None:
        """The arm is commanded along `knots`: advance the plan and the step history."""
        m = knots.shape[0] - 1
        hist = np.vstack([self._dq_prev2[None], self._dq_prev[None], np.diff(knots, axis=0)])
        self._dq_prev2, self._dq_prev = hist[-2].copy(), hist[-1].copy()
        self._plan_idx += m
        self._ws_offset += m
        self._commanded = knots[-1].copy()

    def _moving(self) -> bool:
        """Whether the last commanded step moved (a stop ends with a zero step: the arm is declared at rest)."""
        return bool(np.any(self._dq_prev != 0.0))

    def _step_bounds(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Per-joint bounds (6,) of a step (velocity x dt), of its change (acceleration x dt^2) and of the
        change of that (jerk x dt^3); None where the parameters switch a bound off."""
        assert self._request is not None
        P, lim = self.params, self._request.limits
        step = np.minimum(P.max_step_rad, lim.max_joint_vel * P.dt)
        dstep = lim.max_joint_acc * P.dt**2 if P.limit_acceleration else None
        jstep = lim.max_joint_jerk * P.dt**3 if P.limit_jerk else None
        return step, dstep, jstep

    def _segment(self, knots: np.ndarray, before: tuple[np.ndarray, np.ndarray] | None = None) -> Trajectory:
        """The knots (m+1, 6) as a trajectory at dt, with the knots' backward differences as its derivatives:
        qd_i = (q_i - q_{i-1}) / dt and qdd_i = (qd_i - qd_{i-1}) / dt, for the first sample from the two steps
        `before` (d2, d1) that brought the arm to knots[0] (default: the last two executed; zero at rest).
        Declared and measured agree exactly, and a segment starts with the velocity and acceleration the
        previous one ended with."""
        dt = self.params.dt
        d2, d1 = before if before is not None else (self._dq_prev2, self._dq_prev)
        hist = np.vstack([d2[None], d1[None], np.diff(knots, axis=0)])
        qd = hist[1:] / dt
        qdd = np.diff(hist, axis=0) / dt**2
        t = dt * np.arange(knots.shape[0])
        return Trajectory(t, knots.copy(), qd, qdd)

    # ---- checks ------------------------------------------------------------------------------------------

    def _collision(self, traj: Trajectory) -> str | None:
        """The colliding pair of the first colliding sample of `traj` (FCL, whole scene, configured resolution)."""
        assert self._scene is not None
        hit = first_collision(traj, self._scene, self.kin, **self._resolution)
        if hit is None:
            return None
        return colliding_pair(self._scene, densify(traj, self.kin, **self._resolution)[hit])

    def _collision_ahead(self, knots: np.ndarray) -> tuple[str, int] | None:
        """(pair, steps) when the last plan, after the segment `knots` that follows it, collides within the
        steps the arm needs to stop from the segment's end (+2), checked joint-linearly and coarsely."""
        if self._plan is None or knots.shape[0] < 2:
            return None
        start = self._plan_idx + knots.shape[0] - 1
        _, dstep, _ = self._step_bounds()
        a = float(np.min(dstep)) if dstep is not None else self.params.max_step_rad
        n = math.ceil(float(np.abs(knots[-1] - knots[-2]).max()) / a) + 2
        rest = self._plan[start + 1 : start + 1 + n]
        if rest.shape[0] == 0:
            return None
        path = np.vstack([knots[-1:], rest])
        qs = densify_path(path, _LOOKAHEAD_RESOLUTION_RAD)[1:]
        assert self._scene is not None
        i = self._scene.first_collision(qs)
        if i is None:
            return None
        # densify_path puts ceil(|step| / resolution) points on each step: which step the hit is on
        lengths = np.linalg.norm(np.diff(path, axis=0), axis=1)
        per_step = np.maximum(1, np.ceil(lengths / _LOOKAHEAD_RESOLUTION_RAD - 1e-9))
        return colliding_pair(self._scene, qs[i]), int(np.searchsorted(np.cumsum(per_step), i + 1)) + 1

    def _violation(self, knots: np.ndarray, sph: np.ndarray, boxes: list[Box]) -> str | None:
        """Why the knot path (m+1, 6) (knots[0] = the current state) breaks a hard constraint, or None."""
        P = self.params
        step, dstep, jstep = self._step_bounds()
        return violation(
            self.kin,
            knots,
            sph,
            boxes,
            step,
            dstep,
            jstep,
            dq_prev=self._dq_prev,
            dq_prev2=self._dq_prev2,
            box_margin_m=P.box_margin_m,
            substeps=P.constraint_substeps,
        )

    # ---- ways to stop, checked before they are needed ------------------------------------------------

    def _free_stop(
        self, q: np.ndarray, stops: list[np.ndarray | None], hist: tuple[np.ndarray, np.ndarray] | None = None
    ) -> tuple[np.ndarray | None, str]:
        """The first of `stops` (knots from `q`, None: none) that is free in the FCL scene, with the step history
        `hist` (d2, d1) before it (default: the executed steps); else None and why not (the first pair hit)."""
        why = "no stop within the limits"
        for i, knots in enumerate(stops):
            if knots is None:
                continue
            pair = self._collision(self._segment(knots, hist))
            if pair is None:
                return knots, ""
            if i == 0 or why.startswith("no stop"):
                why = pair
        return None, why

    def _stop_after(self, knots: np.ndarray) -> tuple[np.ndarray | None, str]:
        """A free stop from the end of the segment `knots` (m+1, 6), with the steps it ends with: at rest there,
        the end itself; else the shortest stop (`braking.stopping_steps`) or the last plan up to where it may
        stop, the shorter first, whichever the FCL scene passes. None and the pair hit when neither is free."""
        hist = np.vstack([self._dq_prev2[None], self._dq_prev[None], np.diff(knots, axis=0)])
        d2, d1 = hist[-2], hist[-1]
        _, dstep, jstep = self._step_bounds()
        end = knots[-1]
        if can_stop_now(d2, d1, dstep, jstep):
            return np.vstack([end[None], end[None]]), ""
        along = None
        i = self._plan_idx + knots.shape[0] - 1
        if self._plan is not None and i < self._plan.shape[0] and np.array_equal(self._plan[i], end):
            along = self._along(end, self._plan[i + 1 :], d2, d1)
        stops = sorted((s for s in (self._brake_knots(end, (d2, d1)), along) if s is not None), key=len)
        return self._free_stop(end, list(stops) or [None], (d2, d1))

    def _kept_stop(self, q: np.ndarray) -> list[np.ndarray]:
        """The stop kept free from the last segment's end (`_stop_after`), from the measured state `q`: as it is
        when `q` is that end, else its steps taken from `q` (the arm tracks to within its controller's error)."""
        stop = self._safe_stop
        if stop is None:
            return []
        if np.array_equal(stop[0], q):
            return [stop]
        return [np.vstack([q[None], q[None] + np.cumsum(np.diff(stop, axis=0), axis=0)])]

    def _brake_knots(self, q: np.ndarray, hist: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray | None:
        """The shortest stop from `q` and the two steps `hist` (d2, d1) that brought the arm there (default: the
        executed ones; `braking.stopping_steps`), ending in a zero step, within the joint limits; None when there
        is none."""
        step, dstep, jstep = self._step_bounds()
        d2, d1 = hist if hist is not None else (self._dq_prev2, self._dq_prev)
        steps = stopping_steps(d2, d1, step, dstep, jstep)
        if steps is None:
            return None
        knots = np.vstack([q[None], q[None] + np.cumsum(steps, axis=0)])
        knots[-1] = knots[-2]  # the zero step, exactly
        lim = self.kin.joint_limits
        if np.any(knots < lim[:, 0]) or np.any(knots > lim[:, 1]):
            return None
        return knots

    def _along(self, q: np.ndarray, rest: np.ndarray, d2: np.ndarray, d1: np.ndarray) -> np.ndarray | None:
        """From `q`, reached by the steps `d2` then `d1`, the knots `rest` (k, 6) up to the first one the arm may
        stop at (`braking.can_stop_now`), then a zero step; None when it may stop at none of them."""
        _, dstep, jstep = self._step_bounds()
        path = [q]
        for nxt in rest:
            d2, d1 = d1, nxt - path[-1]
            path.append(nxt)
            if can_stop_now(d2, d1, dstep, jstep):
                return np.vstack([*path, path[-1]])
        return None

    def _stop_along_plan(self, q: np.ndarray, sph: np.ndarray, boxes: list[Box]) -> np.ndarray | None:
        """The last plan's next knots up to the first one the arm may stop at (`braking.can_stop_now`), then a
        zero step, from the measured state, if they pass the constraint check; else, from a measured state off the
        plan, its steps taken from there (as `_fallback_knots`); None without such a plan. From a state that lags
        the commanded knot (a physics controller: 4-6 mrad near a warehouse drop) the first step to the plan's next
        knot carries the lag, and where the plan's step changes use its bounds (a warm plan's did: 84-93% of the
        jerk bound) it breaks them: warehouse seed 0's stop along the plan was refused for 0.0514 rad against
        0.0512, the shortest stop, straight on, went 11 mm into the wall's margin, and the next solve refused its
        start. The plan's own steps keep the bounds after the steps the arm was commanded."""
        _, dstep, jstep = self._step_bounds()
        if can_stop_now(self._dq_prev2, self._dq_prev, dstep, jstep):
            return np.vstack([q[None], q[None]])
        if self._plan is None:
            return None
        knots = self._along(q, self._plan[self._plan_idx + 1 :], self._dq_prev2, self._dq_prev)
        if knots is not None and self._violation(knots, sph, boxes) is None:
            return knots
        steps = np.diff(self._plan[self._plan_idx :], axis=0)
        if steps.shape[0] == 0 or np.array_equal(q, self._plan[self._plan_idx]):
            return None
        knots = self._along(q, q[None] + np.cumsum(steps, axis=0), self._dq_prev2, self._dq_prev)
        return knots if knots is not None and self._violation(knots, sph, boxes) is None else None

    def _stop_at_goal(self, q: np.ndarray, sph: np.ndarray, boxes: list[Box]) -> np.ndarray | None:
        """How a moving arm within the goal tolerance comes to rest: of the stop along the last plan
        (`_stop_along_plan`), the shortest stop (`_brake_knots`) and the stop kept free from the last segment's
        end (`_kept_stop`), those free in the FCL scene (and passing the constraint check, when any does); the
        shortest that ends within the tolerance, as the seed stops as soon as it is within it, else the shortest
        (the loop then solves again from rest). With none free, the shortest stop or the plan's (the segment's
        check then brakes as it can); None without any."""
        along, brake = self._stop_along_plan(q, sph, boxes), self._brake_knots(q)
        free = [
            k
            for k in (along, brake, *self._kept_stop(q))
            if k is not None and self._collision(self._segment(k)) is None
        ]
        if not free:
            return brake if brake is not None else along
        checked = [k for k in free if self._violation(k, sph, boxes) is None] or free
        there = [k for k in checked if np.linalg.norm(self._tracked(k[-1]) - self._target) <= self._tolerance]
        return min(there or checked, key=len)

    def _fallback_knots(self, q: np.ndarray, sph: np.ndarray, boxes: list[Box], k: int) -> np.ndarray | None:
        """Up to k remaining steps of the last feasible plan, from the measured state, if they still pass: its
        knots, or else its steps taken from the measured state (the arm tracks a plan only to within its
        controller's error, and the first step from there to the plan's next knot can break the acceleration
        bound the plan's own steps keep: a RoboCup transfer ended there)."""
        if self._plan is None:
            return None
        rest = self._plan[self._plan_idx + 1 : self._plan_idx + 1 + k]
        if rest.shape[0] == 0:
            return None
        knots = np.vstack([q[None], rest])
        why = self._violation(knots, sph, boxes)
        if why is None:
            return knots
        steps = np.diff(self._plan[self._plan_idx : self._plan_idx + 1 + k], axis=0)
        shifted = np.vstack([q[None], q[None] + np.cumsum(steps, axis=0)])
        also = self._violation(shifted, sph, boxes)
        if also is None:
            return shifted
        log.info("%s: the last feasible plan no longer passes (%s; its steps from here: %s)", self.name, why, also)
        return None
