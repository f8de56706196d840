"""The MPC's horizon as a Crocoddyl problem for mim-solvers' CSQP: the seed formulation (`nmpc`'s, seeds
000/001) with any set of proxy spheres, re-targeted and warm-started from solve to solve.

Time is counted in MPC steps: a free inverse-dynamics action model integrated by Euler with a unit time step
makes the velocity state the joint step of one MPC step (q' = q + v', v' = v + a), so the seed's step bound
is a bound on the state and the control (a) is the change of the step, which the request's acceleration
limit bounds (`nmpc`'s `limit_acceleration`). The rows:
- cost: the tcp's distance from the goal at every knot, `terminal_weight_factor` times at the last; the
  joint step (`step_weight`); soft table clearance of every sphere; at the last knot soft facing down (a
  point 0.1 m along the tool axis straight below the goal: the yaw stays free);
- hard: joint limits and |step| <= the step bound at every knot after the first, |step change| <= the
  acceleration bound; and one row per sphere and knot: its centre (a frame translation) within bounds, the
  axis-aligned region that keeps it beyond a face of every box near it (`twin_croc.rows`), re-set at each
  solve. Only rows whose bounds changed are touched: a warm start shifts the plan, and the bounds with it,
  so most stay as they were; and, in a problem built with self slots, up to `self_slots` rows per knot, each
  the distance of two spheres on links that are not neighbours (`twin.planning.selfrows`), re-targeted per solve.

The held object's spheres are frames on the tcp whose placements change per goal (`set_object`), so the
problem is built once per sphere model and horizon.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import crocoddyl
import mim_solvers  # after crocoddyl (see twin_croc)
import numpy as np
import pinocchio as pin

from twin.plugin import SelfRows, Weights  # the seed's cost weights, nmpc's too
from twin_croc.pinocchio_arm import TCP_FRAME_NAME, arm_model, sphere_frames

if TYPE_CHECKING:
    from twin.plugin import URArm

__all__ = ["HorizonProblem", "PairDistances", "Solve"]

# a constraint row's open bound: infinite, which CSQP recognises (a row open on both sides gets the smallest ADMM
# penalty, rho_min, so it costs the QP nothing: with 1e9 instead, the QP of a warm solve took ~100 ADMM
# iterations); the cost barriers' open side stays finite (ActivationBounds takes the midpoint of its bounds)
_OPEN = np.inf
_FAR = 1e9
_AHEAD_M = 0.1  # the facing-down point: this far along the tool axis
SEED_WEIGHTS = Weights(1.0, 10.0, 0.02, 1e4, 1e3)  # position, terminal factor, step, table, facing down


def _one_thread(problem: crocoddyl.ShootingProblem) -> None:
    """Run the problem's knots on one thread. A problem with a model written in Python (`PairDistances`) runs on
    one already, and Crocoddyl answers setting it with "Warning: the number of threads won't affect the
    computational performance ..." on stderr each time: set it only when it is not 1."""
    if problem.nthreads != 1:
        problem.nthreads = 1


class PairDistances(crocoddyl.ResidualModelAbstract):  # type: ignore[misc]
    """The distances between pairs of frames' origins (sphere centres), one row per slot, re-targetable (`pairs`:
    per slot a pair of frame ids, or None: the row reads 0 and is left open). A Python residual: crocoddyl has no
    point-to-point distance, and one residual for all of a knot's slots makes one call from C++ instead of one
    per slot."""

    def __init__(self, state: crocoddyl.StateMultibody, nu: int, slots: int):
        super().__init__(state, slots, nu, True, False, False)
        self.pairs: list[tuple[int, int] | None] = [None] * slots
        self._model = state.pinocchio
        self._nv = state.nv
        self._r = np.zeros(slots)
        self._rx = np.zeros((slots, state.nx))

    def _delta(self, pd: pin.Data, pair: tuple[int, int]) -> np.ndarray:
        a, b = pair
        m = self._model
        return pin.updateFramePlacement(m, pd, a).translation - pin.updateFramePlacement(m, pd, b).translation

    def calc(self, data: crocoddyl.ResidualDataAbstract, x: np.ndarray, u: np.ndarray | None = None) -> None:
        pd, r = data.shared.pinocchio, self._r
        for i, pair in enumerate(self.pairs):
            r[i] = 0.0 if pair is None else float(np.linalg.norm(self._delta(pd, pair)))
        data.r[:] = r

    def calcDiff(self, data: crocoddyl.ResidualDataAbstract, x: np.ndarray, u: np.ndarray | None = None) -> None:
        pd, m, rx, nv = data.shared.pinocchio, self._model, self._rx, self._nv
        frame = pin.LOCAL_WORLD_ALIGNED
        for i, pair in enumerate(self.pairs):
            if pair is None:
                rx[i] = 0.0
                continue
            d = self._delta(pd, pair)
            n = d / max(float(np.linalg.norm(d)), 1e-9)
            ja = pin.getFrameJacobian(m, pd, pair[0], frame)[:3]
            jb = pin.getFrameJacobian(m, pd, pair[1], frame)[:3]
            rx[i, :nv] = n @ (ja - jb)
        data.Rx[:] = rx


