"""`nmpc`: the warehouse system's (seeds 000/001) receding-horizon NMPC as a planner plugin.

Per solve: from the measured joint state, the latest obstacle boxes of the planning scene and the held
object, optimise N = 30 joint steps (dt 0.08 s; seed 001: 0.1 s) under per-step increments of +-0.15 rad,
proxy spheres around the gripper (and around the held box) outside every obstacle box at every step and
between steps (hard), table clearance (soft, slack) and a terminal facing-down tool (soft, slack); cost:
TCP position error, terminal weight x10, a lighter joint-step penalty. Execute the first k steps (seed 000:
k = 1; seed 001: k = 3), replan. Stop within 3 cm of the goal (SUCCESS) or after 40 solves (NO_SOLUTION).
Beyond the seed (each can be switched off): the step may change by at most the request's joint
acceleration limit x dt^2 per step and that change by at most its jerk limit x dt^3 (`jerk_limited`
declares the latter), and two spheres guard the wrist links.

Why these choices:
* Building an NLP costs ~1.5 s expanded (fastest solves) or ~0.1 s mapped, a solve ~15 ms: NLPs are built
  once per process and problem shape (number of boxes, number of held-object spheres) and shared by every
  planner instance with the same parameters (`twin_nmpc.nlp.cached_problem`); the shape a run uses (`box_slots`
  box slots: by default the fixtures perception reports and one placed object) is built expanded when the
  planner is constructed, not inside a timed step, and a shape first met inside a step is built mapped (a
  RoboCup run meets one per count of objects left on the table: 57 s of building became 2 s). Each solve only
  changes parameters and is warm-started from the previous solution shifted by the executed steps (and carried
  on past its horizon within the bounds), primal and dual, from a small barrier (`warm_mu_init`).
* An NLP holds only the boxes a proxy sphere comes within `box_screen_m` (0.1 m) of along the plan the solve
  starts from (the shifted last plan, or the initial guess): rows of a box far away are inactive at the
  solution and only cost evaluations (a RoboCup table holds up to 7 boxes: x 11 spheres x 2 check points x
  30 stages). A solution that comes within half that distance of a box left out is solved again with the box,
  so every accepted plan is a solution of the problem with every box, and the numpy check below checks it
  against every box. The boxes sit in a fixed number of slots (unused ones hold a box far away; a box keeps
  its slot while it is in the scene) so a change of which boxes are near keeps the NLP's shape and the warm
  start.
* The perceived box is extended over the whole workspace in y, so the only way is over it, and a straight
  initial guess through the box starts IPOPT where the box distance has zero gradient. The first solve is
  therefore seeded over the box: lift, transfer, lower, through IK waypoints (measured on the bench
  scenes: ~35 IPOPT iterations from this guess, ~180 from the straight one, which only the chord terms of
  the pairwise box rows pull out of the box at all).
* Everything around a solve is the receding-horizon loop's (`twin.planning.receding`, shared with `croc`): the
  independent numpy check of every plan, the fallback to the last feasible plan, the FCL check of every
  segment and the braking before a collision, segments whose derivatives are their knots' differences, the
  `goal_kinds` (positions) and what the result's info counts. The NLP's step, step-change and jerk rows are
  the velocity, acceleration and jerk limits of what a segment declares.

The pieces: `twin_nmpc.params` (the parameter model), `twin_nmpc.nlp` (the NLP and its cache); from twin's
core, through `twin.plugin`, what it shares with `croc`: `twin.planning.receding_params` (the shared parameters,
the default spheres), `twin.planning.proxy_spheres` (the proxy spheres and the numpy check of a plan),
`twin.planning.guess` (the cold solve's initial guess), `twin.planning.braking` (stops within the bounds),
`twin.planning.selfrows` (the self rows), `twin.planning.receding` (the receding-horizon loop around a solve);
this module holds the IPOPT solve.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.plugin import (
    CHECK_TOL_M,
    DEFAULT_ARM_SPHERES,
    DEFAULT_WHOLE_ARM_TOOL_SPHERES,
    Box,
    RecedingHorizonMPC,
    SelfRows,
    Solved,
    box_gaps,
    guess_slack,
    link_groups,
    pair_gaps,
    robot_spheres,
    self_pairs,
    self_rows,
    self_violation,
    sphere_positions,
    subdivide,
    with_object,
)
from twin_nmpc.nlp import NMPCProblem, ProblemShape, SolveOutput, cached_problem
from twin_nmpc.params import NMPCParams

if TYPE_CHECKING:
    from twin.plugin import PluginContext

__all__ = ["NMPCPlanner"]

log = logging.getLogger("twin")

# what fills an NLP's unused box slots: a 2 cm box 100 m below the base, whose rows are never near active
_FAR_BOX: Box = ("", np.array([0.0, 0.0, -100.0]), np.array([0.0, 0.0, -100.0]))
_SELF_ROUNDS = 2  # solves again at most this often with the self rows chosen on a plan that broke them


class NMPCPlanner(RecedingHorizonMPC):
    """Receding-horizon NMPC over CasADi/IPOPT: `reset(request, scene)`, then `step(q)` until a MotionResult."""

    Params = NMPCParams
    name = "nmpc"
    params: NMPCParams

    def __init__(self, params: NMPCParams | None, context: PluginContext):
        P = params if params is not None else NMPCParams()
        self._expected_slots = P.box_slots if P.box_slots is not None else self.default_box_slots(context)
        expected = P.prebuild_boxes if P.prebuild_boxes is not None else [self._expected_slots]
        self._problems: dict[ProblemShape, NMPCProblem] = {}
        super().__init__(P, context)
        # the self set (croc's: whole-arm spheres covering each link within the box margin) and, per count of
        # held-object spheres, its pairs the self rows keep apart: a tool or held-object sphere and a forearm or
        # upper-arm sphere (the wrist's links are the tool's neighbours or fold away from it)
        self._self_sph = robot_spheres(DEFAULT_WHOLE_ARM_TOOL_SPHERES, np.asarray(DEFAULT_ARM_SPHERES, dtype=float))
        self._self_pairs: dict[int, np.ndarray] = {}
        for nb in sorted(set(expected)):  # built here, not in the first (timed) step
            self.problem(ProblemShape(P.horizon, nb, 0, P.constraint_substeps, P.self_slots), expand=True)

    @staticmethod
    def default_box_slots(context: PluginContext) -> int:
        """The box slots a config's runs need (`box_slots` None): perception reports one box per fixture the
        planners do not know, and a task that places objects adds each placed one as a box, beside the way to the
        next drop (warehouse: the wall and a placed cube, so 2; with 1, transfers 2-4 built a second slot inside a
        step, mapped, whose iterations cost ~3x the expanded ones)."""
        world = context.settings.world
        return sum(not f.known for f in world.fixtures) + int(any(item.count for item in world.objects.items))

    def _start_goal(self) -> None:
        super()._start_goal()
        # the box in each NLP box slot ("" = free), kept from solve to solve of a goal; a goal starts with the
        # slots of the shape the planner expects (`prebuild_boxes`), so its plans do not depend on earlier goals
        self._slots: list[str] = []
        self._box_slots = self._expected_slots

    # ---- the NLPs ---------------------------------------------------------------------------------
    def problem(self, shape: ProblemShape, *, expand: bool = False) -> NMPCProblem:
        """The NLP for `shape`: from the process-wide cache (`cached_problem`), built there on first use.
        `expand`: expanded into one SX graph (slow to build, fast to solve: the shapes built at construction)
        or kept as the stage function mapped over the horizon (~0.1 s to build, solves ~2x slower: a shape
        first met inside a step, e.g. another count of perceived boxes or held-object spheres)."""
        prob = self._problems.get(shape)
        if prob is None:
            P = self.params
            prob = cached_problem(
                shape,
                robot_spheres=self._robot_sph,
                dh=self.kin.dh,
                tcp_offset_m=self.kin.tcp_offset_m,
                weights=self._weights(),
                table_clearance_m=P.table_clearance_m,
                facing_down_cos=math.cos(P.facing_down_tol_rad),
                cold_options=self._ipopt_options(cold=True),
                warm_options=self._ipopt_options(cold=False),
                expand=expand,
            )
            self._problems[shape] = prob
        return prob

    @property
    def build_time_s(self) -> float:
        """Seconds it took to build the NLPs this planner has used (each once per process, then shared)."""
        return sum(p.build_time_s for p in self._problems.values())

    def _ipopt_options(self, *, cold: bool) -> dict[str, Any]:
        """nlpsol options. Constraint violation is held to 1e-6 (scaled rows: ~micrometres) even when a solve
        stops at IPOPT's "acceptable" level. A solve is bounded by its iteration limit, a count: where it ends,
        whether its plan is accepted and so whether the next solve starts warm are the same on every machine.
        A CPU-time cap (`solve_time_limit_s`, `cold_solve_time_limit_s`) is only set when asked for: the
        former caps (1 s warm, 5 s cold) were within 3x of what a solve of a new NLP shape needs (a cold
        mapped solve with two boxes: 114 iterations, 2 s CPU here), so a slower or busier machine failed
        solves this one accepts and went on cold from a different state."""
        P = self.params
        tol = P.cold_ipopt_tol if cold else P.ipopt_tol
        opts: dict[str, Any] = {
            "ipopt.tol": tol,
            "ipopt.acceptable_tol": 10 * tol,
            "ipopt.acceptable_iter": 5,
            "ipopt.constr_viol_tol": 1e-6,
            "ipopt.acceptable_constr_viol_tol": 1e-6,
            "ipopt.max_iter": P.cold_max_iter if cold else P.ipopt_max_iter,
            # IPOPT scales the NLP itself; MUMPS scaling the KKT matrix again at every factorisation cost
            # 12-18 % of a solve here for the same iterates (bench_nmpc, 20 scenes)
            "ipopt.mumps_permuting_scaling": 0,
            "ipopt.mumps_scaling": 0,
        }
        cap = P.cold_solve_time_limit_s if cold else P.solve_time_limit_s
        if cap is not None:
            opts["ipopt.max_cpu_time"] = cap
        if cold:
            opts["ipopt.mu_init"] = P.cold_mu_init
        else:  # LIBRARY-NOTES: dual warm start from the previous (shifted) solution
            opts.update(
                {
                    "ipopt.warm_start_init_point": "yes",
                    "ipopt.warm_start_bound_push": 1e-6,
                    "ipopt.warm_start_mult_bound_push": 1e-6,
                    "ipopt.mu_init": P.warm_mu_init,
                }
            )
        opts.update({f"ipopt.{k}": v for k, v in P.ipopt_options.items()})
        return opts

    # ---- one solve ------------------------------------------------------------------------------------
    def _solve(self, q: np.ndarray, boxes: list[Box], obj: np.ndarray, sph: np.ndarray) -> Solved:
        """One IPOPT solve, warm-started (primal and dual, shifted) from the last accepted one of the same shape."""
        P = self.params
        step, dstep, jstep = self._step_bounds()

        # the NLP holds the boxes near the plan the solve starts from (`box_screen_m`), in a fixed number of slots
        # (unused ones hold a far-away box) so that the shape, and with it the warm start, survives a change of
        # which boxes are near; a solution that comes close to a box left out is solved again with it
        def cold_guess() -> np.ndarray:
            return self._cold_guess(q, boxes, sph)

        guess: np.ndarray | None = None
        if self._ws is not None:
            # the last plan, shifted by the steps executed since and carried on past its horizon (`_shifted`)
            ref = self._shifted(self._ws[1].q, min(self._ws_offset, P.horizon - 1))[1:]
        else:
            ref = guess = cold_guess()
        near = self._near_boxes(np.vstack([q[None], ref]), sph, boxes, P.box_screen_m)
        lim = self.kin.joint_limits
        spent, iterations, rounds = 0.0, 0, 0
        own, pairs = self._self_set(obj)
        srows: SelfRows | None = None
        self_again, self_rounds = False, 0
        restart: SolveOutput | None = None
        restart_shape: ProblemShape | None = None
        while True:
            rounds += 1
            slotted, moved = self._fill_slots(near, boxes)
            shape = ProblemShape(P.horizon, len(slotted), obj.shape[0], P.constraint_substeps, P.self_slots)
            if shape not in self._problems:
                log.info("nmpc: building the NLP for %s inside a step (more boxes near than `box_slots`)", shape)
            prob = self.problem(shape)
            if srows is None or self_again:
                srows = self._self_rows(q, ref if restart is None else restart.q[1:], own, pairs)
            pself, self_lo = self._self_parameters(srows, own)
            p = np.concatenate([self._parameters(q, slotted, obj), pself])
            bounds = prob.bounds(lim[:, 0], lim[:, 1], step, dstep, jstep, facing_down=P.facing_down, self_lo=self_lo)
            if restart is not None and restart_shape == shape:  # again from the plan that broke the self rows
                lam_g0 = restart.lam_g.copy()
                lam_g0[prob.self_rows().reshape(-1)] = 0.0
                sol = prob.solve(restart.x, p, bounds, lam_x0=restart.lam_x, lam_g0=lam_g0)
            elif self._ws is not None and self._ws[0] == shape:
                prev = self._ws[1]
                k = self._ws_offset
                x0 = prob.with_knots(prob.shift(prev.x, prob.block_x, k), ref)
                lam_x0 = prob.shift(prev.lam_x, prob.block_x, k)
                lam_g0 = prob.shift(prev.lam_g, prob.block_g, k)
                lam_g0[prob.box_rows(moved)] = 0.0  # a slot that now holds another box starts without multipliers
                lam_g0[prob.self_rows().reshape(-1)] = 0.0  # the self slots hold other pairs now
                sol = prob.solve(x0, p, bounds, lam_x0=lam_x0, lam_g0=lam_g0)
            else:
                if guess is None:
                    guess = cold_guess()
                x0 = prob.pack_x(guess, guess_slack(self.kin, guess, sph, P))
                sol = prob.solve(x0, p, bounds)
            spent += sol.solve_time_s
            iterations += max(sol.iterations, 0)
            # every round adds a box left out, so this ends after at most len(boxes) + 1 rounds
            left = [b for b in boxes if all(b[0] != n[0] for n in near)]
            missed = [] if P.box_screen_m is None else self._near_boxes(sol.q, sph, left, P.box_screen_m / 2)
            # a plan that brings a pair of the self set closer than the rows chosen on the plan it started from
            # allow (a pair without a row there) is solved again, from itself, with the rows chosen on it
            self_again = (
                sol.converged
                and not missed
                and self_rounds < _SELF_ROUNDS
                and self._self_short(sol.q, own, pairs) is not None
            )
            if not sol.converged or not (missed or self_again):
                break
            if self_again:
                self_rounds += 1
                restart, restart_shape = sol, shape
                continue
            restart = None
            names = {b[0] for b in near + missed}
            near = [b for b in boxes if b[0] in names]
        entry = {
            "status": sol.status,
            "iterations": iterations,
            "boxes": len(near),
            "rounds": rounds,
            "self_rounds": self_rounds,
            "slots": shape.n_boxes,
        }
        problem = None if sol.converged else f"IPOPT: {sol.status}"
        return Solved(
            sol.q if sol.converged else None,
            problem,
            spent,
            sol.cost,
            entry,
            guess=guess,
            warm_start=(shape, sol),
            warm=sol.warm,
        )

    # ---- the self rows ---------------------------------------------------------------------------------
    def _self_set(self, obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The self set with the held object's spheres `obj` (m, 4) (TCP frame) and its pairs the rows keep apart
        (`twin.planning.selfrows.self_pairs`, those of a tool or held-object sphere with a forearm or upper-arm one)."""
        own = with_object(self._self_sph, obj)
        pairs = self._self_pairs.get(obj.shape[0])
        if pairs is None:
            g = link_groups(own)
            pairs = self_pairs(own)
            keep = (g[pairs[:, 0]] == 6) & np.isin(g[pairs[:, 1]], (2, 3)) | (g[pairs[:, 1]] == 6) & np.isin(
                g[pairs[:, 0]], (2, 3)
            )
            pairs = self._self_pairs[obj.shape[0]] = np.ascontiguousarray(pairs[keep])
        return own, pairs

    def _self_bound(self) -> float:
        """How far apart two spheres of the self set must stay, m: each covers its link only to within the box
        margin, so twice that (croc's bound)."""
        return 2 * self.params.box_margin_m

    def _self_rows(self, q: np.ndarray, ref: np.ndarray, own: np.ndarray, pairs: np.ndarray) -> SelfRows | None:
        """The self rows of the plan q, ref (N, 6) (`twin.planning.selfrows.self_rows`, croc's choice and margins)."""
        P = self.params
        if not P.self_slots:
            return None
        centres = sphere_positions(self.kin, np.vstack([q[None], ref]), own)
        return self_rows(
            centres,
            own[:, 4],
            pairs,
            slots=P.self_slots,
            within=P.self_screen_m,
            extra=self._self_bound() + P.self_tightening_m,
        )

    def _self_parameters(self, rows: SelfRows | None, own: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The NLP's self-slot parameters (per stage and slot: the tool sphere's offset in the TCP frame, the arm
        sphere's in its frame, 1 if that is frame 2) and the slots' lower bounds (N, slots) (-inf: open)."""
        P = self.params
        N, S = P.horizon, P.self_slots
        par = np.zeros((N, S, 7))
        lo = np.full((N, S), -np.inf)
        if rows is not None and S:
            pr, lo_rows = rows.pairs[1:], rows.lo[1:]
            used = pr[..., 0] >= 0
            g = link_groups(own)
            i, j = pr[..., 0], pr[..., 1]
            tool_first = g[i] == 6
            a = np.where(tool_first, i, j)
            b = np.where(tool_first, j, i)
            par[..., 0:3] = np.where(used[..., None], own[a, 1:4], 0.0)
            par[..., 3:6] = np.where(used[..., None], own[b, 1:4], 0.0)
            par[..., 6] = np.where(used, (own[b, 0] == 2).astype(float), 0.0)
            lo = np.where(used, lo_rows, -np.inf)
        return par.reshape(-1), lo

    def _self_short(self, knots: np.ndarray, own: np.ndarray, pairs: np.ndarray) -> str | None:
        """Why the knot path (m+1, 6) brings a pair of the self set closer than the self bound, between the knots
        too (`constraint_substeps` points per step), or None (`twin.planning.selfrows.self_violation`)."""
        if not self.params.self_slots or knots.shape[0] < 2 or pairs.shape[0] == 0:
            return None
        qs = np.vstack([knots[:1], subdivide(knots, self.params.constraint_substeps)])
        gaps = pair_gaps(sphere_positions(self.kin, qs, own), own[:, 4], pairs)
        return self_violation(gaps, bound=self._self_bound(), tol=CHECK_TOL_M)

    def _violation(self, knots: np.ndarray, sph: np.ndarray, boxes: list[Box]) -> str | None:
        """The loop's check of the hard constraints (`RecedingHorizonMPC._violation`) and of the self rows, as
        croc's: every pair the rows keep apart stays `_self_bound` apart, or no closer than it starts."""
        why = super()._violation(knots, sph, boxes)
        if why is not None:
            return why
        obj = sph[self._robot_sph.shape[0] :, 1:5]
        own, pairs = self._self_set(obj)
        return self._self_short(knots, own, pairs)

    def _parameters(self, q: np.ndarray, boxes: list[Box], obj: np.ndarray) -> np.ndarray:
        m = self.params.box_margin_m
        parts = [q, self._dq_prev, self._dq_prev2, self._target, self._track, [self.params.table_z_m]]
        for _, lo, hi in boxes:
            parts += [0.5 * (lo + hi), 0.5 * (hi - lo) + m]
        for s in obj:
            parts += [s[:3], [s[3]]]
        return np.concatenate([np.asarray(a, dtype=float).reshape(-1) for a in parts])

    def _fill_slots(self, near: list[Box], boxes: list[Box]) -> tuple[list[Box], list[int]]:
        """The boxes of the NLP's slots, and which slots changed box: a box keeps its slot while it is in the
        scene (its multipliers stay where they were); a near box without one takes a free slot, or the slot of
        a box no longer near, or a new slot (the planner's slot count only grows: one NLP shape, warm starts)."""
        by_name = {b[0]: b for b in boxes}
        near_names = {b[0] for b in near}
        old = list(self._slots) + [""] * (self._box_slots - len(self._slots))
        slots = [n if n in by_name else "" for n in old]
        for name in (b[0] for b in near):
            if name in slots:
                continue
            free = [i for i, n in enumerate(slots) if n == ""] or [
                i for i, n in enumerate(slots) if n not in near_names
            ]
            if free:
                slots[free[0]] = name
            else:
                slots.append(name)
        self._slots, self._box_slots = slots, len(slots)
        moved = [i for i, n in enumerate(slots) if i >= len(old) or n != old[i]]
        return [by_name[n] if n else _FAR_BOX for n in slots], moved

    def _near_boxes(self, knots: np.ndarray, sph: np.ndarray, boxes: list[Box], within: float | None) -> list[Box]:
        """The boxes the spheres come within `within` m of along the knot path (all of them when None), in order."""
        if within is None or not boxes:
            return list(boxes)
        P = self.params
        gaps = box_gaps(self.kin, knots, sph, boxes, box_margin_m=P.box_margin_m, substeps=P.constraint_substeps)
        return [b for b, g in zip(boxes, gaps, strict=True) if g < within]
