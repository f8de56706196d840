"""Defensive inverse kinematics for the UR5e (seed 002's "advanced IK", made analytic and typed).

The seed scored four numerical seeds (continuity, analytic, high-elbow reference, random perturbation);
here every analytic branch of the closed-form UR5e solver is a candidate (a superset of those four), each
wrapped by multiples of 2*pi to the value nearest the continuity seed inside the joint limits. Candidates
are scored with the seed's cost

    0.3 * |q - q_seed| + 0.6 * |q - q_ref| + P_flip (|base| > 1.57 rad) + P_singularity (cond(J) > 500)

after jump protection has removed every candidate that moves the base more than 3.0 rad or a wrist joint
(joints 4..6) more than 5.0 rad away from the seed. Unreachable, singular or rejected targets never raise:
the result carries `q=None` and a reason a person can act on.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import ur_analytic_ik
from pydantic import BaseModel, ConfigDict, Field

from twin.plugin import Pose, URArm

__all__ = [
    "DefensiveIK",
    "DefensiveIKParams",
    "IKResult",
    "condition_numbers",
]

log = logging.getLogger("twin")

_TWO_PI = 2.0 * math.pi
_WRIST = slice(3, 6)


class DefensiveIKParams(BaseModel):
    """Weights and thresholds of the defensive IK; defaults are the seed's (SPEC, System B)."""

    model_config = ConfigDict(extra="forbid")

    w_continuity: float = Field(0.3, ge=0, description="weight of |q - q_seed| (rad)")
    w_reference: float = Field(0.6, ge=0, description="weight of |q - q_ref| (rad)")
    flip_penalty: float = Field(100.0, ge=0, description="added when |base| exceeds flip_base_rad")
    flip_base_rad: float = Field(1.57, gt=0)
    singularity_penalty: float = Field(
        100.0, ge=0, description="added when cond(J) exceeds singularity_cond (the seed gives no value; ours)"
    )
    singularity_cond: float = Field(500.0, gt=1)
    reject_singular: bool = Field(False, description="reject (not just penalise) candidates above singularity_cond")
    max_base_jump_rad: float = Field(3.0, gt=0)
    max_wrist_jump_rad: float = Field(5.0, gt=0)
    tol: float = Field(1e-6, gt=0, description="a solution must reproduce the target within tol (m, Frobenius)")


@dataclass(frozen=True)
class IKResult:
    """Outcome of one defensive IK query.

    `q` (6,) rad is the chosen solution or None; `reason` says why (or notes penalties on success);
    `cost` is the seed's cost of `q`; `candidates` is the number of (finite) analytic branches scored;
    `condition` is cond(J) at `q`.
    """

    q: np.ndarray | None
    reason: str
    cost: float = math.inf
    candidates: int = 0
    condition: float = math.nan
    rejected: dict[str, int] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.q is not None


