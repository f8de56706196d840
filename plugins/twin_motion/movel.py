"""Cartesian straight-line planners: `toppra.movel` and the seed-002 baseline `seed.slerp_movel`.

The TCP (or flange) moves on the straight line from its start pose to the goal pose while its orientation
follows SLERP at the same fraction s in [0, 1] of the way. Joint waypoints come from the defensive IK,
each seeded by the previous one (continuity first: the start's IK branch is kept).

`toppra.movel` refines its waypoints until the joint-space spline through them stays within the line and
SLERP tolerances (default 1 mm, 0.5 deg) everywhere, and times the spline with TOPP-RA under the joint
limits and an optional TCP speed limit. A line that leaves the workspace, needs a joint to jump (a branch
change) or passes a singularity (cond(J) above a threshold) is a typed failure with a reason.

`seed.slerp_movel` is the seed as written: 0.02 m steps, N = max(2, ceil(L / step) + 1) waypoints,
IK seeded by the previous waypoint, 0.12 m/s nominal, at least 1.5 s, abort on any waypoint without IK.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from pydantic import Field
from scipy.interpolate import CubicSpline

from twin.plugin import (
    JointGoal,
    MotionRequest,
    MotionResult,
    Pose,
    PoseGoal,
    Status,
    Trajectory,
    quats_to_matrices,
)
from twin_motion.movej import MotionPlannerBase, sample_times, stationary
from twin_motion.retimers import toppra_time_spline

if TYPE_CHECKING:
    from twin.plugin import PlanningScene

__all__ = ["CartesianLine", "SeedSlerpMoveL", "ToppraMoveL", "quat_slerp"]

log = logging.getLogger("twin")


def quat_slerp(q0: np.ndarray, q1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(n, 4) x-y-z-w quaternions on the shorter arc from q0 to q1 at fractions `s` (n,).

    Nearly parallel quaternions fall back to normalised linear interpolation (as the seed does).
    """
    q0 = np.asarray(q0, dtype=float) / np.linalg.norm(q0)
    q1 = np.asarray(q1, dtype=float) / np.linalg.norm(q1)
    s = np.asarray(s, dtype=float)[:, None]
    dot = float(q0 @ q1)
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = (1.0 - s) * q0 + s * q1
        return q / np.linalg.norm(q, axis=1, keepdims=True)
    theta = math.acos(min(1.0, dot))
    return (np.sin((1.0 - s) * theta) * q0 + np.sin(s * theta) * q1) / math.sin(theta)


def rotation_angles(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """(n,) angles (rad) between rotations (n, 3, 3); accurate near zero (|Ra - Rb|_F = 2 sqrt2 sin(a/2))."""
    f = np.sqrt(((Ra - Rb) ** 2).sum(axis=(1, 2))) / (2.0 * math.sqrt(2.0))
    return 2.0 * np.arcsin(np.clip(f, 0.0, 1.0))


@dataclass(frozen=True)
class CartesianLine:
    """The straight line with SLERP orientation between two poses (4, 4) in the base frame."""

    T0: np.ndarray
    T1: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "_q0", Pose.from_matrix(self.T0).quat_xyzw)
        object.__setattr__(self, "_q1", Pose.from_matrix(self.T1).quat_xyzw)

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(self.T1[:3, 3] - self.T0[:3, 3]))

    @property
    def angle_rad(self) -> float:
        return float(rotation_angles(self.T0[None, :3, :3], self.T1[None, :3, :3])[0])

    def poses(self, s: np.ndarray) -> np.ndarray:
        """(n, 4, 4) poses at fractions `s` (n,) of the way."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        out = np.zeros((s.shape[0], 4, 4))
        out[:, 3, 3] = 1.0
        out[:, :3, 3] = self.T0[:3, 3] + s[:, None] * (self.T1[:3, 3] - self.T0[:3, 3])
        out[:, :3, :3] = quats_to_matrices(quat_slerp(self._q0, self._q1, s))  # type: ignore[attr-defined]
        return out

    def deviation(self, T: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position error (m) and orientation error (rad) of poses T (n, 4, 4) from the line at fractions s."""
        ref = self.poses(s)
        return np.linalg.norm(T[:, :3, 3] - ref[:, :3, 3], axis=1), rotation_angles(T[:, :3, :3], ref[:, :3, :3])