def _step_cost(state: crocoddyl.StateMultibody, nu: int) -> crocoddyl.CostModelResidual:
    """The joint step (the velocity half of the state) squared."""
    return crocoddyl.CostModelResidual(
        state,
        crocoddyl.ActivationModelWeightedQuad(np.concatenate([np.zeros(6), np.ones(6)])),
        crocoddyl.ResidualModelState(state, np.zeros(state.nx), nu),
    )


def _control_cost(state: crocoddyl.StateMultibody, nu: int) -> crocoddyl.CostModelResidual:
    """The change of the step (the control) squared: a small regularisation."""
    return crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelControl(state, nu))


def _acceleration_row(state: crocoddyl.StateMultibody, nu: int) -> crocoddyl.ConstraintModelResidual:
    """|step change| <= the acceleration bound (set per solve; open until then)."""
    return crocoddyl.ConstraintModelResidual(
        state, crocoddyl.ResidualModelControl(state, nu), np.full(6, -_OPEN), np.full(6, _OPEN)
    )


def _state_row(state: crocoddyl.StateMultibody, nu: int) -> crocoddyl.ConstraintModelResidual:
    """Joint limits and |step| <= the step bound, on the state (set per solve; open until then)."""
    return crocoddyl.ConstraintModelResidual(
        state,
        crocoddyl.ResidualModelState(state, np.zeros(state.nx), nu),
        np.full(state.nx, -_OPEN),
        np.full(state.nx, _OPEN),
    )


@dataclass(frozen=True)
class Solve:
    """A solve's plan: joints (H+1, 6) and steps (H+1, 6) at the knots; whether CSQP met its tolerance, its
    iterations, the cost."""

    qs: np.ndarray
    steps: np.ndarray
    converged: bool
    iterations: int
    cost: float


