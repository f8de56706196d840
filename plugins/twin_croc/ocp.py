"""One solve of the seed formulation (`nmpc`'s, seeds 000/001) as a Crocoddyl problem for mim-solvers' CSQP.

Time is counted in MPC steps: a free inverse-dynamics action model integrated by Euler with a unit time step
makes the velocity state the joint step of one MPC step (q' = q + v', v' = v + a), so the seed's step bound
is a bound on the state. The seed's rows (`nmpc`'s without the acceleration and jerk rows it adds):
- cost: the tcp's distance from the goal at every knot, `terminal_weight_factor` times at the last; the
  joint step (`step_weight`); soft table clearance of every sphere; at the last knot soft facing down (a
  point 0.1 m along the tool axis straight below the goal: the yaw stays free);
- hard: joint limits and |step| <= `max_step_rad`; each proxy sphere outside each (margin-grown) box. A
  sphere-box pair is one frame-translation row per knot whose bounds say "beyond this face": the face the
  warm start's sphere is farthest out of, chosen per step and applied at both knots of the step (bounding the
  knots alone lets the path between them cut into the box). The rows are built once per problem shape and
  re-targeted (`updateBounds`) at each solve (rows for boxes beyond those given are left unbounded).

Not a planner yet (issue 28, in progress): `solve` is what the receding-horizon loop will call each step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import crocoddyl
import mim_solvers  # after crocoddyl (see twin_croc)
import numpy as np
import pinocchio as pin

from twin_croc.model import TCP_FRAME_NAME, arm_model, sphere_frames

if TYPE_CHECKING:
    from twin.plugin import UR5e

__all__ = ["SeedProblem", "Solve"]

_FREE = 1e9  # bounds of a row that is switched off
_AHEAD_M = 0.1  # the facing-down point: this far along the tool axis


@dataclass(frozen=True)
class Solve:
    """A solve's plan: joints (H+1, 6) and steps (H+1, 6) at the knots, whether CSQP converged, its
    iterations."""

    qs: np.ndarray
    steps: np.ndarray
    converged: bool
    iterations: int


class SeedProblem:
    """The seed formulation for a fixed horizon, sphere set and number of boxes; `solve` re-targets the goal,
    the boxes and the faces and warm-starts from a plan."""

    def __init__(
        self,
        kin: UR5e,
        spheres: np.ndarray,
        *,
        n_boxes: int,
        tcp_index: int,
        horizon: int = 30,
        max_step_rad: float = 0.15,
        position_weight: float = 1.0,
        terminal_weight_factor: float = 10.0,
        step_weight: float = 0.02,
        table_z_m: float = 0.0,
        table_clearance_m: float = 0.0,
        table_weight: float = 1e4,
        facing_down_weight: float = 1e3,
        box_margin_m: float = 0.01,
        max_iterations: int = 50,
        termination_tolerance: float = 1e-4,
    ):
        self.model = arm_model(kin)
        self.spheres = np.asarray(spheres, dtype=float)
        self.radii = self.spheres[:, 4]
        self.sphere_ids = sphere_frames(self.model, self.spheres, tcp_index=tcp_index)
        tcp = self.model.getFrameId(TCP_FRAME_NAME)
        ahead = self.model.frames[tcp].placement * pin.SE3(np.eye(3), np.array([0.0, 0.0, _AHEAD_M]))
        self.ahead_id = self.model.addFrame(
            pin.Frame("ahead", self.model.frames[tcp].parentJoint, ahead, pin.FrameType.OP_FRAME)
        )
        self.data = self.model.createData()
        self.horizon, self.n_boxes, self.margin = horizon, n_boxes, box_margin_m
        self.max_iterations = max_iterations
        state = crocoddyl.StateMultibody(self.model)
        actuation = crocoddyl.ActuationModelFull(state)
        nu = actuation.nu
        self._goal_rows: list[crocoddyl.ResidualModelFrameTranslation] = []
        self._face_rows: list[list[crocoddyl.ConstraintModelResidual]] = []  # per knot: (2 steps x boxes x spheres)
        lb = np.concatenate([self.model.lowerPositionLimit, np.full(6, -max_step_rad)])
        ub = np.concatenate([self.model.upperPositionLimit, np.full(6, max_step_rad)])
        models = []
        for k in range(horizon + 1):
            terminal = k == horizon
            costs = crocoddyl.CostModelSum(state, nu)
            goal = crocoddyl.ResidualModelFrameTranslation(state, tcp, np.zeros(3), nu)
            self._goal_rows.append(goal)
            weight = position_weight * (terminal_weight_factor if terminal else 1.0)
            costs.addCost("position", crocoddyl.CostModelResidual(state, goal), weight)
            steps = np.concatenate([np.zeros(6), np.ones(6)])
            costs.addCost(
                "step",
                crocoddyl.CostModelResidual(
                    state,
                    crocoddyl.ActivationModelWeightedQuad(steps),
                    crocoddyl.ResidualModelState(state, np.zeros(state.nx), nu),
                ),
                step_weight,
            )
            if not terminal:
                costs.addCost(
                    "control", crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelControl(state, nu)), 1e-4
                )
            for s, fid in enumerate(self.sphere_ids):
                floor = np.array([-_FREE, -_FREE, table_z_m + table_clearance_m + self.radii[s]])
                barrier = crocoddyl.ActivationModelQuadraticBarrier(
                    crocoddyl.ActivationBounds(floor, np.full(3, _FREE))
                )
                row = crocoddyl.ResidualModelFrameTranslation(state, fid, np.zeros(3), nu)
                costs.addCost(f"table{s}", crocoddyl.CostModelResidual(state, barrier, row), table_weight)
            if terminal:
                self._ahead_row = crocoddyl.ResidualModelFrameTranslation(state, self.ahead_id, np.zeros(3), nu)
                costs.addCost("facing_down", crocoddyl.CostModelResidual(state, self._ahead_row), facing_down_weight)
            constraints = crocoddyl.ConstraintModelManager(state, nu)
            if k > 0:
                constraints.addConstraint(
                    "limits",
                    crocoddyl.ConstraintModelResidual(
                        state, crocoddyl.ResidualModelState(state, np.zeros(state.nx), nu), lb, ub
                    ),
                )
            rows = []
            for j in range(2 * n_boxes * len(self.sphere_ids)):
                fid = self.sphere_ids[j % len(self.sphere_ids)]
                row = crocoddyl.ConstraintModelResidual(
                    state,
                    crocoddyl.ResidualModelFrameTranslation(state, fid, np.zeros(3), nu),
                    np.full(3, -_FREE),
                    np.full(3, _FREE),
                )
                constraints.addConstraint(f"face{j}", row)
                rows.append(row)
            self._face_rows.append(rows)
            dam = crocoddyl.DifferentialActionModelFreeInvDynamics(state, actuation, costs, constraints)
            models.append(crocoddyl.IntegratedActionModelEuler(dam, 0.0 if terminal else 1.0))
        self.problem = crocoddyl.ShootingProblem(np.zeros(state.nx), models[:-1], models[-1])
        self.solver = mim_solvers.SolverCSQP(self.problem)
        self.solver.reg_min = 1e-2  # the default cycles on these problems (issue 28's spike)
        self.solver.max_qp_iters = 1000
        # CSQP's default (1e-6 on the KKT residual) is never met with reg_min at 1e-2: the residual stalls near
        # 7e-5 after ~10 iterations while the plan no longer moves (measured over the warehouse wall: the same
        # tcp error to 0.1 mm at 10 and at 200 iterations), so every solve ran to its iteration cap
        self.solver.termination_tolerance = termination_tolerance

    def centres(self, qs: np.ndarray) -> np.ndarray:
        """(m, n, 3) sphere centres for joints (m, 6)."""
        out = np.empty((len(qs), len(self.sphere_ids), 3))
        for i, q in enumerate(qs):
            pin.framesForwardKinematics(self.model, self.data, q)
            out[i] = [self.data.oMf[f].translation for f in self.sphere_ids]
        return out

    def _faces(self, centres: np.ndarray, boxes: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[np.ndarray]:
        """Per step (H,) and box: (spheres, 3, 2) lower/upper bounds on the centres that keep each sphere
        beyond the box face its centre is farthest out of over the step's two knots."""
        out = []
        for k in range(self.horizon):
            per_box = []
            for lo, hi in boxes:
                lo_m, hi_m = np.asarray(lo) - self.margin, np.asarray(hi) + self.margin
                bounds = np.empty((len(self.sphere_ids), 3, 2))
                bounds[:, :, 0], bounds[:, :, 1] = -_FREE, _FREE
                for s in range(len(self.sphere_ids)):
                    c = 0.5 * (centres[k, s] + centres[k + 1, s])
                    outside = np.concatenate([c - hi_m, lo_m - c])  # +x +y +z -x -y -z
                    f = int(np.argmax(outside))
                    axis, upper = f % 3, f < 3
                    if upper:
                        bounds[s, axis, 0] = hi_m[axis] + self.radii[s]
                    else:
                        bounds[s, axis, 1] = lo_m[axis] - self.radii[s]
                per_box.append(bounds)
            out.append(np.array(per_box))
        return out

    def solve(
        self,
        q0: np.ndarray,
        step0: np.ndarray,
        goal: np.ndarray,
        boxes: Sequence[tuple[np.ndarray, np.ndarray]],
        guess: np.ndarray,
    ) -> Solve:
        """Solve from joints `q0` and last step `step0` towards the tcp position `goal` (3,), the spheres kept
        out of `boxes` ((lo, hi) each, without the margin; at most `n_boxes`), warm-started from the joint
        plan `guess` (H+1, 6) (the last plan shifted, or an initial guess)."""
        if len(boxes) > self.n_boxes:
            raise ValueError(f"{len(boxes)} boxes, the problem has rows for {self.n_boxes}")
        goal = np.asarray(goal, dtype=float)
        for row in self._goal_rows:
            row.reference = goal
        self._ahead_row.reference = goal - np.array([0.0, 0.0, _AHEAD_M])
        faces = self._faces(self.centres(guess), boxes)
        n = len(self.sphere_ids)
        for k, rows in enumerate(self._face_rows):
            for row in rows:
                row.updateBounds(np.full(3, -_FREE), np.full(3, _FREE))
            for half, step in ((0, k - 1), (1, k)):  # the step ending here and the one starting here
                if not 0 <= step < self.horizon:
                    continue
                for b in range(len(boxes)):
                    for s in range(n):
                        lo, hi = faces[step][b, s, :, 0], faces[step][b, s, :, 1]
                        rows[(half * self.n_boxes + b) * n + s].updateBounds(lo, hi)
        x0 = np.concatenate([q0, step0])
        self.problem.x0 = x0
        steps = np.vstack([step0, np.diff(guess, axis=0)])
        xs = [np.concatenate([q, v]) for q, v in zip(guess, steps, strict=True)]
        xs[0] = x0
        us = [np.zeros(6)] * self.horizon
        converged = bool(self.solver.solve(xs, us, self.max_iterations))
        X = np.array(self.solver.xs)
        return Solve(X[:, :6].copy(), X[:, 6:].copy(), converged, int(self.solver.iter))