class _LineFailure(Exception):
    """Internal: the line cannot be followed; carries the status and reason for the result."""

    def __init__(self, status: Status, reason: str):
        super().__init__(reason)
        self.status = status
        self.reason = reason


class _MoveLBase(MotionPlannerBase):
    """Shared by both MoveL planners: the line from the start pose to the goal pose of the goal frame."""

    def line_for(self, request: MotionRequest) -> tuple[CartesianLine, str]:
        goal = request.goal
        if isinstance(goal, PoseGoal):
            frame = goal.frame
            if frame not in ("tcp", "flange"):
                raise _LineFailure(Status.INVALID_GOAL, f"unknown goal frame {frame!r}; allowed: tcp, flange")
            T1 = goal.pose.matrix()
        else:
            frame = "tcp"
            T1 = self.kin.fk(np.asarray(goal.q, dtype=float), frame)
        T0 = self.kin.fk(request.start, frame)
        return CartesianLine(T0, T1), frame

    def goal_checks(self, request: MotionRequest, line: CartesianLine, frame: str) -> None:
        """INVALID_GOAL when the goal pose has no IK at all or a joint goal is outside the limits."""
        if isinstance(request.goal, JointGoal) and not self.kin.within_limits(request.goal.q):
            raise _LineFailure(Status.INVALID_GOAL, "the joint goal is outside the joint limits")
        S, why = self.ik.branches(line.T1, frame)
        if S.shape[0] == 0:
            raise _LineFailure(Status.INVALID_GOAL, f"the goal pose has no IK solution: {why}")

    def end_config(self, request: MotionRequest, q_end: np.ndarray) -> np.ndarray:
        """The last waypoint; a joint goal must be reached exactly, on the branch the line arrived on."""
        if isinstance(request.goal, JointGoal):
            err = float(np.abs(q_end - request.goal.q).max())
            if err > 1e-6:
                raise _LineFailure(
                    Status.INVALID_GOAL,
                    f"the line from the start's IK branch ends {err:.3f} rad away from the joint goal (another "
                    "IK branch or 2*pi wrap of the same pose); use a MoveJ or a pose goal",
                )
            return np.array(request.goal.q, dtype=float)
        return q_end

    def _plan(self, request: MotionRequest, scene: PlanningScene) -> MotionResult:
        bad = self.check_start(request, scene)
        if bad:
            return bad
        try:
            line, frame = self.line_for(request)
            self.goal_checks(request, line, frame)
            if line.length_m < 1e-9 and line.angle_rad < 1e-9:
                q_end = self.end_config(request, np.array(request.start))
                if np.abs(q_end - request.start).max() <= 1e-12:
                    return self.finish(request, scene, stationary(request.start), info={"waypoints": 1})
            return self._plan_line(request, scene, line, frame)
        except _LineFailure as f:
            return MotionResult(f.status, f.reason)

    def _plan_line(self, request: MotionRequest, scene: PlanningScene, line: CartesianLine, frame: str) -> MotionResult:
        raise NotImplementedError


