"""Other solvers for the `nmpc` problem, side by side with the planner's IPOPT, on the solves of real runs.

`bench_nmpc.py --alternatives N` records every solve of N seeded warehouse transfers (seed 000: dt 0.08 s, one
step per solve) and replays the ones of the most common problem shape through each alternative. A warm solve
starts from the alternative's own previous solution shifted by the executed step (primal and, where the
interface takes them, dual), with the parameters (measured state, boxes) of the recorded run.

The alternatives work on the optimal-control form of the same problem, which structure-exploiting solvers
need: per stage a state x_k = (q_k, d_k, e_k) (joints, last step, last step change) and a control
u_k = (f_k, s_k) (change of the step change, table slack; the last stage also the facing-down slack), with
x_{k+1} = (q + d + e + f, d + e + f, e + f). The step, acceleration and jerk rows become bounds on d, e, f;
the box, table and cost terms are the planner's own stage function (`NMPCProblem.stage_function`), so the
constraints and the cost are the planner's.

- `ipopt, OCP form`: IPOPT with the planner's options on that form (what the form costs IPOPT);
- `fatrop, OCP form`: CasADi's fatrop interface with structure detection; it takes no dual warm start;
- `SQP Gauss-Newton + HPIPM`: CasADi's `sqpmethod` with the Gauss-Newton Hessian of the cost (2 J^T J of
  its residuals: no second derivatives of the kinematics) and HPIPM, a Riccati interior-point QP solver,
  told the stage structure;
- `one HPIPM QP`: only the first QP of that SQP, timed alone: what a real-time iteration (one QP per
  control step, as acados does) would cost at least with these tools.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

import twin_nmpc.nlp as model
from twin.config import PlannerBlock, Settings
from twin.planning import make_context, make_planner, plan_with
from twin_nmpc.scenarios import build_scene, transfer_scenes


@dataclass
class Recorded:
    """One solve of the recorded run: its inputs and what IPOPT did with them."""

    shape: model.ProblemShape
    x0: np.ndarray
    p: np.ndarray
    bounds: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    warm: bool
    q: np.ndarray  # IPOPT's knots (N+1, 6)
    time_s: float
    iterations: int


def record(settings: Settings, params: dict[str, Any], n: int, seed: int) -> tuple[Any, list[Recorded]]:
    """Run n transfers with `nmpc` and keep every solve."""
    ctx = make_context(settings)
    planner = make_planner(PlannerBlock(name="nmpc", params=params), ctx)
    out: list[Recorded] = []
    solve = model.NMPCProblem.solve

    def recording(self: model.NMPCProblem, x0: np.ndarray, p: np.ndarray, bounds: Any, **kw: Any) -> Any:
        sol = solve(self, x0, p, bounds, **kw)
        out.append(Recorded(self.shape, x0, p, bounds, sol.warm, sol.q, sol.solve_time_s, sol.iterations))
        return sol

    model.NMPCProblem.solve = recording  # type: ignore[method-assign]
    try:
        for ts in transfer_scenes(n, seed, settings=settings):
            plan_with(planner, ts.request, build_scene(settings, ts), ctx)
    finally:
        model.NMPCProblem.solve = solve  # type: ignore[method-assign]
    return planner.inner, out


class OCPForm:
    """The planner's NLP for one shape in optimal-control form (see the module docstring)."""

    def __init__(self, planner: Any, shape: model.ProblemShape, *, state_rows_first: bool = False):
        """`state_rows_first`: the measured-state rows before stage 0's gap (what fatrop's structure detection
        takes) rather than among stage 0's path rows (the [gap_k, path_k] order CasADi's HPIPM interface needs)."""
        self.state_rows_first = state_rows_first
        prob = planner.problem(shape)
        P = planner.params
        self.prob, self.N = prob, shape.horizon
        N = self.N
        n_rows = prob.block_g - 18
        self.n_rows = n_rows
        self.bound_p = prob.n_params  # then step, step change, jerk change, joint lo, joint hi (6 each)
        par = ca.SX.sym("p", prob.n_params + 30)
        pp = par[: prob.n_params]
        step, dstep, jstep, lo, hi = (par[prob.n_params + 6 * i : prob.n_params + 6 * i + 6] for i in range(5))
        X = [ca.SX.sym(f"x{k}", 18) for k in range(N + 1)]
        U = [ca.SX.sym(f"u{k}", 8 if k == N - 1 else 7) for k in range(N)]
        g: list[ca.SX] = []
        lbg: list[np.ndarray] = []
        ubg: list[np.ndarray] = []
        res: list[ca.SX] = []
        row_lb = prob.lbg[18 : prob.block_g]
        z: list[ca.SX] = []
        for k in range(N):
            q, d, e = X[k][0:6], X[k][6:12], X[k][12:18]
            f, s = U[k][0:6], U[k][6]
            e1 = e + f
            d1 = d + e1
            q1 = q + d1
            z += [X[k], U[k]]
            if k == 0 and state_rows_first:
                g.append(X[0] - ca.vertcat(pp[0:6], pp[6:12], pp[6:12] - pp[12:18]))
                lbg.append(np.zeros(18))
                ubg.append(np.zeros(18))
            gap = ca.vertcat(q1, d1, e1) - X[k + 1]  # the gap first: [gap_k, path_k] per stage
            g.append(-gap if state_rows_first else gap)  # the sign each interface's detection expects
            lbg.append(np.zeros(18))
            ubg.append(np.zeros(18))
            w = P.position_weight * (P.terminal_weight_factor if k == N - 1 else 1.0)
            rows, r, R9 = prob.stage_function(q, q1, s, pp, w, ca.SX.zeros(0, 1))
            path = [f + jstep, jstep - f, e1 + dstep, dstep - e1, d1 + step, step - d1, q1 - lo, hi - q1, s, rows]
            lo_path = [np.zeros(49), row_lb]
            hi_path = [np.full(49 + n_rows, np.inf)]
            if k == 0 and not state_rows_first:  # the measured state, as the first rows of stage 0
                path.insert(0, X[0] - ca.vertcat(pp[0:6], pp[6:12], pp[6:12] - pp[12:18]))
                lo_path.insert(0, np.zeros(18))
                hi_path.insert(0, np.zeros(18))
            res.append(r)
            if k == N - 1:
                sd = U[k][7]
                path += [sd, -R9[8] + sd]
                lo_path += [np.zeros(1), np.full(1, prob.lbg[-1])]
                hi_path += [np.full(2, np.inf)]
                res.append(math.sqrt(P.facing_down_weight) * sd)
            g.append(ca.vertcat(*path))
            lbg.append(np.concatenate(lo_path))
            ubg.append(np.concatenate(hi_path))
        z.append(X[N])
        self.z = ca.vertcat(*z)
        self.nz = int(self.z.numel())
        self.nlp = {"x": self.z, "p": par, "f": ca.sumsqr(ca.vertcat(*res)), "g": ca.vertcat(*g)}
        self.lbg, self.ubg = np.concatenate(lbg), np.concatenate(ubg)
        self.ng = self.lbg.size
        Jr = ca.jacobian(ca.vertcat(*res), self.z)
        lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", self.ng)
        self.gauss_newton = ca.Function(
            "gn",
            [self.z, par, lam_f, lam_g],
            [2 * lam_f * ca.mtimes(Jr.T, Jr)],
            ["x", "p", "lam_f", "lam_g"],
            ["hess_gamma_x_x"],
        )
        self.structure = {
            "N": N,
            "nx": [18] * (N + 1),
            "nu": [7] * (N - 1) + [8, 0],
            "ng": [67 + n_rows] + [49 + n_rows] * (N - 2) + [51 + n_rows, 0],
        }

    def parameters(self, r: Recorded) -> np.ndarray:
        lbx, ubx, _, ubg = r.bounds
        return np.concatenate([r.p, ubg[0:6], ubg[6:12], ubg[12:18], lbx[:6], ubx[:6]])

    def start_state(self, p: np.ndarray) -> np.ndarray:
        return np.concatenate([p[0:6], p[6:12], p[6:12] - p[12:18]])

    def pack(self, r: Recorded) -> np.ndarray:
        """z from the recorded primal start (knots)."""
        N = self.N
        qk = np.vstack([r.p[None, 0:6], self.prob.knots(r.x0)])
        d = np.diff(np.vstack([r.p[None, 0:6] - r.p[None, 6:12], qk]), axis=0)
        e = np.diff(np.vstack([r.p[None, 6:12] - r.p[None, 12:18], d]), axis=0)
        parts: list[np.ndarray] = []
        for k in range(N):
            parts += [qk[k], d[k], e[k], e[k + 1] - e[k], np.zeros(2 if k == N - 1 else 1)]
        parts += [qk[N], d[N], e[N]]
        return np.concatenate(parts)

    def shift_z(self, z: np.ndarray) -> np.ndarray:
        N = self.N
        body = z[: 25 * (N - 1)].reshape(N - 1, 25)
        last_x, last_u, xn = z[25 * (N - 1) : 25 * (N - 1) + 18], z[25 * (N - 1) + 18 : -18], z[-18:]
        new = np.concatenate([body[1:], np.concatenate([last_x, last_u[:7]])[None]])
        return np.concatenate([new.reshape(-1), xn, last_u, xn])

    def shift_g(self, lam: np.ndarray) -> np.ndarray:
        """Multipliers shifted one stage (those of the measured-state rows stay)."""
        at = 0 if self.state_rows_first else 18
        init, rest = lam[at : at + 18], np.concatenate([lam[:at], lam[at + 18 :]])
        blk = 18 + 49 + self.n_rows
        body = rest[: blk * (self.N - 1)].reshape(self.N - 1, blk)
        last = rest[blk * (self.N - 1) :]
        out = np.concatenate([body[1:].reshape(-1), last[:blk], last])
        return np.concatenate([out[:at], init, out[at:]])

    def knots(self, z: np.ndarray) -> np.ndarray:
        return np.array([z[25 * k : 25 * k + 6] for k in range(self.N)] + [z[-18:-12]])


