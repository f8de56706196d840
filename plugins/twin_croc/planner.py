"""`croc`: the receding-horizon MPC on the field's optimal-control stack, Crocoddyl's shooting problem solved by
mim-solvers' constrained SQP (CSQP), in the loop `nmpc` uses (`twin.planning.receding`: checks, fallback,
braking, segments), so the two differ only in the solver and, in `whole_arm` mode, in what they keep apart.

Modes:
* `seed`: `nmpc`'s formulation (horizon, dt, step bound, acceleration bound, tcp position cost, terminal
  weight, soft table clearance, soft terminal facing-down, hard tool, wrist and held-object spheres against
  the perceived boxes). The differences: no jerk rows (the control is the step's change; its change is not
  a row here), so croc is not `jerk_limited`; the soft table clearance counts the box margin (the spheres
  cover their links only with it: without, a gripper corner met the table on a bench scene).
* `whole_arm`: tight spheres on every link from the shoulder to the fingertips (`arm_spheres`,
  `whole_arm_tool_spheres`; the seed's tool spheres are sized for a held cube), against every primitive of
  the planning scene (fixtures such as bins, perceived boxes and objects; each as its axis-aligned box),
  except the table, which stays the soft table term: an MPC that can work in the RoboCup cell. Its spheres
  cover the links only with the box margin, so a measured state with a sphere inside a box the link is
  clear of (FCL) is not refused: the rows hold that sphere no deeper than it started.
* Both modes keep the arm from itself (`twin.planning.selfrows`, `self_slots`): the seeds' formulation does not,
  and croc's plans folded the elbow until the upper arm met wrist 1 (a warehouse drop near the base) or
  swung the gripper into the forearm; the loop's FCL check stopped them, the goal was lost. The rows are
  there only while a pair of the arm's spheres comes near (`self_screen_m`), so most solves are the seeds'
  formulation exactly.
  A pair is kept twice the box margin apart (each sphere covers its link only to within one margin), and the
  loop's check of a plan (`_violation`) judges every pair between the knots too: the rows are a few slots per
  knot chosen on the plan a round starts from, and a warm solve is one iteration (warehouse seeds 105-111
  folded the gripper base into the forearm until both held).

Why these choices:
* One problem per count of held-object spheres, built on first use (without: when the planner is
  constructed): one row per sphere and knot holds the sphere beyond a face of every box near it
  (`twin_croc.rows`), re-set per solve, so the QP's size does not depend on the number of boxes in the scene.
* Warm starts: the last solution shifted by the executed steps, primal and dual, with an iteration budget
  (`warm_rounds` x `iterations_per_round`) so that a warm solve ends within the step period; a cold solve
  (the first of a goal, or after a rejected one) starts from the loop's over-the-box guess.
* An iterate CSQP did not finish (its budget ran out) is still a plan if the loop's independent check of the
  hard constraints passes it (a real-time MPC executes its best feasible iterate); the log says
  `converged: false`. A solve whose plan fails the check is never executed: the loop follows the last plan
  as a counted fallback.
* The faces are chosen on the plan a solve starts from, so they hold a sphere beyond a face it has left
  when the iterate moves faster than that plan (past the wall while the faces still say "above it"), and
  CSQP, linearising the same faces for ten iterations, wandered off (cost 20 -> 140, never converging over
  the warehouse wall). So a solve runs in rounds of `iterations_per_round` SQP iterations, the faces (and
  the pairs: only those near the plan, `box_screen_m`, are bounded) chosen again on each round's iterate,
  until CSQP converges with faces that no longer change, or `warm_rounds` rounds (one: a real-time
  iteration per step), or for a cold solve `cold_rounds` and a plan the loop's check passes (at most
  `cold_max_rounds`: a goal's first plan has no earlier one to fall back on).
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np

from twin.plugin import (
    CHECK_TOL_M,
    TCP_FRAME,
    Box,
    RecedingHorizonMPC,
    SelfRows,
    Solved,
    pair_gaps,
    robot_spheres,
    self_pairs,
    self_rows,
    self_violation,
    sphere_positions,
    subdivide,
    with_object,
)
from twin_croc.ocp import HorizonProblem
from twin_croc.params import CrocParams
from twin_croc.rows import Pairs, close_pairs, sphere_bounds

if TYPE_CHECKING:
    from twin.plugin import MotionRequest, PlanningScene, PluginContext

__all__ = ["CrocPlanner"]

_TABLE_TOP_TOL_M = 1e-3  # a primitive whose top is this close to the table top is the table (the soft term)


def _aabb(kind: str, size: tuple[float, ...], T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds of a primitive (kinds and sizes as twin.robot.urdf_model.Shape) at pose T."""
    if kind == "box":
        half = 0.5 * np.asarray(size[:3], dtype=float)
    elif kind == "sphere":
        half = np.full(3, float(size[0]))
    else:  # cylinder or capsule about its local z
        r, length = float(size[0]), float(size[1])
        half = np.array([r, r, 0.5 * length + (r if kind == "capsule" else 0.0)])
    ext = np.abs(T[:3, :3]) @ half
    return T[:3, 3] - ext, T[:3, 3] + ext