# ---- toppra.movel ---------------------------------------------------------------------------------------
class ToppraMoveL(_MoveLBase):
    """Straight TCP line + SLERP, IK at refined waypoints, timed by TOPP-RA (joint and TCP speed limits).

    Not jerk-limited (declared): TOPP-RA parameterises under velocity and acceleration constraints only, so
    the acceleration may jump (from rest at t = 0, and between its constant-acceleration grid intervals).
    """

    jerk_limited: ClassVar[bool] = False

    class Params(MotionPlannerBase.Params):
        step_m: float = Field(0.02, gt=0, le=0.1, description="initial waypoint spacing along the line")
        step_rad: float = Field(0.1, gt=0, le=0.5, description="initial waypoint spacing in orientation")
        max_line_deviation_m: float = Field(0.001, gt=0, description="allowed TCP distance from the line")
        max_orientation_deviation_deg: float = Field(0.5, gt=0, description="allowed angle from the SLERP orientation")
        check_margin: float = Field(
            0.5, gt=0, le=1, description="the spline is refined to this fraction of the tolerances"
        )
        max_joint_step_rad: float = Field(0.1, gt=0, description="largest joint change between neighbouring waypoints")
        min_step_m: float = Field(0.0005, gt=0, description="waypoints are not subdivided below this TCP step")
        min_step_rad: float = Field(0.002, gt=0, description="... nor below this orientation step")
        max_condition: float = Field(500.0, gt=1, description="cond(J) above this on the line is a singularity")
        max_tcp_speed_m_s: float | None = Field(
            None,
            gt=0,
            description="speed limit (m/s) of the goal frame along the line; the request's max_tcp_speed also applies",
        )
        margin: float = Field(0.01, ge=0, lt=0.5, description="TOPP-RA gets the limits tightened by this fraction")
        refinements: int = Field(1, ge=0, le=10, description="TOPP-RA grid refinements where samples overshoot")
        verify_samples: bool = Field(True, description="re-check line and SLERP deviation at every output sample")

    params: Params

    def _waypoint(self, line: CartesianLine, frame: str, s: float, q_prev: np.ndarray) -> tuple[np.ndarray, float]:
        T = line.poses(np.array([s]))[0]
        res = self.ik.solve(T, q_prev, q_prev, frame=frame, penalise_flip=False, penalise_singularity=False)
        if not res.ok:
            p = T[:3, 3]
            raise _LineFailure(
                Status.IK_FAILED,
                f"the line leaves the workspace at s = {s:.4f} "
                f"(x, y, z = {p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f} m): {res.reason}",
            )
        return np.array(res.q), res.condition

    def _step_ok(self, a: np.ndarray, b: np.ndarray) -> bool:
        return float(np.abs(b - a).max()) <= self.params.max_joint_step_rad

    def _can_split(self, line: CartesianLine, ds: float) -> bool:
        p = self.params
        return ds * line.length_m > p.min_step_m or ds * line.angle_rad > p.min_step_rad

    def _check_singular(self, s: float, cond: float) -> None:
        if not (cond <= self.params.max_condition):
            raise _LineFailure(
                Status.IK_FAILED,
                f"the line passes a singularity at s = {s:.4f}: cond(J) = {cond:.0f} > {self.params.max_condition:g}",
            )

    def waypoints(self, request: MotionRequest, line: CartesianLine, frame: str) -> tuple[np.ndarray, np.ndarray]:
        """(k,) fractions and (k, 6) joint waypoints along the line, continuity-seeded and jump-free."""
        p = self.params
        n = max(2, math.ceil(line.length_m / p.step_m) + 1, math.ceil(line.angle_rad / p.step_rad) + 1)
        targets = list(np.linspace(0.0, 1.0, n)[::-1][:-1])  # a stack: next target on top
        S, Q = [0.0], [np.array(request.start, dtype=float)]
        self._check_singular(0.0, self.ik.condition(Q[0], frame))
        while targets:
            s = targets[-1]
            q, cond = self._waypoint(line, frame, s, Q[-1])
            if not self._step_ok(Q[-1], q):
                if self._can_split(line, s - S[-1]):
                    targets.append(0.5 * (S[-1] + s))
                    continue
                j = int(np.argmax(np.abs(q - Q[-1])))
                raise _LineFailure(
                    Status.IK_FAILED,
                    f"the line crosses a singularity or branch change between s = {S[-1]:.4f} and {s:.4f}: joint "
                    f"{j + 1} jumps {abs(q[j] - Q[-1][j]):.2f} rad (cond(J) = {cond:.0f})",
                )
            self._check_singular(s, cond)
            targets.pop()
            S.append(s)
            Q.append(q)
        return np.array(S), np.array(Q)

    def refine(
        self, line: CartesianLine, frame: str, S: np.ndarray, Q: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Insert waypoints until the joint spline stays within margin x tolerances of the line and SLERP."""
        p = self.params
        tol_p = p.max_line_deviation_m * p.check_margin
        tol_a = math.radians(p.max_orientation_deviation_deg) * p.check_margin
        tool = self.ik.tool(frame)
        frac = np.linspace(0.0, 1.0, 9)[1:-1]
        for _ in range(8):
            spline = CubicSpline(S, Q, bc_type="not-a-knot")
            s_chk = (S[:-1, None] + np.diff(S)[:, None] * frac[None, :]).ravel()
            T = self.kin.dh_frames(spline(s_chk))[:, 6] @ tool
            dp, da = line.deviation(T, s_chk)
            dp, da = dp.reshape(-1, frac.size).max(axis=1), da.reshape(-1, frac.size).max(axis=1)
            bad = np.flatnonzero((dp > tol_p) | (da > tol_a))
            if bad.size == 0:
                return S, Q, float(dp.max()), float(da.max())
            newS, newQ = [S[0]], [Q[0]]
            bad_set = set(bad.tolist())
            for i in range(S.shape[0] - 1):
                if i in bad_set:
                    sm = 0.5 * (S[i] + S[i + 1])
                    qm, cond = self._waypoint(line, frame, sm, Q[i])
                    if not (self._step_ok(Q[i], qm) and self._step_ok(qm, Q[i + 1])):
                        raise _LineFailure(Status.IK_FAILED, f"the IK branch changes near s = {sm:.4f} (joint jump)")
                    self._check_singular(sm, cond)
                    newS.append(sm)
                    newQ.append(qm)
                newS.append(S[i + 1])
                newQ.append(Q[i + 1])
            S, Q = np.array(newS), np.array(newQ)
        raise _LineFailure(
            Status.IK_FAILED,
            f"could not keep the joint path within {p.max_line_deviation_m * 1e3:g} mm / "
            f"{p.max_orientation_deviation_deg:g} deg of the line "
            f"(worst {dp.max() * 1e3:.2f} mm, {math.degrees(da.max()):.2f} deg)",
        )

    def _plan_line(self, request: MotionRequest, scene: PlanningScene, line: CartesianLine, frame: str) -> MotionResult:
        p = self.params
        S, Q = self.waypoints(request, line, frame)
        Q[-1] = self.end_config(request, Q[-1])
        S, Q, dev_p, dev_a = self.refine(line, frame, S, Q)
        speeds = [v for v in (p.max_tcp_speed_m_s, request.limits.max_tcp_speed) if v is not None]
        tcp_speed = min(speeds) if speeds else None
        timed = toppra_time_spline(
            S,
            Q,
            request.limits,
            sample_dt_s=p.sample_dt_s,
            margin=p.margin,
            refinements=p.refinements,
            tcp_length_m=line.length_m,
            tcp_speed=tcp_speed,
        )
        traj = timed.trajectory()
        info: dict[str, Any] = {
            "waypoints": int(S.shape[0]),
            "line_length_m": line.length_m,
            "rotation_deg": math.degrees(line.angle_rad),
            "spline_line_deviation_m": dev_p,
            "spline_orientation_deviation_deg": math.degrees(dev_a),
        }
        if p.verify_samples and timed.s is not None:
            T = self.kin.dh_frames(traj.q)[:, 6] @ self.ik.tool(frame)
            dp, da = line.deviation(T, timed.s)
            info["line_deviation_m"], info["orientation_deviation_deg"] = float(dp.max()), math.degrees(float(da.max()))
            if dp.max() > p.max_line_deviation_m or da.max() > math.radians(p.max_orientation_deviation_deg):
                return MotionResult(
                    Status.IK_FAILED,
                    f"the timed trajectory strays {dp.max() * 1e3:.2f} mm / "
                    f"{math.degrees(da.max()):.2f} deg from the line",
                    path=Q,
                    info=info,
                )
        return self.finish(request, scene, traj, path=Q, info=info)


# ---- seed.slerp_movel -----------------------------------------------------------------------------------
class SeedSlerpMoveL(_MoveLBase):
    """Seed 002's MoveL: fixed 0.02 m steps, IK seeded by the previous waypoint, 0.12 m/s, >= 1.5 s.

    The waypoints are joined by a cubic spline in time with zero end velocities. By default the duration
    is stretched where needed so joint velocity, acceleration and jerk stay under the request's limits
    (`respect_limits: false` keeps the seed's timing even when it exceeds them).

    Not jerk-limited (declared): the seed times its waypoints by duration alone, with no acceleration
    profile (its report: continuity "waypoint-based"), and the clamped spline that reproduces it starts and
    ends at rest with a nonzero acceleration, so qdd jumps at t = 0 and at the end however long T is. The
    stretch above bounds the jerk inside the spline, not those two jumps; this is the baseline as it was.
    """

    jerk_limited: ClassVar[bool] = False

    class Params(MotionPlannerBase.Params):
        step_m: float = Field(0.02, gt=0, description="Cartesian step between waypoints")
        nominal_speed_m_s: float = Field(0.12, gt=0, description="TCP speed that sets the duration")
        min_duration_s: float = Field(1.5, ge=0, description="shortest duration")
        respect_limits: bool = Field(True, description="stretch the duration to keep the joint limits")

    params: Params

    def _plan_line(self, request: MotionRequest, scene: PlanningScene, line: CartesianLine, frame: str) -> MotionResult:
        p = self.params
        L = line.length_m
        n = max(2, math.ceil(L / p.step_m) + 1)
        S = np.linspace(0.0, 1.0, n)
        poses = line.poses(S)
        Q = [np.array(request.start, dtype=float)]
        for i in range(1, n):
            res = self.ik.solve(poses[i], Q[-1], self.home, frame=frame)
            if not res.ok:
                return MotionResult(
                    Status.IK_FAILED, f"waypoint {i} of {n - 1} (s = {S[i]:.3f}) has no IK: {res.reason}"
                )
            Q.append(np.array(res.q))
        Qa = np.array(Q)
        Qa[-1] = self.end_config(request, Qa[-1])
        spline = CubicSpline(S, Qa, bc_type="clamped")  # unit time u in [0, 1]
        T = max(p.min_duration_s, L / p.nominal_speed_m_s)
        stretched = False
        if p.respect_limits:
            u = np.unique(np.concatenate([S, np.linspace(0.0, 1.0, 2001)]))
            lim = request.limits
            d1 = np.abs(spline(u, 1)).max(axis=0)
            d2 = np.abs(spline(u, 2)).max(axis=0)
            d3 = np.abs(spline(u, 3)).max(axis=0)
            T_lim = max(
                float((d1 / lim.max_joint_vel).max()),
                math.sqrt(float((d2 / lim.max_joint_acc).max())),
                float(np.cbrt((d3 / lim.max_joint_jerk).max())),
            )
            if T_lim > T:
                T, stretched = T_lim * (1.0 + 1e-9), True
        t = sample_times(T, p.sample_dt_s)
        u = t / T
        q = spline(u)
        qd = spline(u, 1) / T
        qdd = spline(u, 2) / T**2
        q[0], q[-1] = Qa[0], Qa[-1]
        qd[0] = qd[-1] = 0.0
        traj = Trajectory(t, q, qd, qdd)
        info = {"waypoints": n, "line_length_m": L, "stretched_for_limits": stretched}
        return self.finish(request, scene, traj, path=Qa, info=info)