def _hpipm_options(form: OCPForm) -> dict[str, Any]:
    """CasADi's HPIPM interface told the stage structure; residual tolerances instead of its 1e-8 defaults,
    which it did not reach within 100 iterations here."""
    hpipm = {"iter_max": 100, "mode": "balance", "res_g_max": 1e-5}
    hpipm.update(dict.fromkeys(("res_b_max", "res_d_max", "res_m_max"), 1e-7))
    return dict(form.structure, error_on_fail=False, hpipm=hpipm)


def _solvers(planner: Any, form: OCPForm) -> dict[str, tuple[OCPForm, Any, Any, bool]]:
    """name -> (its form, cold solver, warm solver, takes dual warm start); `form` has the [gap_k, path_k]
    order, fatrop gets its own."""
    fform = OCPForm(planner, form.prob.shape, state_rows_first=True)
    quiet = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes"}
    cold_o, warm_o = planner._ipopt_options(cold=True), planner._ipopt_options(cold=False)
    out: dict[str, tuple[OCPForm, Any, Any, bool]] = {
        "ipopt, OCP form": (
            form,
            ca.nlpsol("c", "ipopt", form.nlp, dict(quiet, **cold_o)),
            ca.nlpsol("w", "ipopt", form.nlp, dict(quiet, **warm_o)),
            True,
        )
    }
    fat = {
        "structure_detection": "auto",
        "equality": [bool(a == b) for a, b in zip(fform.lbg, fform.ubg, strict=True)],
        "print_time": False,
        "fatrop.print_level": 0,
        "fatrop.tol": planner.params.ipopt_tol,
        "fatrop.mu_init": 1e-3,
        "fatrop.max_iter": 300,
    }
    f = ca.nlpsol("f", "fatrop", fform.nlp, fat)
    out["fatrop, OCP form"] = (fform, f, f, False)
    hp = _hpipm_options(form)
    sqp = {
        "print_time": False,
        "print_header": False,
        "print_iteration": False,
        "print_status": False,
        "hess_lag": form.gauss_newton,
        "qpsol": "hpipm",
        "qpsol_options": hp,
        "max_iter": 50,
        "tol_pr": 1e-6,
        "tol_du": 1e-3,
        "error_on_fail": False,
    }
    s = ca.nlpsol("s", "sqpmethod", form.nlp, sqp)
    out["SQP Gauss-Newton + HPIPM"] = (form, s, s, True)
    return out