def _cond(J: np.ndarray) -> np.ndarray:
    sv = np.linalg.svd(J, compute_uv=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        return sv[:, 0] / sv[:, -1]


def condition_numbers(kin: URArm, qs: np.ndarray, frame: str = "tcp") -> np.ndarray:
    """(n,) cond(J) of `frame`'s Jacobian for (n, 6) configurations (inf at an exact singularity)."""
    return _cond(kin.jacobians_from_frames(kin.dh_frames(qs), frame))


class DefensiveIK:
    """The seed's defensive IK over every analytic branch; see the module docstring.

    `kin` (the context's arm: no default) supplies joint limits and the tool frames; `params` the weights
    and thresholds.
    """

    def __init__(self, kin: URArm, params: DefensiveIKParams | None = None):
        self.kin = kin
        self.params = params or DefensiveIKParams()
        self._tool = {f: self.kin.tool_transform(f) for f in ("tcp", "flange")}
        self._tool_inv = {f: np.linalg.inv(T) for f, T in self._tool.items()}
        self._dh = self.kin.dh
        self._analytic = getattr(ur_analytic_ik, self.kin.model)  # the closed form of this arm
        self._lo = self.kin.joint_limits[:, 0] - 1e-12
        self._hi = self.kin.joint_limits[:, 1] + 1e-12

    def tool(self, frame: str) -> np.ndarray:
        """(4, 4) pose of `frame` in the flange frame."""
        return self._tool[frame]

    def branches(self, T: np.ndarray, frame: str = "tcp") -> tuple[np.ndarray, str]:
        """(k, 6) finite analytic branches for pose `T` of `frame` (angles in [-pi, pi]), and a reason if k = 0.

        Accuracy (the target reproduced within tol) is checked later, only for the branches that compete.
        """
        T_fl = T @ self._tool_inv[frame]
        try:
            raw = self._analytic.inverse_kinematics(T_fl)
        except Exception as e:  # noqa: BLE001 -- a broken pose must not escape as an exception
            return np.zeros((0, 6)), f"analytic IK failed on this pose: {e}"
        S = np.array(raw, dtype=float).reshape(-1, 6)
        S = S[np.isfinite(S).all(axis=1)]
        if S.shape[0] == 0:
            return S, "unreachable: " + self._why_unreachable(T_fl)
        return S, ""

    def accurate(self, q: np.ndarray, T: np.ndarray, frame: str = "tcp") -> bool:
        """Whether FK(q) reproduces `T` within tol (position norm, rotation Frobenius norm)."""
        F = self._analytic.forward_kinematics(*q) @ self._tool[frame]
        E = F[:3] - T[:3]
        tol = self.params.tol
        return bool(math.sqrt((E[:, 3] ** 2).sum()) <= tol and math.sqrt((E[:, :3] ** 2).sum()) <= tol)

    def condition(self, q: np.ndarray, frame: str = "tcp") -> float:
        """cond(J) at `q` (6,) for the Jacobian of `frame`."""
        sv = np.linalg.svd(self.kin.jacobian(q, frame), compute_uv=False)
        return float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf

    def _why_unreachable(self, T_fl: np.ndarray) -> str:
        d, a = self._dh.d, self._dh.a
        wc = T_fl[:3, 3] - d[5] * T_fl[:3, 2]  # wrist centre (frame 5 origin)
        r_xy = math.hypot(wc[0], wc[1])
        if r_xy < d[3]:
            return (
                f"the wrist centre is {r_xy:.3f} m from the base z axis, inside the shoulder singularity column "
                f"(radius d4 = {d[3]:.4f} m)"
            )
        dist = float(np.linalg.norm(wc - np.array([0.0, 0.0, d[0]])))
        reach = abs(a[1]) + abs(a[2])
        return (
            f"no analytic solution (wrist centre {dist:.3f} m from the shoulder; the arm spans "
            f"{reach:.3f} m plus the wrist offsets): out of reach or orientation not attainable there"
        )

    def wrap_near(self, S: np.ndarray, q_seed: np.ndarray) -> np.ndarray:
        """Each joint of each row of `S` shifted by 2*pi*k to the value nearest `q_seed` inside the limits.

        A joint whose range is shorter than 2*pi may have no wrap inside; it keeps an out-of-limits value
        and the candidate is rejected by the limit check.
        """
        V = S + _TWO_PI * np.round((q_seed - S) / _TWO_PI)
        V = np.where(V > self._hi, V - _TWO_PI, V)
        V = np.where(V < self._lo, V + _TWO_PI, V)
        return V

    def solve(
        self,
        target: np.ndarray | Pose,
        q_seed: np.ndarray,
        q_ref: np.ndarray | None = None,
        *,
        frame: str = "tcp",
        penalise_flip: bool = True,
        penalise_singularity: bool = True,
        is_valid: Callable[[np.ndarray], bool] | None = None,
    ) -> IKResult:
        """Best joint solution for `target` (4, 4) pose of `frame` in the base frame, or a reason.

        `q_seed` (6,) is the continuity seed (the current or previous joint state); `q_ref` (6,) the
        reference posture (defaults to the seed). `penalise_flip=False` and `penalise_singularity=False`
        drop those penalties (MoveL keeps the start's branch by continuity and reports singularities
        itself). `is_valid(q)` may reject candidates (e.g. in collision); it is only called for candidates
        that would otherwise win.
        """
        p = self.params
        T = target.matrix() if isinstance(target, Pose) else np.asarray(target, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            return IKResult(None, "the target is not a finite (4, 4) pose")
        seed = np.asarray(q_seed, dtype=float).reshape(6)
        ref = seed if q_ref is None else np.asarray(q_ref, dtype=float).reshape(6)
        S, why = self.branches(T, frame)
        if S.shape[0] == 0:
            return IKResult(None, why)
        Q = self.wrap_near(S, seed)
        k = Q.shape[0]
        dq = Q - seed
        adq = np.abs(dq)
        in_lim = ((Q >= self._lo) & (Q <= self._hi)).all(axis=1)
        base_jump, wrist_jump = adq[:, 0], adq[:, _WRIST].max(axis=1)
        jump = in_lim & ((base_jump > p.max_base_jump_rad) | (wrist_jump > p.max_wrist_jump_rad))
        dr = Q - ref
        cost = p.w_continuity * np.sqrt(np.einsum("ij,ij->i", dq, dq)) + p.w_reference * np.sqrt(
            np.einsum("ij,ij->i", dr, dr)
        )
        if penalise_flip:
            cost += p.flip_penalty * (np.abs(Q[:, 0]) > p.flip_base_rad)
        rejected = {"joint limits": k - int(in_lim.sum()), "jump protection": int(jump.sum())}
        base_cost = cost.tolist()
        order = [int(i) for i in np.argsort(cost, kind="stable")[(in_lim & ~jump)[np.argsort(cost, kind="stable")]]]
        min_base_jump = float(base_jump[in_lim].min()) if in_lim.any() else math.inf
        min_wrist_jump = float(wrist_jump[in_lim].min()) if in_lim.any() else math.inf

        # Visit candidates cheapest first; the singularity penalty and the checks are only paid for the
        # candidates that could still win (usually just one).
        best, best_cost, best_cond = -1, math.inf, math.nan
        conds: list[float] = []
        for i in order:
            if base_cost[i] >= best_cost:
                break
            if not self.accurate(Q[i], T, frame):
                rejected["inaccurate"] = rejected.get("inaccurate", 0) + 1
                continue
            c = self.condition(Q[i], frame)
            conds.append(c)
            singular = not (c <= p.singularity_cond)
            if singular and p.reject_singular:
                rejected["singularity"] = rejected.get("singularity", 0) + 1
                continue
            total = base_cost[i] + (p.singularity_penalty if singular and penalise_singularity else 0.0)
            if total >= best_cost:
                continue
            if is_valid is not None and not is_valid(Q[i]):
                rejected["invalid"] = rejected.get("invalid", 0) + 1
                continue
            best, best_cost, best_cond = i, total, c
        rejected = {r: c for r, c in rejected.items() if c}
        if best < 0:
            why = self._why_rejected(k, rejected, min_base_jump, min_wrist_jump, conds)
            return IKResult(None, why, candidates=k, rejected=rejected)
        notes = []
        if not (best_cond <= p.singularity_cond):
            notes.append(f"near-singular: cond(J) = {best_cond:.0f} > {p.singularity_cond:g}")
        if penalise_flip and abs(Q[best, 0]) > p.flip_base_rad:
            notes.append(f"base {Q[best, 0]:+.2f} rad beyond +-{p.flip_base_rad:g} (flip penalty)")
        reason = "ok" + (f" ({'; '.join(notes)})" if notes else "")
        q = Q[best].copy()
        q.setflags(write=False)
        return IKResult(q, reason, best_cost, k, best_cond, rejected)

    def _why_rejected(
        self, k: int, rejected: dict[str, int], min_base_jump: float, min_wrist_jump: float, conds: list[float]
    ) -> str:
        p = self.params
        parts = []
        if rejected.get("jump protection"):
            parts.append(
                f"{rejected['jump protection']} by jump protection (smallest base jump {min_base_jump:.2f} rad, "
                f"limit {p.max_base_jump_rad:g}; smallest wrist jump {min_wrist_jump:.2f} rad, "
                f"limit {p.max_wrist_jump_rad:g})"
            )
        if rejected.get("joint limits"):
            parts.append(f"{rejected['joint limits']} outside the joint limits")
        if rejected.get("singularity"):
            parts.append(
                f"{rejected['singularity']} singular (smallest cond(J) {min(conds):.0f} > {p.singularity_cond:g})"
            )
        if rejected.get("inaccurate"):
            parts.append(f"{rejected['inaccurate']} do not reproduce the target within {p.tol:g} (near a singularity)")
        if rejected.get("invalid"):
            parts.append(f"{rejected['invalid']} invalid (e.g. in collision)")
        return f"rejected: all {k} IK branches: " + "; ".join(parts)