class HorizonProblem:
    """The formulation for a fixed horizon, sphere model (`spheres` (n, 5) = frame, x, y, z, r; frame a DH
    frame 1..6 or `tcp_index`) and number of held-object spheres; with `self_slots` > 0, that many self rows per
    knot between the spheres `self_spheres` (m, 5), then the held object's."""

    def __init__(
        self,
        kin: URArm,
        spheres: np.ndarray,
        *,
        tcp_index: int,
        n_object: int = 0,
        horizon: int = 30,
        acceleration_rows: bool = True,
        weights: Weights = SEED_WEIGHTS,
        table_z_m: float = 0.0,
        table_clearance_m: float = 0.0,
        termination_tolerance: float = 1e-3,
        qp_tolerance: float = 3e-3,
        self_spheres: np.ndarray | None = None,
        self_slots: int = 0,
    ):
        self.model = arm_model(kin)
        self._add_sphere_frames(spheres, tcp_index, n_object, self_spheres, self_slots)
        self._add_track_frames()
        self.data = self.model.createData()
        self.horizon, self.acceleration_rows = horizon, acceleration_rows
        self._table_floor = table_z_m + table_clearance_m
        state = crocoddyl.StateMultibody(self.model)
        self._pin_model = state.pinocchio  # the model the residuals read (the object frames are set on it)
        actuation = crocoddyl.ActuationModelFull(state)
        self._goal_rows: list[crocoddyl.ResidualModelFrameTranslation] = []
        self._table_rows: list[list[crocoddyl.ActivationModelQuadraticBarrier]] = []
        self._spheres: list[list[crocoddyl.ConstraintModelResidual]] = []  # per knot: one row per sphere
        self._limits: list[crocoddyl.ConstraintModelResidual | None] = []
        self._accel: list[crocoddyl.ConstraintModelResidual | None] = []
        self._self: list[tuple[PairDistances, crocoddyl.ConstraintModelResidual] | None] = []  # per knot
        models = [self._knot(state, actuation, k, weights) for k in range(horizon + 1)]
        self._open_rows()
        self.problem = crocoddyl.ShootingProblem(np.zeros(state.nx), models[:-1], models[-1])
        # one thread: a horizon of 30 small knots gains little from threads, and compare runs in workers. NB: a NaN
        # in a step makes CSQP throw inside its OpenMP loop, which aborts the process instead of reaching Python
        _one_thread(self.problem)
        self._bound_slack = 2 * qp_tolerance
        self._tolerances = (termination_tolerance, qp_tolerance)
        self.solver = self._new_solver()
        self._last: tuple[np.ndarray, np.ndarray, list[np.ndarray]] | None = None  # xs, us, duals
        self.set_track(np.zeros(3))

    # ---- the formulation's terms: each builds one named piece (the constructor reads as their list) ----------
    def _add_sphere_frames(
        self, spheres: np.ndarray, tcp_index: int, n_object: int, self_spheres: np.ndarray | None, self_slots: int
    ) -> None:
        """A frame per sphere of the robot and of the held object (parked at the tcp, r 0.01, until `set_object`),
        then per sphere of the self set."""
        robot = np.asarray(spheres, dtype=float).reshape(-1, 5)
        obj = np.column_stack([np.full(n_object, tcp_index), np.zeros((n_object, 3)), np.full(n_object, 0.01)])
        self.n_robot, self.n_object = robot.shape[0], n_object
        self.radii = np.concatenate([robot[:, 4], obj[:, 4]])
        self.sphere_ids = sphere_frames(self.model, np.vstack([robot, obj]), tcp_index=tcp_index)
        # the self set's frames only where self rows read them (crocoddyl places every frame of the model at every
        # knot: the whole arm's 38 more cost seed mode ~25 % per iteration)
        own = np.zeros((0, 5)) if self_spheres is None or not self_slots else np.asarray(self_spheres, dtype=float)
        own = own.reshape(-1, 5)
        self.self_slots = self_slots if own.shape[0] else 0
        self._self_ids = np.array(
            sphere_frames(self.model, own, tcp_index=tcp_index, prefix="self") + self.sphere_ids[len(robot) :],
            dtype=int,
        )

    def _add_track_frames(self) -> None:
        """The point that goes to the goal (`set_track`: the tcp, or the flange for a flange goal), and the
        facing-down point 0.1 m further along the tool axis."""
        tcp = self.model.getFrameId(TCP_FRAME_NAME)
        self._tcp_placement = self.model.frames[tcp].placement.copy()
        joint = self.model.frames[tcp].parentJoint
        track = self.model.addFrame(pin.Frame("track", joint, self._tcp_placement, pin.FrameType.OP_FRAME))
        ahead_id = self.model.addFrame(pin.Frame("ahead", joint, self._tcp_placement, pin.FrameType.OP_FRAME))
        self._track_ids = (track, ahead_id)

    def _knot(
        self, state: crocoddyl.StateMultibody, actuation: crocoddyl.ActuationModelFull, k: int, weights: Weights
    ) -> crocoddyl.IntegratedActionModelEuler:
        """Knot k's action model: its costs and constraints (the terminal knot: no control, the heavier position
        cost and facing down; the first knot, the measured state: no state rows)."""
        terminal = k == self.horizon
        nu = actuation.nu
        costs = crocoddyl.CostModelSum(state, nu)
        position = weights.position * (weights.terminal_factor if terminal else 1.0)
        costs.addCost("position", self._position_cost(state, nu), position)
        costs.addCost("step", _step_cost(state, nu), weights.step)
        if not terminal:
            costs.addCost("control", _control_cost(state, nu), 1e-4)
        for s, table in enumerate(self._table_costs(state, nu)):
            costs.addCost(f"table{s:03d}", table, weights.table_slack)
        if terminal:
            costs.addCost("facing_down", self._facing_down_cost(state, nu), weights.facing_down_slack)
        # the manager orders its rows by name: a_accel (6), b_limits (12), c_sphere000 .. (3 each), d_self
        constraints = crocoddyl.ConstraintModelManager(state, nu)
        accel = _acceleration_row(state, nu) if self.acceleration_rows and not terminal else None
        if accel is not None:
            constraints.addConstraint("a_accel", accel)
        limits = _state_row(state, nu) if k > 0 else None  # the first knot is the measured state
        if limits is not None:
            constraints.addConstraint("b_limits", limits)
        rows = self._sphere_rows(state, nu) if k > 0 else []
        for j, row in enumerate(rows):
            constraints.addConstraint(f"c_sphere{j:03d}", row)
        self_row = self._self_row(state, nu) if self.self_slots and k > 0 else None
        if self_row is not None:
            constraints.addConstraint("d_self", self_row[1])
        self._self.append(self_row)
        self._accel.append(accel)
        self._limits.append(limits)
        self._spheres.append(rows)
        dam = crocoddyl.DifferentialActionModelFreeInvDynamics(state, actuation, costs, constraints)
        return crocoddyl.IntegratedActionModelEuler(dam, 0.0 if terminal else 1.0)

    def _position_cost(self, state: crocoddyl.StateMultibody, nu: int) -> crocoddyl.CostModelResidual:
        """The tracked point's distance from the goal (the goal is set per solve)."""
        goal = crocoddyl.ResidualModelFrameTranslation(state, self._track_ids[0], np.zeros(3), nu)
        self._goal_rows.append(goal)
        return crocoddyl.CostModelResidual(state, goal)

    def _table_costs(self, state: crocoddyl.StateMultibody, nu: int) -> list[crocoddyl.CostModelResidual]:
        """Per sphere the soft table clearance: a barrier on its centre's height (the object's re-set by
        `set_object`)."""
        barriers, costs = [], []
        for s, fid in enumerate(self.sphere_ids):
            floor = np.array([-_FAR, -_FAR, self._table_floor + self.radii[s]])
            barrier = crocoddyl.ActivationModelQuadraticBarrier(crocoddyl.ActivationBounds(floor, np.full(3, _FAR)))
            row = crocoddyl.ResidualModelFrameTranslation(state, fid, np.zeros(3), nu)
            costs.append(crocoddyl.CostModelResidual(state, barrier, row))
            barriers.append(barrier)
        self._table_rows.append(barriers)
        return costs

    def _facing_down_cost(self, state: crocoddyl.StateMultibody, nu: int) -> crocoddyl.CostModelResidual:
        """The facing-down point's distance from the point below the goal (the yaw stays free)."""
        self._ahead_row = crocoddyl.ResidualModelFrameTranslation(state, self._track_ids[1], np.zeros(3), nu)
        return crocoddyl.CostModelResidual(state, self._ahead_row)

    def _sphere_rows(self, state: crocoddyl.StateMultibody, nu: int) -> list[crocoddyl.ConstraintModelResidual]:
        """Per sphere its centre within bounds (`twin_croc.rows`, set per solve; open until then)."""
        return [
            crocoddyl.ConstraintModelResidual(
                state,
                crocoddyl.ResidualModelFrameTranslation(state, fid, np.zeros(3), nu),
                np.full(3, -_OPEN),
                np.full(3, _OPEN),
            )
            for fid in self.sphere_ids
        ]

    def _self_row(
        self, state: crocoddyl.StateMultibody, nu: int
    ) -> tuple[PairDistances, crocoddyl.ConstraintModelResidual]:
        """The knot's self rows: `self_slots` pair distances, re-targeted per solve (`_set_self`; open until then)."""
        dist = PairDistances(state, nu, self.self_slots)
        open_ = np.full(self.self_slots, _OPEN)
        return dist, crocoddyl.ConstraintModelResidual(state, dist, -open_, open_)

    def _open_rows(self) -> None:
        """What the rows hold now, all open: where each knot's sphere rows start in its duals (after a_accel and
        b_limits), the sphere rows' bounds and the self rows' pairs (sphere indices of the self set, -1: open) and
        lower bounds."""
        self._sphere_offset = [(6 if a is not None else 0) + (12 if k > 0 else 0) for k, a in enumerate(self._accel)]
        self._bounds = np.empty((self.horizon + 1, len(self.sphere_ids), 2, 3))
        self._bounds[:, :, 0], self._bounds[:, :, 1] = -_OPEN, _OPEN
        self._bounds_now: dict[str, tuple[bytes, bytes]] = {}
        self._self_pairs = np.full((self.horizon + 1, self.self_slots, 2), -1, dtype=int)
        self._self_lo = np.full((self.horizon + 1, self.self_slots), -_OPEN)

    def renew(self) -> None:
        """Crocoddyl's data of every knot and the solver as new (~5 ms for the whole arm with self rows). Some
        state of the data outlives a solve: with sphere rows re-targeted between problems (tried, not kept: it
        saved no time), the same request planned again after other goals took other QP iterations and another
        path while every model, bound and input was the same (the contract's determinism check). The planner
        renews the problems a goal used before the next goal, so a goal's plan cannot depend on the goals before
        it."""
        self.problem = crocoddyl.ShootingProblem(
            self.problem.x0, list(self.problem.runningModels), self.problem.terminalModel
        )
        _one_thread(self.problem)
        self.solver = self._new_solver()
        self._last = None

    def _new_solver(self) -> mim_solvers.SolverCSQP:
        """A CSQP solver of this problem in its first state (~0.1 ms): a cold solve, and the first from another
        problem's solution, get a new one (CSQP keeps its ADMM state, the QP's slacks and the penalty it adapted,
        from solve to solve)."""
        solver = mim_solvers.SolverCSQP(self.problem)
        solver.reg_min = 1e-2  # the default cycles on these problems (issue 28's spike)
        solver.max_qp_iters = 1000
        # CSQP's defaults (1e-6 on the KKT residual, 1e-4 on the ADMM QP's) are never met here once the
        # acceleration rows are active: over the warehouse wall every SQP iteration ran its QP to 1000 ADMM
        # iterations (~30 ms) and the KKT residual stalled near 1e-4 for 100 iterations while the plan no longer
        # moved. The QP's tolerance is also how well it keeps bounds: the joint, step and acceleration bounds
        # are tightened by twice it (one QP tolerance let a step of 0.152 rad through a 0.15 bound), the sphere
        # rows by the planner's `row_tightening_m`
        solver.termination_tolerance, qp_tolerance = self._tolerances
        solver.eps_abs = qp_tolerance
        solver.eps_rel = qp_tolerance
        solver.reset_y = False  # the duals are warm-started (shifted) by `solve`
        solver.reset_rho = True  # (from the penalty it adapted last: within a goal)
        return solver

    # ---- re-targeting -----------------------------------------------------------------------------------
    def set_object(self, obj: np.ndarray) -> None:
        """The held object's spheres (m, 4) = (x, y, z, r) in the tcp frame, m <= n_object (the others are
        parked at the tcp; give them no rows)."""
        obj = np.asarray(obj, dtype=float).reshape(-1, 4)
        if obj.shape[0] > self.n_object:
            raise ValueError(f"{obj.shape[0]} held-object spheres, the problem has frames for {self.n_object}")
        for i in range(self.n_object):
            fid = self.sphere_ids[self.n_robot + i]
            x = obj[i, :3] if i < obj.shape[0] else np.zeros(3)
            self._pin_model.frames[fid].placement = self._tcp_placement * pin.SE3(np.eye(3), x)
            r = obj[i, 3] if i < obj.shape[0] else 0.01
            self.radii[self.n_robot + i] = r
            floor = np.array([-_FAR, -_FAR, self._table_floor + r])
            for barriers in self._table_rows:
                barriers[self.n_robot + i].bounds = crocoddyl.ActivationBounds(floor, np.full(3, _FAR))

    def set_track(self, offset: np.ndarray) -> None:
        """The point that goes to the goal: `offset` (3,) in the tcp frame (on the tool axis)."""
        offset = np.asarray(offset, dtype=float)
        track, ahead = self._track_ids
        self._pin_model.frames[track].placement = self._tcp_placement * pin.SE3(np.eye(3), offset)
        ahead_at = offset + np.array([0.0, 0.0, _AHEAD_M])
        self._pin_model.frames[ahead].placement = self._tcp_placement * pin.SE3(np.eye(3), ahead_at)

    def _set(self, key: str, row: crocoddyl.ConstraintModelResidual, lo: np.ndarray, hi: np.ndarray) -> None:
        """updateBounds only when the bounds change (most stay the same from solve to solve)."""
        now = (lo.tobytes(), hi.tobytes())
        if self._bounds_now.get(key) != now:
            row.updateBounds(lo, hi)
            self._bounds_now[key] = now

    def _set_spheres(self, bounds: np.ndarray) -> None:
        """Set the sphere rows to `bounds` (H+1, n, 2, 3) where they changed."""
        changed = np.any(bounds != self._bounds, axis=(2, 3))
        changed[0] = False  # the first knot has no sphere rows (the measured state)
        for k, j in zip(*np.nonzero(changed), strict=True):
            self._spheres[k][j].updateBounds(bounds[k, j, 0], bounds[k, j, 1])
        self._bounds = bounds.copy()

    def _set_self(self, rows: SelfRows | None) -> None:
        """Set the self rows to `rows` (sphere indices of the self set, then the held object's); None opens them
        all."""
        if not self.self_slots:
            if rows is not None:
                raise ValueError("self rows for a problem built without self slots")
            return
        if rows is None:
            pairs = np.full_like(self._self_pairs, -1)
            lo = np.full_like(self._self_lo, -_OPEN)
        else:
            pairs, lo = np.asarray(rows.pairs, dtype=int), np.asarray(rows.lo, dtype=float)
        changed = np.any(pairs != self._self_pairs, axis=(1, 2)) | np.any(lo != self._self_lo, axis=1)
        changed[0] = False
        for k in np.nonzero(changed)[0]:
            dist, row = self._self[k]  # type: ignore[misc]
            ids = self._self_ids
            dist.pairs = [None if a < 0 else (int(ids[a]), int(ids[b])) for a, b in pairs[k]]
            row.updateBounds(np.where(pairs[k, :, 0] < 0, -_OPEN, lo[k]), np.full(self.self_slots, _OPEN))
        self._self_pairs, self._self_lo = pairs.copy(), lo.copy()

    # ---- solving ----------------------------------------------------------------------------------------
    def centres(self, qs: np.ndarray) -> np.ndarray:
        """(m, n, 3) sphere centres for joints (m, 6) (pinocchio's; twin's own are `sphere_positions`)."""
        out = np.empty((len(qs), len(self.sphere_ids), 3))
        for i, q in enumerate(qs):
            pin.framesForwardKinematics(self._pin_model, self.data, q)
            out[i] = [self.data.oMf[f].translation for f in self.sphere_ids]
        return out

    def solve(
        self,
        q0: np.ndarray,
        step0: np.ndarray,
        goal: np.ndarray,
        bounds: np.ndarray,
        *,
        step_bound: np.ndarray,
        accel_bound: np.ndarray | None = None,
        guess: np.ndarray | None = None,
        shift: int = 0,
        max_iterations: int = 50,
        self_rows: SelfRows | None = None,
        source: HorizonProblem | None = None,
    ) -> Solve:
        """Solve from joints `q0` and last step `step0` towards the goal position `goal` (3,) of the tracked point
        with each sphere's centre within `bounds` (H+1, n, 2, 3) (`twin_croc.rows`; knot 0's are not used; n: the
        robot's spheres, then the object's, parked ones free), steps within `step_bound` (6,) and step changes within
        `accel_bound` (6,), and the self rows `self_rows` (`twin.planning.selfrows`; None: none). Cold from the joint
        plan `guess` (H+1, 6), or warm (guess None): the last solution (of `source`, the same problem with or
        without self rows, if given) shifted by `shift` executed steps, primal and dual (a row's duals kept only
        where its bounds are those of the knot `shift` later)."""
        goal = np.asarray(goal, dtype=float)
        for row in self._goal_rows:
            row.reference = goal
        self._ahead_row.reference = goal - np.array([0.0, 0.0, _AHEAD_M])
        # the QP holds bounds to about its tolerance: the joint, step and step-change bounds are tightened by it
        eps = self._bound_slack
        lo_x = np.concatenate([self.model.lowerPositionLimit + eps, -(step_bound - eps)])
        hi_x = np.concatenate([self.model.upperPositionLimit - eps, step_bound - eps])
        a = np.full(6, _OPEN) if accel_bound is None else np.asarray(accel_bound, dtype=float) - eps
        for k in range(self.horizon + 1):
            lim, acc = self._limits[k], self._accel[k]
            if lim is not None:
                self._set(f"l{k}", lim, lo_x, hi_x)
            if acc is not None:
                self._set(f"a{k}", acc, -a, a)
        before, self_before = self._bounds, (self._self_pairs, self._self_lo)
        self._set_spheres(np.asarray(bounds, dtype=float))
        self._set_self(self_rows)
        if guess is not None or source not in (None, self):
            self.solver = self._new_solver()
        x0 = np.concatenate([q0, step0])
        self.problem.x0 = x0
        H = self.horizon
        if guess is None:
            src_prob = self if source is None else source
            if src_prob._last is None:
                raise ValueError("a warm solve needs an earlier solve; give a guess")
            if src_prob is not self:
                if len(src_prob.sphere_ids) != len(self.sphere_ids) or src_prob.horizon != H:
                    raise ValueError("a warm start from a problem with other sphere rows or another horizon")
                before = src_prob._bounds
                self_before = (src_prob._self_pairs, src_prob._self_lo)
            xs_prev, us_prev, y_prev = src_prob._last
            same_slots = src_prob.self_slots == self.self_slots
            idx = np.minimum(np.arange(H + 1) + shift, H)
            X = xs_prev[idx].copy()
            X[idx == H, 6:] = 0.0  # past the old horizon: resting at its last knot
            U = np.vstack([us_prev[shift:], np.zeros((min(shift, H), 6))])[:H]
            duals = []
            for k, now in enumerate(self.solver.y):
                # a knot's duals come from the knot `shift` later when that one has the same rows (a running knot's
                # from a running knot; the terminal knot has no acceleration row): giving CSQP a dual vector of
                # another length corrupts its memory (NaN steps some solves later). From the problem without (or
                # with) self rows, the rows before them are the same, the self rows' duals start at zero
                y = np.zeros(len(now))
                src = k + shift
                if k > 0 and src <= H and (src < H) == (k < H):
                    off = self._sphere_offset[k]
                    common = off + 3 * len(self.sphere_ids)
                    y[:common] = y_prev[src][:common]
                    for j in np.nonzero(np.any(self._bounds[k] != before[src], axis=(1, 2)))[0]:
                        y[off + 3 * j : off + 3 * j + 3] = 0.0
                    if same_slots and self.self_slots:
                        y[common:] = y_prev[src][common:]
                        moved = np.any(self._self_pairs[k] != self_before[0][src], axis=1)
                        moved |= self._self_lo[k] != self_before[1][src]
                        y[common:][moved] = 0.0
                duals.append(y)
        else:
            steps = np.vstack([step0, np.diff(guess, axis=0)])
            X = np.hstack([guess, steps])
            U = np.diff(steps, axis=0)
            duals = [np.zeros_like(y) for y in self.solver.y]
        X[0] = x0
        self.solver.y = duals
        converged = bool(self.solver.solve(list(X), list(U), max_iterations))
        xs, us = np.array(self.solver.xs), np.array(self.solver.us)
        self._last = (xs, us, [np.array(y) for y in self.solver.y])
        return Solve(xs[:, :6].copy(), xs[:, 6:].copy(), converged, int(self.solver.iter), float(self.solver.cost))