def compare(settings: Settings, params: dict[str, Any], n: int, seed: int) -> None:
    """Print the planner's IPOPT and each alternative on the recorded solves of the most common shape."""
    planner, recs = record(settings, params, n, seed)
    shape = max({r.shape for r in recs}, key=lambda s: sum(r.shape == s for r in recs))
    recs = [r for r in recs if r.shape == shape]
    form = OCPForm(planner, shape)
    print(f"== NMPC solvers side by side: {len(recs)} solves of {n} transfers, shape {shape}")
    print(f"   planner NLP {form.prob.nx} variables x {form.prob.ng} rows; OCP form {form.nz} x {form.ng}")

    def line(name: str, warm: list[float], cold: list[float], its: list[int], dev: list[float], fails: int) -> None:
        print(
            f"{name:28s} warm median {1e3 * np.median(warm):7.1f} p95 {1e3 * np.percentile(warm, 95):7.1f} ms |"
            f" cold median {1e3 * np.median(cold):7.1f} ms | iterations median {np.median(its):4.0f} |"
            f" first step vs IPOPT {np.median(dev):.1e} rad median | failed {fails}"
        )

    line(
        "ipopt (the planner's)",
        [r.time_s for r in recs if r.warm],
        [r.time_s for r in recs if not r.warm],
        [r.iterations for r in recs],
        [0.0],
        0,
    )
    k = int(params.get("execute_steps", 1))
    for name, (solver_form, cold, warm, duals) in _solvers(planner, form).items():
        tw, tc, its, dev, fails, prev = [], [], [], [], 0, None
        for r in recs:
            p = solver_form.parameters(r)
            use_warm = r.warm and prev is not None
            args: dict[str, Any] = {"p": p, "lbg": solver_form.lbg, "ubg": solver_form.ubg}  # no variable bounds
            if use_warm:
                z0 = prev[0]
                for _ in range(k):
                    z0 = solver_form.shift_z(z0)
                args["x0"] = z0
                if duals:
                    lam = prev[1]
                    for _ in range(k):
                        lam = solver_form.shift_g(lam)
                    args["lam_g0"] = lam
            else:
                args["x0"] = solver_form.pack(r)
            args["x0"][:18] = solver_form.start_state(r.p)
            solver = warm if use_warm else cold
            t0 = time.perf_counter()
            sol = solver(**args)
            dt = time.perf_counter() - t0
            st = solver.stats()
            ok = bool(st.get("success", False))
            fails += not ok
            (tw if use_warm else tc).append(dt)
            its.append(int(st.get("iter_count", -1)))
            z = np.asarray(sol["x"]).reshape(-1)
            prev = (z, np.asarray(sol["lam_g"]).reshape(-1)) if ok else None
            dev.append(float(np.abs(solver_form.knots(z)[1] - r.q[1]).max()))
        line(name, tw or [math.nan], tc or [math.nan], its, dev, fails)
    # one QP alone: the floor of a real-time iteration with these tools
    qp_times = []
    hp = _hpipm_options(form)
    data = ca.Function(
        "qp",
        [form.z, form.nlp["p"]],
        [ca.gradient(form.nlp["f"], form.z), form.nlp["g"], ca.jacobian(form.nlp["g"], form.z)],
    )
    H0 = form.gauss_newton(form.pack(recs[0]), form.parameters(recs[0]), 1.0, np.zeros(form.ng))
    A0 = data(form.pack(recs[0]), form.parameters(recs[0]))[2]
    qp = ca.conic("qp", "hpipm", {"h": H0.sparsity(), "a": A0.sparsity()}, hp)
    for r in recs[:40]:
        z, p = form.pack(r), form.parameters(r)
        grad, g, A = data(z, p)
        H = form.gauss_newton(z, p, 1.0, np.zeros(form.ng))
        lbz, ubz = np.full(form.nz, -np.inf), np.full(form.nz, np.inf)
        gv = np.asarray(g).reshape(-1)
        t0 = time.perf_counter()
        qp(h=H, g=grad, a=A, lba=form.lbg - gv, uba=form.ubg - gv, lbx=lbz, ubx=ubz)
        qp_times.append(time.perf_counter() - t0)
    print(f"{'one HPIPM QP (RTI floor)':28s} median {1e3 * np.median(qp_times):7.1f} ms per QP (evaluations excluded)")
    print()