class CrocPlanner(RecedingHorizonMPC):
    """Receding-horizon MPC over Crocoddyl + CSQP: `reset(request, scene)`, then `step(q)` until a MotionResult."""

    Params = CrocParams
    name = "croc"
    _recovers_blocked_segments = True  # (twin.planning.receding): stress seed 110, a lagged fallback by the wall
    params: CrocParams

    def __init__(self, params: CrocParams | None, context: PluginContext):
        super().__init__(params if params is not None else CrocParams(), context)
        P = self.params
        arm = np.asarray(P.arm_spheres, dtype=float).reshape(-1, 5)
        self._self_sph = robot_spheres(P.whole_arm_tool_spheres, arm)  # kept apart pairwise (self rows)
        if P.mode == "whole_arm":
            self._robot_sph = self._self_sph
        self._problems: dict[tuple[int, int], HorizonProblem] = {}
        self._self_pairs: dict[int, np.ndarray] = {}  # per held-object sphere count
        self._used: set[HorizonProblem] = set()  # the problems this goal solved (renewed before the next goal)
        self.build_time_s = 0.0
        self.problem(0)  # built here, not in the first (timed) step; one per held-object sphere count

    def problem(self, n_object: int, self_slots: int = 0) -> HorizonProblem:
        """The problem for the robot's spheres and `n_object` held-object spheres, with `self_slots` self rows
        per knot (built on first use: ~0.1 s; parked object frames would cost ~40 % more per iteration than
        none, and idle self rows ~4 us per knot and row: a horizon with no pair near is solved without them)."""
        prob = self._problems.get((n_object, self_slots))
        if prob is None:
            P = self.params
            t0 = time.perf_counter()
            prob = HorizonProblem(
                self.kin,
                self._robot_sph,
                tcp_index=TCP_FRAME,
                n_object=n_object,
                horizon=P.horizon,
                acceleration_rows=P.limit_acceleration,
                weights=self._weights(),
                table_z_m=P.table_z_m,
                table_clearance_m=P.table_clearance_m + P.box_margin_m,
                termination_tolerance=P.termination_tolerance,
                qp_tolerance=P.qp_tolerance,
                self_spheres=self._self_sph,
                self_slots=self_slots,
            )
            self.build_time_s += time.perf_counter() - t0
            self._problems[(n_object, self_slots)] = prob
        return prob

    def reset(self, request: MotionRequest, scene: PlanningScene) -> None:
        """A new goal: the problems the last goal solved start as new (`HorizonProblem.renew`: a goal's plan does
        not depend on the goals before it)."""
        for prob in self._used:
            prob.renew()
        self._used.clear()
        super().reset(request, scene)

    def _self_rows(
        self, qs: np.ndarray, self_sph: np.ndarray, pairs: np.ndarray, centres: np.ndarray | None = None
    ) -> SelfRows | None:
        """The self rows of the plan `qs` (H+1, 6) (`twin.planning.selfrows`; `centres`: the self set's there, when
        known), None if it needs none."""
        P = self.params
        if not P.self_slots:
            return None
        if centres is None:
            centres = sphere_positions(self.kin, qs, self_sph)
        radii = self_sph[:, 4]
        return self_rows(
            centres,
            radii,
            pairs,
            slots=P.self_slots,
            within=P.self_screen_m,
            extra=self._self_bound() + P.row_tightening_m,
        )

    def _self_bound(self) -> float:
        """How far apart two of the arm's own spheres must stay, m: each covers its link only to within the box
        margin (`twin_croc.params`), so twice that (one let the gripper base into the forearm)."""
        return 2 * self.params.box_margin_m

    def _self_set(self, sph: np.ndarray) -> np.ndarray:
        """The spheres kept apart pairwise (the self set, then the held object's) for the loop's spheres `sph`
        (the robot's, then the held object's)."""
        return np.vstack([self._self_sph, sph[self._robot_sph.shape[0] :]])

    def _violation(self, knots: np.ndarray, sph: np.ndarray, boxes: list[Box]) -> str | None:
        """The loop's check of the hard constraints (`RecedingHorizonMPC._violation`) and of the self rows: every
        pair of the self set, at the knots and between them (`constraint_substeps` points per step, joint-linear),
        stays `_self_bound` apart or no closer than it starts (`twin.planning.selfrows.self_violation`)."""
        why = super()._violation(knots, sph, boxes)
        if why is not None or not self.params.self_slots or knots.shape[0] < 2:
            return why
        own = self._self_set(sph)
        pairs = self._self_pairs.get(own.shape[0] - self._self_sph.shape[0])
        if pairs is None:
            pairs = self._self_pairs[own.shape[0] - self._self_sph.shape[0]] = self_pairs(own)
        qs = np.vstack([knots[:1], subdivide(knots, self.params.constraint_substeps)])
        gaps = pair_gaps(sphere_positions(self.kin, qs, own), own[:, 4], pairs)
        return self_violation(gaps, bound=self._self_bound(), tol=CHECK_TOL_M)

    def _refuses_sphere_overlap(self) -> bool:
        """No, in both modes: the rows (`twin_croc.rows`) let a sphere that starts inside a margin-grown box come
        out but not go deeper, and the loop's check holds it to the same, so FCL judges the start. whole_arm: its
        spheres cover the links only with the box margin, so one can overlap a box the link is clear of (a
        fingertip sphere 7 mm into a bin wall from a start 1 cm clear of it). seed: its spheres are generous;
        under the stress set's lagging controller a free stop before the warehouse wall (the loop's recovery,
        `RecedingHorizonMPC._recover`) left a proxy sphere 1 cm inside the wall's box with the gripper clear of
        it, and refusing that start lost the cube (seeds 102, 110: "invalid_start")."""
        return False

    def _boxes(self) -> list[Box]:
        """seed: the perceived boxes; whole_arm: every primitive of the scene as its axis-aligned box, but the
        table (the soft table term keeps the spheres above it)."""
        if self.params.mode == "seed" or self._scene is None:
            return super()._boxes()
        out: list[Box] = []
        for name, shapes in sorted(self._scene.environment_shapes().items()):
            for i, (kind, size, T) in enumerate(shapes):
                lo, hi = _aabb(kind, size, T)
                if hi[2] <= self.params.table_z_m + _TABLE_TOP_TOL_M:
                    continue
                out.append((name if len(shapes) == 1 else f"{name}[{i}]", lo, hi))
        return out

    def _solve(self, q: np.ndarray, boxes: list[Box], obj: np.ndarray, sph: np.ndarray) -> Solved:
        """One CSQP solve, in rounds while the faces its iterate is beyond change (module docstring), warm-started
        from the last accepted one shifted by the steps executed since."""
        P = self.params
        t0 = time.perf_counter()
        step, dstep, _ = self._step_bounds()
        radii = sph[:, 4]
        guess: np.ndarray | None = None
        if self._ws is not None:
            plan = self._plan[self._ws_offset :] if self._plan is not None else q[None]
            start = np.vstack([plan, np.repeat(plan[-1:], P.horizon + 1 - plan.shape[0], axis=0)])
        else:
            g0 = time.perf_counter()
            guess = self._cold_guess(q, boxes, sph)
            t0 += time.perf_counter() - g0  # the loop's guess (nmpc's too) is not the solve's time
            start = np.vstack([q[None], guess])
        start[0] = q
        centres = sphere_positions(self.kin, start, sph)
        pairs: Pairs = close_pairs(centres, radii, boxes, P.box_margin_m, P.box_screen_m)
        iterations, qp_iterations, rounds, converged, cost = 0, 0, 0, False, math.nan
        self_sph = with_object(self._self_sph, obj)
        spairs = self._self_pairs.get(obj.shape[0])
        if spairs is None:
            spairs = self._self_pairs[obj.shape[0]] = self_pairs(self_sph)
        same = P.mode == "whole_arm"  # the self set is the robot's (both with the held object's spheres last)
        srows = self._self_rows(start, self_sph, spairs, centres if same else None)
        prob = self.problem(obj.shape[0], P.self_slots if srows is not None else 0)
        # warm: from the last solution, primal and dual (also across the switch to or from the problem with self
        # rows: `source`); cold: from the loop's guess
        cold = self._ws is None
        source = None if cold or self._ws is prob else self._ws
        qs, shift = start, self._ws_offset
        bounds = sphere_bounds(centres, radii, boxes, pairs, margin=P.box_margin_m, tighten=P.row_tightening_m)
        while True:
            rounds += 1
            self._used.add(prob)
            prob.set_object(obj)
            prob.set_track(self._track)
            sol = prob.solve(
                q,
                self._dq_prev,
                self._target,
                bounds,
                step_bound=step,
                accel_bound=dstep,
                guess=qs if cold and rounds == 1 else None,
                shift=shift,
                max_iterations=P.iterations_per_round,
                self_rows=srows,
                source=source,
            )
            iterations += sol.iterations
            qp_iterations += int(prob.solver.qp_iters)
            converged, cost, qs = sol.converged, sol.cost, sol.qs.copy()
            qs[0] = q
            if not cold and rounds >= P.warm_rounds:
                break  # (the next step's solve chooses its faces on this plan, shifted)
            if (
                cold
                and rounds >= P.cold_rounds
                and (rounds >= P.cold_max_rounds or self._violation(qs, sph, boxes) is None)
            ):
                break  # a first plan the loop's check passes: the warm solves of the next steps go on from it
            # the faces follow the solution: a sphere it moved past a box (sooner than the plan the faces came
            # from) is bounded by the face it is beyond now, and a pair it came close to is bounded
            centres = sphere_positions(self.kin, qs, sph)
            if P.box_screen_m is not None:
                pairs |= close_pairs(centres, radii, boxes, P.box_margin_m, P.box_screen_m / 2)
            again = sphere_bounds(centres, radii, boxes, pairs, margin=P.box_margin_m, tighten=P.row_tightening_m)
            srows_again = self._self_rows(qs, self_sph, spairs, centres if same else None)
            # done when no pair is closer than its bound by more than the QP's slack (the nearest pairs of a knot may
            # take turns in its slots from round to round, each held in its turn)
            self_held = srows_again is None or srows_again.deficit <= P.row_tightening_m
            if converged and np.array_equal(again, bounds) and self_held:
                break
            bounds, srows, shift, source = again, srows_again, 0, None  # on from this solution, primal and dual
            if srows is not None and not prob.self_slots:  # a pair came near: on in the problem with self rows
                prob, source = self.problem(obj.shape[0], P.self_slots), prob
        entry = {
            "converged": converged,
            "iterations": iterations,
            "rounds": rounds,
            "pairs": len(pairs),
            "boxes": len({b for _, b in pairs}),
            "qp_iterations": qp_iterations,
            "self_rows": 0 if srows is None else int((srows.pairs[:, :, 0] >= 0).sum()),
        }
        return Solved(
            qs,
            None,
            time.perf_counter() - t0,
            cost,
            entry,
            guess=guess,
            warm_start=prob,
            warm=not cold,
        )
